//! A run: whatever set of files holds one test run, read as one log.
//!
//! A field run is rarely one file: `ros2 bag record` writes a bag directory (`metadata.yaml`
//! and `<name>_0.mcap`, `_1.mcap`, …), `railfuse record --split-*` writes `run-001.mcap`,
//! `run-002.mcap`, …, and two or three recorders on a train each write their own files on
//! their own clocks. [`Run::open`] resolves the inputs a command was given (files,
//! directories of parts, bag directories) into parts, and [`RunReader`] reads them as one
//! log: a streaming k-way merge by time, every channel and schema under one id for the run,
//! each part's clock corrected. Every command that reads logs goes through it, as rosbag2's
//! one reader sits under `play`, `convert` and `info`.
//!
//! - **Order.** Messages leave in order of their (corrected) time on the chosen basis (log or
//!   publish time); equal times leave in input order, then part order, then file order. Within
//!   one file the file's own order is kept, so a one-file run reads exactly as the file.
//! - **Memory.** A part is opened only once the merge reaches the earliest time it can hold
//!   (from its summary's statistics or the bag's `starting_time`) and closed when it ends:
//!   parts of a split run are read one or two at a time, whatever their number.
//! - **Split boundaries.** The same message twice (one topic, one time, one payload, in two
//!   parts) leaves once and is counted; one topic from two parts whose spans interleave is two
//!   sources on one topic, refused with a hint.

mod align;
mod bag;
mod channels;
mod clock;
mod merge;
mod reader;
mod sequential;
mod stamp_order;

use std::path::{Path, PathBuf};

pub use align::{Align, Alignment, ClockEstimate, ClockSource, NoEstimate};
pub use bag::{write_manifest, ManifestFile, ManifestTopic, METADATA as MANIFEST};
pub use clock::{ClockMap, ClockOffset};
pub use merge::{merge, MergeReport, MERGE_METADATA};
pub use reader::{MergeCounts, RunReader};
pub use sequential::Sequential;

use crate::error::{Error, Result};
pub use crate::formats::Storage;
use crate::formats::{Converted, FormatOptions};

/// A part of another tool's format, converted to a temporary MCAP file when the run was
/// opened (once, however often the run is read), removed with the run.
#[derive(Debug)]
pub struct ConvertedPart {
    pub mcap: tempfile::TempPath,
    pub report: Converted,
}

/// Which time orders the merge and is each message's log time downstream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeBasis {
    /// When the recorder received the message (rosbag2's `received`).
    #[default]
    Log,
    /// When the sender published it (rosbag2's `sent`).
    Publish,
    /// The message's own stamp (when the sensor measured it), as PlotJuggler's header-stamp
    /// option: each part held back by a window so its stamps leave in order.
    Stamp,
}

impl std::str::FromStr for TimeBasis {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "log" => Ok(Self::Log),
            "publish" => Ok(Self::Publish),
            "stamp" => Ok(Self::Stamp),
            other => Err(format!("time basis '{other}': use log, publish or stamp")),
        }
    }
}

/// One file of a run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Part {
    pub path: PathBuf,
    /// Which of the inputs it came from (0-based): ties in time leave in input order.
    pub input: usize,
    pub storage: Storage,
    /// What the bag's metadata.yaml says of it, where it came from one.
    pub listed_start_ns: Option<u64>,
    pub listed_duration_ns: Option<u64>,
    pub listed_messages: Option<u64>,
    /// Its clock against the run's time.
    pub clock: ClockMap,
    /// Its conversion, for a part of another tool's format.
    #[serde(skip)]
    pub converted: Option<std::sync::Arc<ConvertedPart>>,
}

/// A part a bag's metadata.yaml lists that is not there (read with `allow_missing_parts`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct MissingPart {
    pub path: PathBuf,
    pub start_ns: Option<u64>,
    pub duration_ns: Option<u64>,
    pub messages: Option<u64>,
}

/// What to read a run with.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub time: TimeBasis,
    /// Clock offsets by file (a part, or an input: every part of it).
    pub clock_offsets: Vec<ClockOffset>,
    /// Read a bag whose metadata.yaml lists a part that is not there (the gap is named).
    pub allow_missing_parts: bool,
    /// Put the recorders on one clock through the GNSS time each logged.
    pub align: Align,
    /// How files of other tools' formats are read.
    pub formats: FormatOptions,
}

/// The files of one run, resolved and in order.
#[derive(Debug, Clone)]
pub struct Run {
    inputs: Vec<PathBuf>,
    parts: Vec<Part>,
    missing: Vec<MissingPart>,
    time: TimeBasis,
    /// The clocks estimated by `--align gnss`.
    alignment: Option<Alignment>,
}

