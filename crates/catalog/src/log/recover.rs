//! Salvage of a damaged log: a recorder killed mid-run, a power cut, a truncated copy, a disk
//! that flipped bytes in the middle. Every intact record, before and after any damage, is
//! copied in order into a new, complete log with its summary and indexes; intact chunks are
//! copied byte for byte. The report says how much was saved and each stretch that was
//! skipped, where and why.
//!
//! A chunk is either whole or lost: its records are compressed together and checked by CRC.
//! Channels whose defining record was lost with a damaged chunk are taken from the file's
//! summary when the end of the file is intact; messages on channels known from neither are
//! counted as orphans.

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use mcap::records::op;
use serde::Serialize;

use super::format::{self, Records};
use super::scan::{Damage, Item, Scanner};
use super::{read_channels, LogWriter};
use crate::error::{Error, Result};

#[derive(Debug, Clone, Default, Serialize)]
pub struct RecoverReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_bytes: u64,
    pub schemas: u64,
    pub channels: u64,
    pub messages: u64,
    pub metadata: u64,
    pub attachments: u64,
    /// Intact chunks copied as they were.
    pub chunks: u64,
    pub messages_per_topic: BTreeMap<String, u64>,
    /// Each stretch of the input that held no intact record, in file order.
    pub skipped: Vec<Damage>,
    /// The first damage, in words (None for an intact file).
    pub stopped_by: Option<String>,
    /// Messages on channels whose channel record was lost (skipped).
    pub orphan_messages: u64,
}

/// The file `recover` writes `output` through until it is complete: `<output>.partial`, or,
/// where that is the input itself (`recover run.mcap.partial -o run.mcap`, the usual case),
/// `<output>.recovering`. The input is never written over, truncated or deleted: an output
/// that is the input (the same path, or a hard or symbolic link to it) is refused.
fn working_path(input: &Path, output: &Path) -> Result<PathBuf> {
    let same = |p: &Path| same_file::is_same_file(input, p).unwrap_or(false);
    if same(output) {
        return Err(Error::OutputIsInput {
            input: input.to_owned(),
            output: output.to_owned(),
        });
    }
    let partial = super::partial_path(output);
    if !same(&partial) {
        return Ok(partial);
    }
    let mut working = output.as_os_str().to_owned();
    working.push(".recovering");
    let working = PathBuf::from(working);
    if same(&working) {
        return Err(Error::OutputIsInput {
            input: input.to_owned(),
            output: working,
        });
    }
    Ok(working)
}

