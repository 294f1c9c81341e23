//! CAN bus logs of other tools into railfuse channels: can-utils' `candump -l` log,
//! Vector's ASC and BLF, ASAM MDF 4 bus logging, through the readers of [`railfuse_can`] and the recorder's own
//! [`CanDecoder`] (so an imported bus is the same channels a live one is). The log's stamp is
//! each frame's bus time and, with no receive time in a file, its log time too.
//!
//! A line that does not parse is skipped and counted with its number; the import goes on.

use std::io::BufReader;
use std::path::Path;

use railfuse_can::dbc::BusDbcs;
use railfuse_can::frame::Frame;
use railfuse_can::lines::BadLine;
use railfuse_catalog::log::LogWriter;
use railfuse_catalog::messages::SourceStats;
use railfuse_catalog::{Error, Result};

use super::ImportReport;
use crate::decode::can::CanDecoder;
use crate::recorder::message::ItemWriter;

/// The CAN log formats read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CanLog {
    /// can-utils' `candump -l`: `(1700000000.123456) can0 123#DEADBEEF`.
    Candump,
    /// Vector's ASC (CANalyzer, CANoe).
    Asc,
    /// Vector's BLF (binary).
    Blf,
    /// ASAM MDF 4 bus logging (CSS CANedge, Vector): `railfuse-mdf`'s reading.
    Mdf4,
}

/// Imports the CAN log `input` to `output`, decoding each bus with its DBC of `dbcs`.
pub fn import(input: &Path, output: &Path, format: CanLog, dbcs: BusDbcs) -> Result<ImportReport> {
    let mut report = ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: format!("{format:?}").to_lowercase(),
        time_base: match format {
            CanLog::Candump => "each frame's stamp in the log (seconds since the Unix epoch)",
            CanLog::Asc => "the trigger block's date (taken as UTC) plus each line's offset",
            CanLog::Blf => "the file header's start (taken as UTC) plus each object's offset",
            CanLog::Mdf4 => "the header's start (UTC) plus each record's master time",
        }
        .into(),
        ..Default::default()
    };
    let fault = |cause: String| Error::Run {
        path: input.to_owned(),
        cause,
    };
    let file = std::fs::File::open(input).map_err(|source| Error::Io {
        path: input.to_owned(),
        source,
    })?;
    let file = BufReader::with_capacity(64 << 10, file);
    let mut frames = match format {
        CanLog::Candump => Frames::Candump(railfuse_can::candump::Reader::new(file)),
        CanLog::Asc => Frames::Asc(railfuse_can::asc::Reader::new(file)),
        CanLog::Blf => {
            Frames::Blf(railfuse_can::blf::Reader::new(file).map_err(|e| fault(e.to_string()))?)
        }
        CanLog::Mdf4 => Frames::Mdf4(Box::new(
            railfuse_mdf::bus::BusFrames::open(input).map_err(|e| fault(e.to_string()))?,
        )),
    };
    let mut writer = ItemWriter::new(LogWriter::create(output)?);
    let mut decoder = CanDecoder::new(dbcs);
    let (mut stats, mut items) = (SourceStats::default(), Vec::new());
    for frame in frames.by_ref() {
        match frame {
            Ok(f) => decoder.frame(&f, f.stamp_ns, &mut stats, &mut items),
            Err(Bad::Line(bad)) => {
                report.skip(bad.line as u64, "line that does not parse", bad.reason)
            }
            // A BLF that breaks its format cannot be read on: what came before is kept.
            Err(Bad::Object(bad)) => {
                *report
                    .skipped
                    .entry("the rest of a broken BLF".into())
                    .or_insert(0) += 1;
                report.first_problems.push(bad.to_string());
            }
        }
        for item in items.drain(..) {
            let item = writer.write(item)?;
            report.messages += 1;
            match report.per_topic.get_mut(&item.topic) {
                Some(n) => *n += 1,
                None => {
                    report.per_topic.insert(item.topic.clone(), 1);
                }
            }
        }
    }
    for (reason, n) in stats.skipped {
        *report.skipped.entry(reason).or_insert(0) += n;
    }
    report.warnings = stats.warnings;
    match &frames {
        Frames::Blf(r) => report.bytes = r.bytes_read(),
        Frames::Mdf4(r) => mdf4_report(&r.report, &mut report),
        _ => report.lines = frames.lines_read() as u64,
    }
    writer.writer.finish()?;
    Ok(report)
}

/// What an MDF file's reading said, into the import's report.
fn mdf4_report(r: &railfuse_mdf::bus::BusReport, report: &mut ImportReport) {
    report.bytes = std::fs::metadata(&report.input).map_or(0, |m| m.len());
    for (why, n) in r.not_used() {
        *report.skipped.entry(why).or_insert(0) += n;
    }
    if let Some(d) = &r.damage {
        report
            .warnings
            .insert(format!("damaged, read up to it: {d}"), 1);
    }
    if !r.finalised {
        report.warnings.insert(
            "not finalised by its logger: read to the end of its data".into(),
            1,
        );
    }
}

/// The frames of a log, in any of the formats.
enum Frames<R> {
    Candump(railfuse_can::candump::Reader<R>),
    Asc(railfuse_can::asc::Reader<R>),
    Blf(railfuse_can::blf::Reader<R>),
    Mdf4(Box<railfuse_mdf::bus::BusFrames>),
}

/// What a log's reader could not read.
enum Bad {
    Line(BadLine),
    Object(railfuse_can::blf::BadObject),
}

impl<R> Frames<R> {
    fn lines_read(&self) -> usize {
        match self {
            Frames::Candump(r) => r.lines_read(),
            Frames::Asc(r) => r.lines_read(),
            Frames::Blf(_) | Frames::Mdf4(_) => 0,
        }
    }
}

impl<R: std::io::BufRead> Iterator for Frames<R> {
    type Item = std::result::Result<Frame, Bad>;
    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Frames::Candump(r) => r.next().map(|f| f.map_err(Bad::Line)),
            Frames::Asc(r) => r.next().map(|f| f.map_err(Bad::Line)),
            Frames::Blf(r) => r.next().map(|f| f.map_err(Bad::Object)),
            Frames::Mdf4(r) => r.next().map(Ok),
        }
    }
}
