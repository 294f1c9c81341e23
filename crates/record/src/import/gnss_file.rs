//! NMEA 0183 and u-blox UBX files (a receiver's output captured to disk) into `/gnss/fix`,
//! through the recorder's own stream decoders: same checksums, same bounds, same counting of
//! what does not decode. GNSS time is the sensor time and, with no receive time in a file, the
//! log time too.

use std::io::Read;
use std::path::Path;

use railfuse_catalog::log::LogWriter;
use railfuse_catalog::messages::{AnyMessage, GnssFix, SourceStats};
use railfuse_catalog::{topics, Error, Result};

use super::ImportReport;
use crate::recorder::stream::{StreamDecoder, StreamFormat};

/// `date`: the UTC date of NMEA fixes that come before any RMC or ZDA sentence (without it,
/// they wait for the first such sentence; those that never get a date are dropped, counted).
pub fn import(
    input: &Path,
    output: &Path,
    format: StreamFormat,
    date: Option<crate::decode::nmea::Date>,
) -> Result<ImportReport> {
    let mut report = ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: format!("{format:?}").to_lowercase(),
        time_base: "GNSS time of each solution (UTC)".into(),
        ..Default::default()
    };
    let io = |source| Error::Io {
        path: input.to_owned(),
        source,
    };
    let mut file = std::fs::File::open(input).map_err(io)?;
    let mut writer = LogWriter::create(output)?;
    let channel = writer.add_channel::<GnssFix>(topics::GNSS_FIX)?;
    let mut decoder = StreamDecoder::with_date(format, date);
    let mut stats = SourceStats::default();
    let (mut buf, mut items) = (vec![0u8; 64 << 10], Vec::new());
    let mut eof = false;
    while !eof {
        let n = file.read(&mut buf).map_err(io)?;
        if n == 0 {
            eof = true;
            decoder.finish(0, &mut stats, &mut items);
        } else {
            report.bytes += n as u64;
            decoder.feed(&buf[..n], 0, &mut stats, &mut items);
        }
        for item in items.drain(..) {
            let AnyMessage::GnssFix(fix) = item.message else {
                continue;
            };
            writer.write(channel, fix.stamp_ns, &fix)?;
            report.messages += 1;
            *report
                .per_topic
                .entry(topics::GNSS_FIX.to_owned())
                .or_insert(0) += 1;
        }
    }
    report.lines = decoder.lines();
    report.skipped = stats.skipped;
    report.first_problems = stats.first_problems;
    report.warnings = stats.warnings;
    writer.finish()?;
    Ok(report)
}
