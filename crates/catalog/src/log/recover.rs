//! Salvage of a damaged log: a recorder killed mid-run, a power cut, a truncated copy. Every
//! record the file holds intact, up to the first damage (a cut-off or corrupt chunk, a torn
//! record), is copied with its ids into a new, complete log with its summary and indexes; the
//! report says how much was saved and where and why reading stopped.
//!
//! A chunk is either whole or lost: its records are compressed together and checked by CRC,
//! so what survives is everything up to the last completed chunk (the recorder closes chunks
//! at least every second for that reason).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{LogReader, LogRecord, LogWriter};
use crate::error::Result;

#[derive(Debug, Clone, Default, Serialize)]
pub struct RecoverReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_bytes: u64,
    /// Bytes of the input read before the damage (or the whole file).
    pub bytes_read: u64,
    pub schemas: u64,
    pub channels: u64,
    pub messages: u64,
    pub metadata: u64,
    pub attachments: u64,
    pub messages_per_topic: BTreeMap<String, u64>,
    /// Why reading stopped before the end, if it did.
    pub stopped_by: Option<String>,
    /// Messages on channels whose channel record was lost (skipped).
    pub orphan_messages: u64,
}

/// Copies every intact record of `input` into a complete log at `output`.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport> {
    let mut report = RecoverReport {
        input: input.to_owned(),
        output: output.to_owned(),
        input_bytes: std::fs::metadata(input).map(|m| m.len()).unwrap_or(0),
        ..Default::default()
    };
    let mut reader = LogReader::open(input)?;
    let mut writer = LogWriter::create(output)?;
    let mut channels = std::collections::HashSet::new();
    while let Some(record) = reader.next() {
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                report.stopped_by = Some(e.to_string());
                break;
            }
        };
        match record {
            LogRecord::Schema(s) => {
                writer.copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
                report.schemas += 1;
            }
            LogRecord::Channel(c) => {
                writer.copy_channel(
                    c.id,
                    c.schema.as_ref().map_or(0, |s| s.id),
                    &c.topic,
                    &c.message_encoding,
                    &c.metadata,
                )?;
                channels.insert(c.id);
                report.channels += 1;
            }
            LogRecord::Message(m) => {
                if !channels.contains(&m.channel.id) {
                    report.orphan_messages += 1;
                    continue;
                }
                writer.write_raw(
                    m.channel.id,
                    m.sequence,
                    m.log_time_ns,
                    m.publish_time_ns,
                    m.data,
                )?;
                report.messages += 1;
                *report
                    .messages_per_topic
                    .entry(m.channel.topic.clone())
                    .or_insert(0) += 1;
            }
            LogRecord::Metadata { name, metadata } => {
                writer.write_metadata(&name, metadata)?;
                report.metadata += 1;
            }
            LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data,
            } => {
                writer.attach(&name, &media_type, log_time_ns, create_time_ns, data)?;
                report.attachments += 1;
            }
        }
    }
    report.bytes_read = reader.bytes_read().min(report.input_bytes);
    writer.finish()?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::RadarSpeed;

    #[test]
    fn a_log_cut_anywhere_gives_back_every_complete_chunk_and_a_valid_file() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("full.mcap");
        let opts = crate::log::WriterOptions {
            chunk_size: 64 << 10,
            zstd_level: 1,
        };
        let mut w = LogWriter::create_with(&path, &opts).unwrap();
        let ch = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
        let n = 60_000u64;
        for k in 0..n {
            let m = RadarSpeed {
                stamp_ns: k,
                speed_mps: k as f64,
                quality: 1.0,
                valid: true,
                speed_variance_m2ps2: None,
            };
            w.write(ch, k, &m).unwrap();
        }
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let whole = recover(&path, &d.path().join("whole.mcap")).unwrap();
        assert_eq!((whole.messages, whole.stopped_by.as_deref()), (n, None));
        let mut last = 0;
        for cut in [0.2, 0.5, 0.9] {
            let broken = d.path().join("broken.mcap");
            std::fs::write(&broken, &bytes[..(bytes.len() as f64 * cut) as usize]).unwrap();
            let fixed = d.path().join("fixed.mcap");
            let r = recover(&broken, &fixed).unwrap();
            assert!(r.stopped_by.is_some(), "{r:?}");
            // Everything but the cut chunk (≈ 64 KiB of JSON, under 1 000 messages) survives,
            // as the same messages in the same order.
            assert!(
                r.messages as f64 > n as f64 * cut - 1000.0 - n as f64 * 0.05,
                "cut {cut}: {} of {n}",
                r.messages
            );
            assert!(r.messages > last);
            last = r.messages;
            let mut reader = LogReader::open(&fixed).unwrap();
            let mut k = 0u64;
            while let Some(rec) = reader.next() {
                if let LogRecord::Message(m) = rec.unwrap() {
                    let v: RadarSpeed = m.decode(&fixed).unwrap();
                    assert_eq!(v.stamp_ns, k);
                    k += 1;
                }
            }
            assert_eq!(k, r.messages);
        }
    }
}