impl Run {
    /// A run of one MCAP file, read as it is.
    pub fn file(path: impl AsRef<Path>) -> Self {
        let path = path.as_ref().to_owned();
        Self {
            inputs: vec![path.clone()],
            parts: vec![Part {
                storage: Storage::Mcap,
                ..Part::new(path, 0)
            }],
            missing: Vec::new(),
            time: TimeBasis::Log,
            alignment: None,
        }
    }

    /// Resolves `inputs` (files, directories of parts, rosbag2 bag directories) into one run.
    pub fn open(inputs: &[PathBuf], options: &RunOptions) -> Result<Self> {
        let Some(first) = inputs.first() else {
            return Err(Error::run(
                Path::new("."),
                "no input: name a log file, bag or directory",
            ));
        };
        let mut run = Self {
            inputs: inputs.to_vec(),
            parts: Vec::new(),
            missing: Vec::new(),
            time: options.time,
            alignment: None,
        };
        for (input, path) in inputs.iter().enumerate() {
            let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
            if meta.is_dir() {
                run.directory(input, path, options)?;
            } else {
                run.parts.push(Part::new(path.clone(), input));
            }
        }
        for part in &mut run.parts {
            part.convert(&options.formats)?;
        }
        for (i, a) in run.parts.iter().enumerate() {
            if let Some(b) = run.parts[..i].iter().find(|b| same_file(&a.path, &b.path)) {
                return Err(Error::run(
                    &a.path,
                    format!(
                        "given twice (also as {}): name each file once",
                        b.path.display()
                    ),
                ));
            }
        }
        for offset in &options.clock_offsets {
            offset.apply(first, &run.inputs, &mut run.parts)?;
        }
        if options.align == Align::Gnss {
            let given: Vec<PathBuf> = options
                .clock_offsets
                .iter()
                .map(|o| o.file.clone())
                .collect();
            let alignment = run.align_gnss(&given)?;
            if alignment.reference.is_none() {
                return Err(align::no_gnss_time(&run, &alignment));
            }
            run.alignment = Some(alignment);
        }
        Ok(run)
    }

