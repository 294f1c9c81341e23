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
    let report = RecoverReport {
        input: input.to_owned(),
        output: output.to_owned(),
        input_bytes: scanner.size(),
        ..Default::default()
    };
    let mut salvage = Salvage {
        input,
        writer: LogWriter::create_working(output, &working, &Default::default())?,
        channels: BTreeMap::new(),
        schemas: HashSet::new(),
        // Channels lost with a damaged chunk may still be in an intact summary.
        summary: match read_channels(input) {
            Ok(Some(summary)) => summary.into_iter().map(|c| (c.id, c)).collect(),
            _ => Summary::new(),
        },
        report,
    };
    while let Some(item) = scanner.next() {
        match item? {
            Item::Damage(d) => {
                let r = &mut salvage.report;
                r.stopped_by
                    .get_or_insert_with(|| format!("byte {}: {}", d.offset, d.cause));
                r.skipped.push(d);
            }
            Item::Chunk(chunk) => salvage.chunk(chunk)?,
            Item::Record { opcode, body, .. } => salvage.record(opcode, &body)?,
        }
    }
    let mut report = salvage.report;
    report.schemas = salvage.schemas.len() as u64;
    report.channels = salvage.channels.len() as u64;
    salvage.writer.finish()?;
    Ok(report)
}

type Summary = BTreeMap<u16, std::sync::Arc<super::ChannelInfo>>;

/// The output being written and what it holds so far.
struct Salvage<'a> {
    input: &'a Path,
    writer: LogWriter,
    /// Channels written, with their topics.
    channels: BTreeMap<u16, String>,
    /// Schemas written.
    schemas: HashSet<u16>,
    /// The input's summary, where it is intact.
    summary: Summary,
    report: RecoverReport,
}

impl Salvage<'_> {
    /// A chunk, copied as it is unless a channel in it, or a message's channel, lost its
    /// definition with the damage (and the summary cannot give it back): then record by
    /// record, leaving out the messages of channels defined nowhere (orphans).
    fn chunk(&mut self, chunk: super::scan::Chunk) -> Result<()> {
        let mut whole = true;
        let mut counts: Vec<(u16, u64)> = Vec::new();
        for record in Records::new(&chunk.records) {
            let record = record.map_err(|e| Error::mcap(self.input, e))?;
            match record.opcode {
                op::SCHEMA => {
                    self.schemas
                        .insert(u16::from_le_bytes([record.body[0], record.body[1]]));
                }
                op::CHANNEL => match mcap::parse_record(op::CHANNEL, record.body) {
                    Ok(mcap::records::Record::Channel(c)) if self.schema_known(c.schema_id)? => {
                        self.channels.insert(c.id, c.topic);
                    }
                    _ => whole = false,
                },
                op::MESSAGE => {
                    let Some(m) = format::parse_message(record.body) else {
                        continue;
                    };
                    let id = m.header.channel_id;
                    whole &= self.channel_known(id)?;
                    match counts.last_mut() {
                        Some((c, n)) if *c == id => *n += 1,
                        _ => counts.push((id, 1)),
                    }
                }
                _ => {}
            }
        }
        if whole {
            self.writer.copy_chunk(chunk)?;
            self.report.chunks += 1;
        } else {
            let channels = &self.channels;
            let (copied, orphans) = self
                .writer
                .copy_records_where(&chunk.records, |id| channels.contains_key(&id))?;
            self.report.orphan_messages += orphans;
            counts = copied.into_iter().collect();
        }
        for (id, n) in counts {
            count(&mut self.report, &self.channels[&id], n);
        }
        Ok(())
    }

    /// A record outside any chunk (an unchunked file, or the data end's records).
    fn record(&mut self, opcode: u8, body: &[u8]) -> Result<()> {
        use mcap::records::Record;
        match mcap::parse_record(opcode, body) {
            Ok(Record::Schema { header, data }) => {
                let (id, name, encoding) = (header.id, &header.name, &header.encoding);
                self.writer.copy_schema(id, name, encoding, &data)?;
                self.schemas.insert(header.id);
            }
            // A channel whose schema was lost (and is not in the summary) is left out.
            Ok(Record::Channel(c)) if self.schema_known(c.schema_id)? => {
                let (id, schema, topic) = (c.id, c.schema_id, &c.topic);
                let w = &mut self.writer;
                w.copy_channel(id, schema, topic, &c.message_encoding, &c.metadata)?;
                self.channels.insert(c.id, c.topic);
            }
            Ok(Record::Message { header, data }) => {
                let id = header.channel_id;
                if !self.channel_known(id)? {
                    self.report.orphan_messages += 1;
                    return Ok(());
                }
                let (seq, log, publish) = (header.sequence, header.log_time, header.publish_time);
                self.writer.write_raw(id, seq, log, publish, &data)?;
                count(&mut self.report, &self.channels[&id], 1);
            }
            Ok(Record::Metadata(m)) => {
                self.writer.write_metadata(&m.name, m.metadata)?;
                self.report.metadata += 1;
            }
            Ok(Record::Attachment { header, data, .. }) => {
                let (name, media) = (&header.name, &header.media_type);
                let (log, created) = (header.log_time, header.create_time);
                self.writer.attach(name, media, log, created, &data)?;
                self.report.attachments += 1;
            }
            _ => {}
        }
        Ok(())
    }

    /// Schema `id` is written (0: none needed), or the summary gives it back now.
    fn schema_known(&mut self, id: u16) -> Result<bool> {
        Ok(id == 0 || self.schemas.contains(&id) || self.restore_schema(id)?)
    }

    /// Channel `id` is written, or the summary gives it back now.
    fn channel_known(&mut self, id: u16) -> Result<bool> {
        Ok(self.channels.contains_key(&id) || self.restore_channel(id)?)
    }

    /// Writes the summary's definition of channel `id` (and its schema), if it has it.
    fn restore_channel(&mut self, id: u16) -> Result<bool> {
        let Some(c) = self.summary.get(&id) else {
            return Ok(false);
        };
        if let Some(s) = &c.schema {
            self.writer
                .copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
            self.schemas.insert(s.id);
        }
        let schema_id = c.schema.as_ref().map_or(0, |s| s.id);
        let w = &mut self.writer;
        w.copy_channel(id, schema_id, &c.topic, &c.message_encoding, &c.metadata)?;
        self.channels.insert(id, c.topic.clone());
        Ok(true)
    }

    /// Writes the summary's schema `id`, if a channel of the summary uses it.
    fn restore_schema(&mut self, id: u16) -> Result<bool> {
        let Some(s) = self
            .summary
            .values()
            .filter_map(|c| c.schema.as_ref())
            .find(|s| s.id == id)
        else {
            return Ok(false);
        };
        self.writer
            .copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
        self.schemas.insert(id);
        Ok(true)
    }
}

fn count(report: &mut RecoverReport, topic: &str, n: u64) {
    report.messages += n;
    *report
        .messages_per_topic
        .entry(topic.to_owned())
        .or_insert(0) += n;
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