/// Copies every intact record of `input` into a complete log at `output`.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport> {
    let working = working_path(input, output)?;
    let mut scanner = Scanner::salvage(input)?;
    let mut report = RecoverReport {
        input: input.to_owned(),
        output: output.to_owned(),
        input_bytes: scanner.size(),
        ..Default::default()
    };
    let mut writer = LogWriter::create_working(output, &working, &Default::default())?;
    let mut channels: BTreeMap<u16, String> = BTreeMap::new();
    // Channels lost with a damaged chunk may still be in an intact summary.
    let mut from_summary = BTreeMap::new();
    if let Ok(Some(summary)) = read_channels(input) {
        for c in summary {
            from_summary.insert(c.id, c);
        }
    }
    let mut schemas = HashSet::new();
    while let Some(item) = scanner.next() {
        match item? {
            Item::Damage(d) => {
                report
                    .stopped_by
                    .get_or_insert_with(|| format!("byte {}: {}", d.offset, d.cause));
                report.skipped.push(d);
            }
            Item::Chunk(chunk) => {
                // Copied as it is unless a channel in it, or a message's channel, lost its
                // definition with the damage (and the summary cannot give it back).
                let mut whole = true;
                let mut counts: Vec<(u16, u64)> = Vec::new();
                for record in Records::new(&chunk.records) {
                    let record = record.map_err(|e| Error::mcap(input, e))?;
                    match record.opcode {
                        op::SCHEMA => {
                            schemas.insert(u16::from_le_bytes([record.body[0], record.body[1]]));
                        }
                        op::CHANNEL => {
                            let Ok(mcap::records::Record::Channel(c)) =
                                mcap::parse_record(op::CHANNEL, record.body)
                            else {
                                whole = false;
                                continue;
                            };
                            let known = c.schema_id == 0
                                || schemas.contains(&c.schema_id)
                                || restore_schema(
                                    &mut writer,
                                    c.schema_id,
                                    &from_summary,
                                    &mut schemas,
                                )?;
                            if known {
                                channels.insert(c.id, c.topic);
                            } else {
                                whole = false;
                            }
                        }
                        op::MESSAGE => {
                            let Some(m) = format::parse_message(record.body) else {
                                continue;
                            };
                            let id = m.header.channel_id;
                            if !channels.contains_key(&id)
                                && !restore(
                                    &mut writer,
                                    id,
                                    &from_summary,
                                    &mut channels,
                                    &mut schemas,
                                )?
                            {
                                whole = false;
                            }
                            match counts.last_mut() {
                                Some((c, n)) if *c == id => *n += 1,
                                _ => counts.push((id, 1)),
                            }
                        }
                        _ => {}
                    }
                }
                if whole {
                    writer.copy_chunk(chunk)?;
                    report.chunks += 1;
                    for (id, n) in counts {
                        count(&mut report, &channels[&id], n);
                    }
                } else {
                    // Record by record, leaving out channels defined nowhere (orphans).
                    let (copied, orphans) = writer
                        .copy_records_where(&chunk.records, |id| channels.contains_key(&id))?;
                    report.orphan_messages += orphans;
                    for (id, n) in copied {
                        count(&mut report, &channels[&id], n);
                    }
                }
            }
            Item::Record { opcode, body, .. } => match mcap::parse_record(opcode, &body) {
                Ok(mcap::records::Record::Schema { header, data }) => {
                    writer.copy_schema(header.id, &header.name, &header.encoding, &data)?;
                    schemas.insert(header.id);
                }
                Ok(mcap::records::Record::Channel(c)) => {
                    // A channel whose schema was lost (and is not in the summary) is left out.
                    let known = c.schema_id == 0
                        || schemas.contains(&c.schema_id)
                        || restore_schema(&mut writer, c.schema_id, &from_summary, &mut schemas)?;
                    if known {
                        let (id, schema, topic) = (c.id, c.schema_id, &c.topic);
                        writer.copy_channel(id, schema, topic, &c.message_encoding, &c.metadata)?;
                        channels.insert(c.id, c.topic);
                    }
                }
                Ok(mcap::records::Record::Message { header, data }) => {
                    if !channels.contains_key(&header.channel_id)
                        && !restore(
                            &mut writer,
                            header.channel_id,
                            &from_summary,
                            &mut channels,
                            &mut schemas,
                        )?
                    {
                        report.orphan_messages += 1;
                        continue;
                    }
                    writer.write_raw(
                        header.channel_id,
                        header.sequence,
                        header.log_time,
                        header.publish_time,
                        &data,
                    )?;
                    count(&mut report, &channels[&header.channel_id], 1);
                }
                Ok(mcap::records::Record::Metadata(m)) => {
                    writer.write_metadata(&m.name, m.metadata)?;
                    report.metadata += 1;
                }
                Ok(mcap::records::Record::Attachment { header, data, .. }) => {
                    writer.attach(
                        &header.name,
                        &header.media_type,
                        header.log_time,
                        header.create_time,
                        &data,
                    )?;
                    report.attachments += 1;
                }
                _ => {}
            },
        }
    }
    report.schemas = schemas.len() as u64;
    report.channels = channels.len() as u64;
    writer.finish()?;
    Ok(report)
}

fn count(report: &mut RecoverReport, topic: &str, n: u64) {
    report.messages += n;
    *report
        .messages_per_topic
        .entry(topic.to_owned())
        .or_insert(0) += n;
}

type Summary = BTreeMap<u16, std::sync::Arc<super::ChannelInfo>>;

/// Writes the summary's definition of channel `id` (and its schema), if the summary has it.
fn restore(
    writer: &mut LogWriter,
    id: u16,
    summary: &Summary,
    channels: &mut BTreeMap<u16, String>,
    schemas: &mut HashSet<u16>,
) -> Result<bool> {
    let Some(c) = summary.get(&id) else {
        return Ok(false);
    };
    if let Some(s) = &c.schema {
        writer.copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
        schemas.insert(s.id);
    }
    let schema_id = c.schema.as_ref().map_or(0, |s| s.id);
    writer.copy_channel(id, schema_id, &c.topic, &c.message_encoding, &c.metadata)?;
    channels.insert(id, c.topic.clone());
    Ok(true)
}