    /// The parts of a directory: a bag's, from its metadata.yaml, else every log file in it.
    fn directory(&mut self, input: usize, dir: &Path, options: &RunOptions) -> Result<()> {
        let metadata = dir.join(bag::METADATA);
        if metadata.exists() {
            let listed = bag::read(&metadata)?;
            for part in listed.parts {
                let path = dir.join(&part.name);
                if !path.exists() {
                    if !options.allow_missing_parts {
                        let partial = crate::log::partial_path(&path);
                        let salvage = match partial.exists() {
                            true => format!(
                                " ({} is: a recording cut off, `railfuse recover {} -o {}` \
                                 salvages it)",
                                partial.display(),
                                partial.display(),
                                path.display()
                            ),
                            false => String::new(),
                        };
                        return Err(Error::run(
                            &path,
                            format!(
                                "listed in {} but not there{salvage}; --allow-missing-parts \
                                 reads the rest and names the gap",
                                metadata.display()
                            ),
                        ));
                    }
                    self.missing.push(MissingPart {
                        path,
                        start_ns: part.start_ns,
                        duration_ns: part.duration_ns,
                        messages: part.messages,
                    });
                    continue;
                }
                self.parts.push(Part {
                    storage: listed.storage,
                    listed_start_ns: part.start_ns,
                    listed_duration_ns: part.duration_ns,
                    listed_messages: part.messages,
                    ..Part::new(path, input)
                });
            }
            return Ok(());
        }
        // As `ros2 bag reindex` would: the storage files, in their numbered order. A table
        // is a part only with a mapping to read it (a directory of logs often holds others).
        let tables = options.formats.csv.is_some();
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| Error::io(dir, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.is_file() && Storage::of_name(p).is_some_and(|s| s != Storage::Csv || tables)
            })
            .collect();
        files.sort_by(|a, b| natural_order(&a.to_string_lossy(), &b.to_string_lossy()));
        if files.is_empty() {
            let partial = std::fs::read_dir(dir)
                .map_err(|e| Error::io(dir, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .find(|p| p.to_string_lossy().ends_with(".partial"));
            let cause = match partial {
                Some(p) => format!(
                    "no finished log file, only {} (left by a recording that did not finish: \
                     `railfuse recover` salvages it)",
                    p.display()
                ),
                None => {
                    "no .mcap, .db3, .gpx or .mf4 file and no metadata.yaml: not a run".to_owned()
                }
            };
            return Err(Error::run(dir, cause));
        }
        self.parts
            .extend(files.into_iter().map(|p| Part::new(p, input)));
        Ok(())
    }

    /// The inputs as given.
    pub fn inputs(&self) -> &[PathBuf] {
        &self.inputs
    }

    /// The path that names the run in messages: its one input.
    pub fn name(&self) -> &Path {
        &self.inputs[0]
    }

    /// The run as said to a person: its input, or its first input and how many more.
    pub fn display(&self) -> String {
        match self.inputs.len() {
            1 => self.inputs[0].display().to_string(),
            n => format!("{} (+{} more)", self.inputs[0].display(), n - 1),
        }
    }

    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// The parts converted from other tools' formats, with what each conversion read.
    pub fn conversions(&self) -> impl Iterator<Item = (&Path, &Converted)> {
        self.parts
            .iter()
            .filter_map(|p| p.converted.as_ref().map(|c| (p.path.as_path(), &c.report)))
    }

    /// Parts a bag lists that are not there.
    pub fn missing(&self) -> &[MissingPart] {
        &self.missing
    }

    /// The recorders' clocks as `--align gnss` estimated them.
    pub fn alignment(&self) -> Option<&Alignment> {
        self.alignment.as_ref()
    }

    pub fn time_basis(&self) -> TimeBasis {
        self.time
    }

    /// The one MCAP file this run is, read as it is (no clock correction, log time): such a
    /// run can be copied chunk by chunk.
    pub fn single_file(&self) -> Option<&Path> {
        match (&self.parts[..], self.time) {
            ([p], TimeBasis::Log) if p.storage == Storage::Mcap && p.clock.is_identity() => {
                Some(&p.path)
            }
            _ => None,
        }
    }

    /// Bytes of every part, for progress.
    pub fn total_bytes(&self) -> u64 {
        self.parts
            .iter()
            .map(|p| std::fs::metadata(&p.path).map_or(0, |m| m.len()))
            .sum()
    }

    /// Where each part begins and ends on the run's clock (its summary's messages, else the
    /// bag's `starting_time` and `duration`), where known.
    pub fn part_spans(&self) -> Result<Vec<Option<(u64, u64)>>> {
        self.parts
            .iter()
            .map(|p| {
                let listed = p
                    .listed_start_ns
                    .map(|t| (t, t + p.listed_duration_ns.unwrap_or(0)));
                let span = match listed {
                    Some(span) => Some(span),
                    None => {
                        crate::log::read_summary(p.mcap_path())?.and_then(|s| s.message_span_ns)
                    }
                };
                Ok(span.map(|(a, b)| (p.clock.correct(a), p.clock.correct(b))))
            })
            .collect()
    }

    /// Opens the merged reader.
    pub fn reader(&self) -> Result<RunReader> {
        RunReader::open(self)
    }
}

impl Part {
    fn new(path: PathBuf, input: usize) -> Self {
        Self {
            storage: Storage::of_file(&path),
            path,
            input,
            listed_start_ns: None,
            listed_duration_ns: None,
            listed_messages: None,
            clock: ClockMap::default(),
            converted: None,
        }
    }

    /// The MCAP file the run reader reads for this part: its own, or its conversion.
    pub fn mcap_path(&self) -> &Path {
        match &self.converted {
            Some(c) => &c.mcap,
            None => &self.path,
        }
    }

    /// Converts a part of another tool's format into a temporary MCAP file.
    fn convert(&mut self, options: &FormatOptions) -> Result<()> {
        if !self.storage.is_converted() || self.converted.is_some() {
            return Ok(());
        }
        let mcap = tempfile::Builder::new()
            .prefix("railfuse-part-")
            .suffix(".mcap")
            .tempfile()
            .map_err(|e| Error::io(&self.path, e))?
            .into_temp_path();
        // Read once by the run reader: no Foxglove twins, which only a viewer reads.
        let writer = crate::log::WriterOptions {
            foxglove: false,
            ..Default::default()
        };
        let report = crate::formats::convert(self.storage, &self.path, &mcap, options, &writer)?;
        self.converted = Some(std::sync::Arc::new(ConvertedPart { mcap, report }));
        Ok(())
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    same_file::is_same_file(a, b).unwrap_or(a == b)
}

/// Names in their numbered order: `bag_2` before `bag_10`, `run-009` before `run-010`.
fn natural_order(a: &str, b: &str) -> std::cmp::Ordering {
    fn pieces(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[i - 1].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (pa, pb) = (pieces(a), pieces(b));
    for (x, y) in pa.iter().zip(&pb) {
        let o = match (x, y) {
            ((true, x), (true, y)) => {
                let (x, y) = (x.trim_start_matches('0'), y.trim_start_matches('0'));
                x.len().cmp(&y.len()).then(x.cmp(y))
            }
            ((_, x), (_, y)) => x.cmp(y),
        };
        if o.is_ne() {
            return o;
        }
    }
    pa.len().cmp(&pb.len()).then(a.cmp(b))
}

#[cfg(test)]
mod tests;
