//! The mapping file (TOML) of a logger's CSV: which column is the time and how to read it,
//! what each column is in, and which column fills which field of which channel's message.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Error, Result};

/// A logger's CSV as railfuse channels. See the module doc of [`super`] for an example.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CsvMapping {
    /// The time of each row, for every channel that does not read its own.
    #[serde(default)]
    pub time: Option<TimeSpec>,
    /// Short forms of `[time] column`, `unit` and `offset_ns`, for a table whose time is one
    /// number.
    #[serde(default)]
    pub time_column: Option<String>,
    #[serde(default)]
    pub time_unit: Option<String>,
    #[serde(default)]
    pub time_offset_ns: Option<u64>,
    /// The character between cells: `,`, `;`, a tab.
    #[serde(default = "default_delimiter")]
    pub delimiter: String,
    /// The decimal mark of numbers: `.` or `,` (with a delimiter other than `,`).
    #[serde(default = "default_decimal")]
    pub decimal: String,
    /// What a column's numbers are in: `[columns.Lat] scale = 1e-7`, `[columns.Alt] unit = "mm"`.
    #[serde(default)]
    pub columns: BTreeMap<String, ColumnSpec>,
    pub channel: Vec<ChannelMapping>,
}

fn default_delimiter() -> String {
    ",".into()
}
fn default_decimal() -> String {
    ".".into()
}

/// How a row's time is read: one column of numbers (`unit`), or text in one or several
/// columns (joined by a space) read with a strftime `format` in a `zone`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSpec {
    #[serde(default)]
    pub column: Option<String>,
    #[serde(default)]
    pub columns: Vec<String>,
    /// s, ms, us or ns of a number (seconds since the Unix epoch, unless `offset_ns` places
    /// relative times).
    #[serde(default)]
    pub unit: Option<String>,
    /// strftime-like (`%Y-%m-%d %H:%M:%S%.f`, `%d.%m.%Y %H:%M:%S`); a `%z` in it reads the
    /// row's own offset.
    #[serde(default)]
    pub format: Option<String>,
    /// The zone of a civil time without an offset: `UTC` (the default), `+02:00`, or an IANA
    /// name (`Europe/Zurich`, daylight saving included).
    #[serde(default)]
    pub zone: Option<String>,
    /// Added to every time (the run's start, for times relative to it).
    #[serde(default)]
    pub offset_ns: i64,
    /// Rows that share one whole second (a logger that writes the second, not its fraction):
    /// `"evenly"` over the second, or `"rate"` (the k-th row at k / `rate_hz`).
    #[serde(default)]
    pub spread: Option<Spread>,
    #[serde(default)]
    pub rate_hz: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Spread {
    Evenly,
    Rate,
}

/// What a column's numbers are in: the value used is `(cell × scale + offset)` in `unit`,
/// turned into the unit of the field it fills (its name's suffix: `_m`, `_mps`, `_deg`, …).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnSpec {
    #[serde(default = "one")]
    pub scale: f64,
    #[serde(default)]
    pub offset: f64,
    #[serde(default)]
    pub unit: Option<String>,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelMapping {
    pub topic: String,
    #[serde(default, rename = "type")]
    pub type_name: Option<String>,
    /// Message field → column name.
    pub fields: BTreeMap<String, String>,
    #[serde(default)]
    pub constants: BTreeMap<String, toml::Value>,
    /// This channel's own time (a phone's fix time beside its IMU's), else the table's.
    #[serde(default)]
    pub time: Option<TimeSpec>,
    /// For `horizontal_accuracy_m` / `vertical_accuracy_m`: the probability that the stated
    /// radius holds the true position (0.68 for phones' accuracies); without it each is one σ
    /// (per horizontal axis, and of the height).
    #[serde(default)]
    pub accuracy_confidence: Option<f64>,
}

impl CsvMapping {
    /// Reads and checks a mapping file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?;
        let mut map: CsvMapping = toml::from_str(&text)
            .map_err(|e| Error::run(path, e.to_string().trim().replace('\n', " ")))?;
        map.fold_short_time(path)?;
        map.check(path)?;
        Ok(map)
    }

    /// `time_column`/`time_unit`/`time_offset_ns` into `[time]`.
    fn fold_short_time(&mut self, path: &Path) -> Result<()> {
        let short =
            self.time_column.is_some() || self.time_unit.is_some() || self.time_offset_ns.is_some();
        if !short {
            return Ok(());
        }
        if self.time.is_some() {
            return Err(Error::run(
                path,
                "give the time once: `[time]` or `time_column`, not both",
            ));
        }
        let offset = self.time_offset_ns.unwrap_or(0);
        self.time = Some(TimeSpec {
            column: self.time_column.take(),
            unit: Some(self.time_unit.take().unwrap_or_else(|| "s".into())),
            offset_ns: i64::try_from(offset)
                .map_err(|_| Error::run(path, format!("time_offset_ns {offset} is too large")))?,
            ..TimeSpec::default()
        });
        self.time_offset_ns = None;
        Ok(())
    }

    fn check(&self, path: &Path) -> Result<()> {
        let bad = |cause: String| Err(Error::run(path, cause));
        if self.delimiter.len() != 1 && self.delimiter != "\t" {
            return bad(format!(
                "delimiter '{}' must be one character",
                self.delimiter
            ));
        }
        match (self.decimal.as_str(), self.delimiter.as_str()) {
            (".", _) => {}
            (",", ",") => return bad("decimal ',' needs another delimiter (';')".into()),
            (",", _) => {}
            (d, _) => return bad(format!("decimal '{d}': '.' or ','")),
        }
        if self.channel.is_empty() {
            return bad("no [[channel]]: nothing to read".into());
        }
        for c in &self.channel {
            if c.time.as_ref().is_some_and(|t| t.spread.is_some()) {
                return bad(format!(
                    "channel {}: `spread` is the table's `[time]`, not a channel's",
                    c.topic
                ));
            }
            if let Some(p) = c.accuracy_confidence.filter(|p| !(*p > 0.0 && *p < 1.0)) {
                return bad(format!(
                    "channel {}: accuracy_confidence {p}: a probability between 0 and 1",
                    c.topic
                ));
            }
        }
        for (name, c) in &self.columns {
            if !(c.scale.is_finite() && c.offset.is_finite()) {
                return bad(format!("columns.{name}: scale and offset must be numbers"));
            }
        }
        Ok(())
    }

    /// The delimiter as the CSV reader takes it.
    pub fn delimiter_byte(&self) -> u8 {
        self.delimiter.as_bytes().first().copied().unwrap_or(b',')
    }
}

/// A mapping with the path it was read from (for messages that name it).
#[derive(Debug, Clone, PartialEq)]
pub struct MappingFile {
    pub path: PathBuf,
    pub mapping: CsvMapping,
}

impl MappingFile {
    pub fn read(path: &Path) -> Result<Self> {
        Ok(Self {
            path: path.to_owned(),
            mapping: CsvMapping::read(path)?,
        })
    }
}