/// Writes the summary's schema `id`, if a channel of the summary uses it.
fn restore_schema(
    writer: &mut LogWriter,
    id: u16,
    summary: &Summary,
    schemas: &mut HashSet<u16>,
) -> Result<bool> {
    let Some(s) = summary
        .values()
        .filter_map(|c| c.schema.as_ref())
        .find(|s| s.id == id)
    else {
        return Ok(false);
    };
    writer.copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
    schemas.insert(id);
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::{LogReader, LogRecord, WriterOptions};
    use crate::messages::RadarSpeed;

    fn log(path: &Path, n: u64) -> Vec<u8> {
        let opts = WriterOptions {
            chunk_size: 64 << 10,
            zstd_level: 1,
            ..WriterOptions::default()
        };
        let mut w = LogWriter::create_with(path, &opts).unwrap();
        let ch = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
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
        std::fs::read(path).unwrap()
    }

    /// The stamps of a log's messages, in file order.
    fn stamps(path: &Path) -> Vec<u64> {
        let mut reader = LogReader::open(path).unwrap();
        let mut out = Vec::new();
        while let Some(rec) = reader.next() {
            if let LogRecord::Message(m) = rec.unwrap() {
                out.push(m.decode::<RadarSpeed>(path).unwrap().stamp_ns);
            }
        }
        out
    }

    #[test]
    fn a_log_cut_anywhere_gives_back_every_complete_chunk_and_a_valid_file() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("full.mcap");
        let n = 60_000u64;
        let bytes = log(&path, n);
        let whole = recover(&path, &d.path().join("whole.mcap")).unwrap();
        assert_eq!((whole.messages, whole.stopped_by.as_deref()), (n, None));
        let mut last = 0;
        for cut in [0.2, 0.5, 0.9] {
            let broken = d.path().join("broken.mcap");
            std::fs::write(&broken, &bytes[..(bytes.len() as f64 * cut) as usize]).unwrap();
            let fixed = d.path().join("fixed.mcap");
            let r = recover(&broken, &fixed).unwrap();
            assert!(
                r.stopped_by.as_deref().unwrap().contains("truncated"),
                "{r:?}"
            );
            // Everything but the cut chunk (≈ 64 KiB of JSON, under 1 000 messages) survives,
            // as the same messages in the same order.
            assert!(
                r.messages as f64 > n as f64 * cut - 1000.0 - n as f64 * 0.05,
                "cut {cut}: {} of {n}",
                r.messages
            );
            assert!(r.messages > last);
            last = r.messages;
            let got = stamps(&fixed);
            assert_eq!(got, (0..r.messages).collect::<Vec<_>>());
        }
    }

    #[test]
    fn damage_in_the_middle_costs_only_the_damaged_chunk() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("full.mcap");
        let n = 60_000u64;
        let bytes = log(&path, n);
        // A spot inside the compressed data of the chunk nearest the middle of the file.
        let mut scanner = Scanner::open(&path).unwrap();
        let mut mid = 0;
        while let Some(item) = scanner.next() {
            if let Item::Chunk(c) = item.unwrap() {
                if c.offset as usize > bytes.len() / 2 {
                    mid = c.offset as usize + 200;
                    break;
                }
            }
        }
        let garbage: Vec<u8> = (0..5000u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        let cases: Vec<(&str, Vec<u8>)> = vec![
            ("flipped bytes", {
                let mut b = bytes.clone();
                for x in &mut b[mid..mid + 64] {
                    *x ^= 0x5a;
                }
                b
            }),
            (
                "garbage inserted",
                [&bytes[..mid], &garbage[..], &bytes[mid..]].concat(),
            ),
            (
                "torn write",
                [&bytes[..mid], &bytes[mid + 20_000..]].concat(),
            ),
        ];
        for (label, broken_bytes) in cases {
            let broken = d.path().join("broken.mcap");
            std::fs::write(&broken, &broken_bytes).unwrap();
            // Strict readers name the damage and the way out.
            let mut reader = LogReader::open(&broken).unwrap();
            let err = loop {
                match reader.next() {
                    Some(Ok(_)) => continue,
                    Some(Err(e)) => break e.to_string(),
                    None => panic!("{label}: read a damaged file to the end"),
                }
            };
            assert!(
                err.contains("damaged at byte") && err.contains("railfuse recover"),
                "{err}"
            );
            let fixed = d.path().join("fixed.mcap");
            let r = recover(&broken, &fixed).unwrap();
            assert!(!r.skipped.is_empty(), "{label}: {r:?}");
            let got = stamps(&fixed);
            // In order, no duplicates, and at most two chunks' worth (≈ 2 × 1 000) lost.
            assert!(got.windows(2).all(|w| w[0] < w[1]), "{label}: out of order");
            assert!(
                got.len() as u64 > n - 2_000,
                "{label}: {} of {n}",
                got.len()
            );
            assert_eq!(
                *got.last().unwrap(),
                n - 1,
                "{label}: the chunks after the damage"
            );
            assert_eq!(r.messages, got.len() as u64);
        }
    }
}
