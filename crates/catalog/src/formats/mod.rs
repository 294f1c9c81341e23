//! Log files of other tools read as a run's parts: each is converted, streaming, into a
//! temporary MCAP file of catalogue (or foreign, ROS) channels, which the run reader then
//! reads like any recording. So every command that takes a run (`info`, `refuse`, `eval`,
//! `viz`, `track`, `tune`, the Python package) takes these files too, and `import` writes the
//! same conversion to a file of its own.
//!
//! - [`rosbag2_sqlite`]: ROS 2 bags in the sqlite3 storage (`.db3`);
//! - [`gpx`]: GPX 1.0 and 1.1 tracks (phones, Garmin units, handheld loggers);
//! - [`mdf4`]: ASAM MDF 4 CAN bus logging (CANedge, Vector), frames onto `/can/<bus>/frames`;
//! - [`csv_table`]: loggers' CSV tables, through a column mapping (`--map`);
//! - [`rosbag1`]: ROS 1 bags (`.bag` 2.0), their channels as `ros1msg` channels.

pub mod accuracy;
pub mod csv_table;
pub mod gpx;
pub mod mdf4;
pub mod rosbag1;
pub mod rosbag2_sqlite;

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};
use crate::log::WriterOptions;

/// How a file of a run stores its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Storage {
    Mcap,
    /// rosbag2's sqlite3 storage.
    Sqlite3,
    Gpx,
    /// ASAM MDF 4 (bus logging).
    Mdf4,
    /// A logger's table, read through a column mapping.
    Csv,
    /// A ROS 1 bag (format 2.0).
    Rosbag1,
}

impl Storage {
    /// The storage a file's name says; `None` for a name that says none.
    pub fn of_name(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "mcap" => Some(Self::Mcap),
            "db3" => Some(Self::Sqlite3),
            "gpx" => Some(Self::Gpx),
            "mf4" | "mdf" => Some(Self::Mdf4),
            "csv" | "tsv" => Some(Self::Csv),
            "bag" => Some(Self::Rosbag1),
            _ => None,
        }
    }

    /// The storage of a file by its name, else by its first bytes; MCAP where neither says.
    pub fn of_file(path: &Path) -> Self {
        if let Some(s) = Self::of_name(path) {
            return s;
        }
        let mut head = Vec::with_capacity(512);
        let read = std::fs::File::open(path).and_then(|f| f.take(512).read_to_end(&mut head));
        match read {
            Ok(_) if looks_like_gpx(&head) => Self::Gpx,
            Ok(_) if looks_like_mdf4(&head) => Self::Mdf4,
            Ok(_) if head.starts_with(b"SQLite format 3\0") => Self::Sqlite3,
            Ok(_) if head.starts_with(b"#ROSBAG V") => Self::Rosbag1,
            _ => Self::Mcap,
        }
    }

    /// Whether the run reader converts it before reading.
    pub fn is_converted(self) -> bool {
        self != Self::Mcap
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Mcap => "MCAP",
            Self::Sqlite3 => "rosbag2 sqlite3",
            Self::Gpx => "GPX",
            Self::Mdf4 => "MDF4",
            Self::Csv => "CSV",
            Self::Rosbag1 => "ROS 1 bag",
        }
    }
}

/// Whether the first bytes of a file are a GPX document's (an XML declaration or comments
/// before `<gpx`).
pub fn looks_like_gpx(head: &[u8]) -> bool {
    let text = String::from_utf8_lossy(head);
    let text = text.trim_start_matches('\u{feff}').trim_start();
    text.starts_with('<') && text.contains("<gpx")
}

/// Whether the first bytes of a file are an MDF file's (finalised or not).
pub fn looks_like_mdf4(head: &[u8]) -> bool {
    head.starts_with(b"MDF     ") || head.starts_with(b"UnFinMF ")
}

/// How the converted formats read their files (the choices a file cannot state itself).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct FormatOptions {
    pub gpx: gpx::GpxOptions,
    /// The column mapping of CSV tables (a table does not say what its columns are).
    #[serde(skip)]
    pub csv: Option<std::sync::Arc<csv_table::mapping::MappingFile>>,
}

/// What a conversion read and wrote.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Converted {
    /// Rows, points or records of the input read.
    pub rows: u64,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    /// Input not written, by reason.
    pub skipped: BTreeMap<String, u64>,
    /// The first few of those, each naming its line or record.
    pub first_problems: Vec<String>,
    /// Breaks in the input's own record of continuity (a GPX track's segments).
    pub gaps: u64,
    /// Where the input is damaged or cut off: what was read before it is kept.
    pub damage: Option<String>,
    /// What was read but may be wrong (a start time in an unknown zone).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Where the sensor frames sit, as the input's `/tf_static` says (ROS bags).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<crate::foreign::FrameTransform>,
}

/// Adds `new` transforms to `frames`, a frame given again replacing what it said before
/// (`/tf_static` is latched: a bag repeats it for every subscriber).
pub(crate) fn add_frames(
    frames: &mut Vec<crate::foreign::FrameTransform>,
    new: Vec<crate::foreign::FrameTransform>,
) {
    for t in new {
        match frames
            .iter_mut()
            .find(|f| f.parent == t.parent && f.child == t.child)
        {
            Some(f) => *f = t,
            None => frames.push(t),
        }
    }
}

impl Converted {
    pub(crate) fn skip(&mut self, reason: &str, detail: impl std::fmt::Display) {
        *self.skipped.entry(reason.to_owned()).or_insert(0) += 1;
        if self.first_problems.len() < 10 {
            self.first_problems.push(format!("{reason}: {detail}"));
        }
    }

    pub(crate) fn count(&mut self, topic: &str) {
        self.messages += 1;
        *self.per_topic.entry(topic.to_owned()).or_insert(0) += 1;
    }

    /// The reasons input was skipped, most frequent first, as a person reads them.
    pub fn reasons(&self) -> String {
        let mut by_count: Vec<(&String, &u64)> = self.skipped.iter().collect();
        by_count.sort_by(|a, b| b.1.cmp(a.1));
        by_count
            .iter()
            .map(|(r, n)| format!("{n} {r}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Converts `input`, of a converted storage, into MCAP at `output`, written with `writer`'s
/// options (a run's temporary file wants no Foxglove twins; an import's file does).
pub fn convert(
    storage: Storage,
    input: &Path,
    output: &Path,
    options: &FormatOptions,
    writer: &WriterOptions,
) -> Result<Converted> {
    match storage {
        Storage::Sqlite3 => rosbag2_sqlite::convert(input, output),
        Storage::Gpx => gpx::convert(input, output, &options.gpx, writer),
        Storage::Mdf4 => mdf4::convert(input, output, options.csv.as_deref(), writer),
        Storage::Rosbag1 => rosbag1::convert(input, output, writer),
        Storage::Csv => match &options.csv {
            Some(mapping) => csv_table::convert(input, output, mapping, writer),
            None => Err(Error::run(
                input,
                "a CSV table needs its column mapping: --map MAPPING.toml (`railfuse import --example-map DIR` writes one to start from)",
            )),
        },
        Storage::Mcap => Err(Error::run(input, "an MCAP file is read as it is")),
    }
}
