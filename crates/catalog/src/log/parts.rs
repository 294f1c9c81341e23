//! A run written as one file or as numbered parts (`run.mcap` → `run-001.mcap`,
//! `run-002.mcap`, …), each part a complete MCAP file that defines every schema and channel
//! its messages use. Records are copied as a run's reader hands them out, under the run's ids.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::{ChannelInfo, IdMap, LogMessage, LogWriter, SchemaInfo, WriterOptions};
use crate::error::Result;

/// The path of part `n` (1-based) of `output`: `run.mcap` → `run-001.mcap`.
pub fn part_path(output: &Path, n: u32) -> PathBuf {
    let stem = output.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let ext = output
        .extension()
        .and_then(|s| s.to_str())
        .unwrap_or("mcap");
    output.with_file_name(format!("{stem}-{n:03}.{ext}"))
}

/// When to begin the next part.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplitRule {
    /// Once a part's file holds this many bytes.
    pub bytes: Option<u64>,
    /// Once a part spans this long (log time, ns).
    pub every_ns: Option<u64>,
    /// At these log times (ns since the run's first message), in order.
    pub at_ns: Vec<u64>,
}

impl SplitRule {
    pub fn splits(&self) -> bool {
        self.bytes.is_some() || self.every_ns.is_some() || !self.at_ns.is_empty()
    }
}

/// Writes a run's records into one file, or into parts by a [`SplitRule`].
pub struct PartWriter {
    output: PathBuf,
    options: WriterOptions,
    rule: SplitRule,
    writer: LogWriter,
    part: u32,
    files: Vec<PathBuf>,
    /// Every schema and channel met, to define in each part that uses them.
    schemas: IdMap<Arc<SchemaInfo>>,
    channels: IdMap<Arc<ChannelInfo>>,
    /// Defined in the part being written.
    defined: IdMap<()>,
    first_ns: Option<u64>,
    part_start_ns: Option<u64>,
    next_at: usize,
    since_size_check: u32,
}

impl PartWriter {
    pub fn create(output: &Path, options: &WriterOptions, rule: SplitRule) -> Result<Self> {
        let first = match rule.splits() {
            true => part_path(output, 1),
            false => output.to_owned(),
        };
        Ok(Self {
            writer: LogWriter::create_with(&first, options)?,
            output: output.to_owned(),
            options: options.clone(),
            rule,
            part: 1,
            files: vec![first],
            schemas: IdMap::default(),
            channels: IdMap::default(),
            defined: IdMap::default(),
            first_ns: None,
            part_start_ns: None,
            next_at: 0,
            since_size_check: 0,
        })
    }

    /// The part being written (its metadata and attachments go there).
    pub fn writer(&mut self) -> &mut LogWriter {
        &mut self.writer
    }

    pub fn schema(&mut self, s: Arc<SchemaInfo>) {
        self.schemas.insert(s.id, s);
    }

    /// A channel; it is defined in each part before its first message there.
    pub fn channel(&mut self, c: Arc<ChannelInfo>) -> Result<()> {
        self.channels.insert(c.id, c.clone());
        self.define(&c)
    }

    fn define(&mut self, c: &ChannelInfo) -> Result<()> {
        if self.defined.insert(c.id, ()).is_some() {
            return Ok(());
        }
        let schema_id = match &c.schema {
            Some(s) => {
                self.writer
                    .copy_schema(s.id, &s.name, &s.encoding, &s.data)?;
                s.id
            }
            None => 0,
        };
        self.writer
            .copy_channel(c.id, schema_id, &c.topic, &c.message_encoding, &c.metadata)
    }

    /// A message, as it was (channel, sequence, times, payload), in the part its time falls in.
    pub fn message(&mut self, m: &LogMessage<'_>) -> Result<()> {
        self.split_before(m.log_time_ns)?;
        if !self.defined.contains_key(&m.channel.id) {
            let c = self
                .channels
                .get(&m.channel.id)
                .cloned()
                .unwrap_or(m.channel.clone());
            self.define(&c)?;
        }
        self.writer.write_raw(
            m.channel.id,
            m.sequence,
            m.log_time_ns,
            m.publish_time_ns,
            m.data,
        )
    }

    /// Begins the next part if the rule says this message belongs there.
    fn split_before(&mut self, t: u64) -> Result<()> {
        let first = *self.first_ns.get_or_insert(t);
        let start = *self.part_start_ns.get_or_insert(t);
        let mut due = false;
        while self
            .rule
            .at_ns
            .get(self.next_at)
            .is_some_and(|&at| t >= first + at)
        {
            self.next_at += 1;
            due = true;
        }
        due |= self.rule.every_ns.is_some_and(|every| t >= start + every);
        // The file's size lags what was written by the chunk being gathered (1 MiB): a part
        // ends within about a chunk of its size, as rosbag2's do.
        if let Some(bytes) = self.rule.bytes {
            self.since_size_check += 1;
            if self.since_size_check >= 1024 {
                self.since_size_check = 0;
                due |= self.writer.bytes_on_disk() >= bytes;
            }
        }
        if !due {
            return Ok(());
        }
        self.part += 1;
        let next = part_path(&self.output, self.part);
        let done = std::mem::replace(
            &mut self.writer,
            LogWriter::create_with(&next, &self.options)?,
        );
        done.finish()?;
        self.files.push(next);
        self.defined.clear();
        self.part_start_ns = Some(t);
        Ok(())
    }

    /// Writes a metadata record to the part being written.
    pub fn metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.writer.write_metadata(name, metadata)
    }

    /// Finishes the last part; every file written, in order.
    pub fn finish(self) -> Result<Vec<PathBuf>> {
        self.writer.finish()?;
        Ok(self.files)
    }
}
