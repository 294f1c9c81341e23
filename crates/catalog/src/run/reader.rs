//! The run's one reader: a streaming k-way merge of its parts by (corrected) time, handing out
//! records as [`LogReader`] does, under the run's ids.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};
use std::hash::BuildHasher;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::channels::Ids;
use super::{ClockMap, Run, Storage, TimeBasis};
use crate::error::{Error, Result};
use crate::log::{read_summary, ChannelInfo, IdMap, LogMessage, LogReader, LogRecord, LogSummary};

/// What the merge did beyond handing messages out.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MergeCounts {
    /// The same message in two parts (one topic, time and payload): handed out once.
    pub duplicates_dropped: u64,
    /// Parts opened and read to their end.
    pub parts_read: usize,
}

/// A part as the merge walks it.
pub(super) struct PartState {
    path: PathBuf,
    input: usize,
    clock: ClockMap,
    /// Earliest (corrected) time it can hold, where known: it is opened when the merge gets
    /// there.
    start_ns: Option<u64>,
    size: u64,
    pub(super) reader: Option<LogReader>,
    /// Messages taken from it so far (its file order).
    taken: u64,
}

/// Messages remembered per channel to find one repeated at a split boundary.
const RECENT: usize = 8;

/// A part's next message waiting in the merge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Head {
    time_ns: u64,
    input: usize,
    part: usize,
    order: u64,
    publish_ns: u64,
}

/// Who last wrote a topic, for telling a split boundary (one hand-over) from two sources.
struct TopicOwner {
    part: usize,
    /// Parts that handed the topic over: one of them again is two sources interleaved.
    handed_over: Vec<usize>,
}

/// The record [`RunReader::next`] is about to hand out.
enum Step {
    Schema(Arc<crate::log::SchemaInfo>),
    Channel(Arc<ChannelInfo>),
    Metadata(String, BTreeMap<String, String>),
    Attachment {
        name: String,
        media_type: String,
        log_time_ns: u64,
        create_time_ns: u64,
    },
    Message(Head),
}

/// Reads a [`Run`] as one log.
pub struct RunReader {
    name: PathBuf,
    time: TimeBasis,
    pub(super) parts: Vec<PartState>,
    /// Parts not opened yet, the latest start first (taken from the end).
    pending: Vec<usize>,
    heads: BinaryHeap<Reverse<Head>>,
    /// Parts whose head was handed out (or that were just opened): read on before merging.
    to_advance: Vec<usize>,
    ids: Ids,
    /// Run channels and schemas handed out already.
    announced_channels: IdMap<()>,
    announced_schemas: IdMap<()>,
    summary: Option<LogSummary>,
    attachment: Vec<u8>,
    /// (time, payload hash, part) of the last few messages handed out on each channel: the
    /// same message again from another part is a duplicate.
    recent: IdMap<Vec<(u64, u64, usize)>>,
    owners: BTreeMap<String, TopicOwner>,
    counts: MergeCounts,
    /// Channel and times of the message handed out last.
    current: Option<(u16, Head)>,
    finished_bytes: u64,
    /// A record to hand out after the one being handed out.
    queued: Option<Step>,
    /// The part of the record being handed out.
    step_part: usize,
}

impl RunReader {
    /// Reads every part's summary (one seek to each file's end) and orders the parts by the
    /// earliest time each can hold.
    pub(super) fn open(run: &Run) -> Result<Self> {
        if let Some(p) = run.parts.iter().find(|p| p.storage == Storage::Sqlite3) {
            return Err(Error::run(
                &p.path,
                "a rosbag2 sqlite3 file: `railfuse import` converts the bag to MCAP, which \
                 every command reads",
            ));
        }
        let mut parts = Vec::with_capacity(run.parts.len());
        let mut summaries = Vec::with_capacity(run.parts.len());
        for p in &run.parts {
            let summary = match read_summary(&p.path) {
                Ok(s) => s,
                // A damaged part is read up to its damage, where the reader names it.
                Err(Error::Damaged { .. }) => None,
                Err(e) => return Err(e),
            };
            let span = summary.as_ref().and_then(|s| s.message_span_ns);
            parts.push(PartState {
                path: p.path.clone(),
                input: p.input,
                clock: p.clock,
                start_ns: match run.time {
                    // Publish times may come before log times: only the log time is bounded.
                    TimeBasis::Publish => None,
                    TimeBasis::Log => p.listed_start_ns.or(span.map(|s| s.0)),
                },
                size: std::fs::metadata(&p.path).map_or(0, |m| m.len()),
                reader: None,
                taken: 0,
            });
            summaries.push(summary);
        }
        set_drift_origins(&mut parts, &summaries);
        for part in &mut parts {
            part.start_ns = part.start_ns.map(|t| part.clock.correct(t));
        }
        let mut pending: Vec<usize> = (0..parts.len()).collect();
        // Unknown starts first, then by start; the latest at the front, as taken from the end.
        pending.sort_by_key(|&i| Reverse((parts[i].start_ns.map_or(0, |s| s + 1), i)));
        let mut reader = Self {
            name: run.name().to_owned(),
            time: run.time,
            parts,
            pending,
            heads: BinaryHeap::new(),
            to_advance: Vec::new(),
            ids: Ids::default(),
            announced_channels: IdMap::default(),
            announced_schemas: IdMap::default(),
            summary: None,
            attachment: Vec::new(),
            recent: IdMap::default(),
            owners: BTreeMap::new(),
            counts: MergeCounts::default(),
            current: None,
            finished_bytes: 0,
            queued: None,
            step_part: 0,
        };
        reader.summary = reader.combine(&summaries)?;
        Ok(reader)
    }

    /// The run's summary from its parts': every channel under its run id (when every part
    /// lists its channels), the longest chunk, the span of all messages.
    fn combine(&mut self, summaries: &[Option<LogSummary>]) -> Result<Option<LogSummary>> {
        if summaries.iter().all(Option::is_none) {
            return Ok(None);
        }
        let mut listed = true;
        for (p, s) in summaries.iter().enumerate() {
            match s.as_ref().and_then(|s| s.channels.as_ref()) {
                Some(channels) => {
                    for c in channels {
                        self.run_channel(p, c)?;
                    }
                }
                None => listed = false,
            }
        }
        let mut channels: Vec<Arc<ChannelInfo>> = self.ids.channels.values().cloned().collect();
        channels.sort_by_key(|c| c.id);
        let spans = summaries.iter().zip(&self.parts).filter_map(|(s, p)| {
            let (a, b) = s.as_ref()?.message_span_ns?;
            Some((p.clock.correct(a), p.clock.correct(b)))
        });
        let span = spans.fold(None, |acc: Option<(u64, u64)>, (a, b)| {
            Some(acc.map_or((a, b), |(x, y)| (x.min(a), y.max(b))))
        });
        Ok(Some(LogSummary {
            channels: (listed && !channels.is_empty()).then_some(channels),
            longest_chunk_ns: summaries
                .iter()
                .filter_map(|s| s.as_ref()?.longest_chunk_ns)
                .max(),
            message_span_ns: span,
        }))
    }

    /// The run's summary, as [`read_summary`] gives a file's (`None`: no part has one).
    pub fn summary(&self) -> Option<&LogSummary> {
        self.summary.as_ref()
    }

    /// What the merge counted so far.
    pub fn counts(&self) -> &MergeCounts {
        &self.counts
    }

    /// The file of the message handed out last (for messages about it).
    pub fn current_path(&self) -> &Path {
        match self.current {
            Some((_, head)) => &self.parts[head.part].path,
            None => &self.name,
        }
    }

    /// Bytes of the run's files read so far.
    pub fn bytes_read(&self) -> u64 {
        self.finished_bytes
            + self
                .parts
                .iter()
                .filter_map(|p| p.reader.as_ref())
                .map(LogReader::bytes_read)
                .sum::<u64>()
    }

    /// The next record of the run, or `None` at its end. Schemas and channels come (once per
    /// run id) before their first message, metadata and attachments as their file is reached.
    #[allow(clippy::should_implement_trait)] // a lending iterator: records borrow the reader
    pub fn next(&mut self) -> Option<Result<LogRecord<'_>>> {
        self.next_with_part().map(|r| r.map(|(_, record)| record))
    }

    /// [`next`](Self::next), with the index of the part (in [`Run::parts`]) it came from.
    pub fn next_with_part(&mut self) -> Option<Result<(usize, LogRecord<'_>)>> {
        match self.step() {
            Ok(Some(step)) => {
                let part = self.step_part;
                Some(Ok((part, self.record(step))))
            }
            Ok(None) => None,
            Err(e) => {
                // Nothing more after an error: every part is closed.
                self.to_advance.clear();
                self.heads.clear();
                self.pending.clear();
                self.parts.iter_mut().for_each(|p| p.reader = None);
                Some(Err(e))
            }
        }
    }

    fn record(&mut self, step: Step) -> LogRecord<'_> {
        match step {
            Step::Schema(s) => LogRecord::Schema(s),
            Step::Channel(c) => LogRecord::Channel(c),
            Step::Metadata(name, metadata) => LogRecord::Metadata { name, metadata },
            Step::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
            } => LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data: &self.attachment,
            },
            Step::Message(head) => {
                let (channel, _) = self.current.expect("set with the step");
                let m = self.parts[head.part]
                    .reader
                    .as_ref()
                    .and_then(LogReader::current_message)
                    .expect("a head's reader holds its message");
                LogRecord::Message(LogMessage {
                    channel: &self.ids.channels[&channel],
                    sequence: m.sequence,
                    log_time_ns: head.time_ns,
                    publish_time_ns: head.publish_ns,
                    data: m.data,
                })
            }
        }
    }

    /// Finds the next record to hand out.
    fn step(&mut self) -> Result<Option<Step>> {
        if let Some(step) = self.queued.take() {
            return Ok(Some(step));
        }
        loop {
            if let Some(&p) = self.to_advance.last() {
                if let Some(step) = self.advance(p)? {
                    self.step_part = p;
                    return Ok(Some(step));
                }
                continue;
            }
            // Open every part the merge has reached before taking the earliest head.
            let earliest = self.heads.peek().map(|h| h.0.time_ns);
            if let Some(&p) = self.pending.last() {
                let reached = match (self.parts[p].start_ns, earliest) {
                    (Some(start), Some(t)) => start <= t,
                    _ => true,
                };
                if reached {
                    self.pending.pop();
                    self.parts[p].reader = Some(LogReader::open(&self.parts[p].path)?);
                    self.to_advance.push(p);
                    continue;
                }
            }
            let Some(Reverse(head)) = self.heads.pop() else {
                return Ok(None);
            };
            self.to_advance.push(head.part);
            let (channel, duplicate) = self.check_message(&head)?;
            if duplicate {
                self.counts.duplicates_dropped += 1;
                continue;
            }
            self.current = Some((channel, head));
            self.step_part = head.part;
            return Ok(Some(Step::Message(head)));
        }
    }

    /// Reads part `p` on to its next message (which joins the heads) or to a record to hand
    /// out now.
    fn advance(&mut self, p: usize) -> Result<Option<Step>> {
        let part = &mut self.parts[p];
        let reader = part.reader.as_mut().expect("an open part");
        let Some(record) = reader.next() else {
            self.finished_bytes += part.size;
            self.counts.parts_read += 1;
            part.reader = None;
            self.to_advance.pop();
            return Ok(None);
        };
        let step = match record? {
            LogRecord::Message(m) => {
                let (log, publish) = (
                    part.clock.correct(m.log_time_ns),
                    part.clock.correct(m.publish_time_ns),
                );
                part.taken += 1;
                let head = Head {
                    time_ns: match self.time {
                        TimeBasis::Log => log,
                        TimeBasis::Publish => publish,
                    },
                    input: part.input,
                    part: p,
                    order: part.taken,
                    publish_ns: publish,
                };
                self.heads.push(Reverse(head));
                self.to_advance.pop();
                None
            }
            LogRecord::Schema(s) => {
                let (s, _) = self.ids.schema(p, &s).ok_or_else(|| self.full(p))?;
                self.announced_schemas
                    .insert(s.id, ())
                    .is_none()
                    .then_some(Step::Schema(s))
            }
            LogRecord::Channel(c) => {
                let c = self.run_channel(p, &c)?;
                let channel = self
                    .announced_channels
                    .insert(c.id, ())
                    .is_none()
                    .then(|| Step::Channel(c.clone()));
                match c.schema.as_ref() {
                    // A schema this part shares with an earlier one, said before its channel.
                    Some(s) if self.announced_schemas.insert(s.id, ()).is_none() => {
                        self.queued = channel;
                        Some(Step::Schema(s.clone()))
                    }
                    _ => channel,
                }
            }
            LogRecord::Metadata { name, metadata } => Some(Step::Metadata(name, metadata)),
            LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data,
            } => {
                self.attachment.clear();
                self.attachment.extend_from_slice(data);
                Some(Step::Attachment {
                    name,
                    media_type,
                    log_time_ns: part.clock.correct(log_time_ns),
                    create_time_ns,
                })
            }
        };
        Ok(step)
    }

    /// The run's channel for part `p`'s, with its topic's owner noted.
    fn run_channel(&mut self, p: usize, c: &Arc<ChannelInfo>) -> Result<Arc<ChannelInfo>> {
        let (c, _) = self.ids.channel(p, c).ok_or_else(|| self.full(p))?;
        Ok(c)
    }

    fn full(&self, p: usize) -> Error {
        Error::run(
            &self.parts[p].path,
            "the run has more than 65535 channels or schemas: read fewer files at once",
        )
    }

    /// The run channel of a head, and whether it repeats a message handed out already; a
    /// topic taken back by a part that had handed it over is two sources on one topic.
    fn check_message(&mut self, head: &Head) -> Result<(u16, bool)> {
        let reader = self.parts[head.part].reader.as_ref().expect("open");
        let m = reader.current_message().expect("a head's message");
        let channel = self
            .ids
            .channel_of(head.part, m.channel.id)
            .expect("its channel came before it");
        if self.parts.len() == 1 {
            return Ok((channel, false));
        }
        let hash = foldhash::fast::FixedState::with_seed(0).hash_one(m.data);
        let recent = self.recent.entry(channel).or_default();
        let twice = recent
            .iter()
            .any(|&(t, h, part)| t == head.time_ns && h == hash && part != head.part);
        if twice {
            return Ok((channel, true));
        }
        if recent.len() == RECENT {
            recent.remove(0);
        }
        recent.push((head.time_ns, hash, head.part));
        let topic = &self.ids.channels[&channel].topic;
        match self.owners.get_mut(topic.as_str()) {
            None => {
                self.owners.insert(
                    topic.clone(),
                    TopicOwner {
                        part: head.part,
                        handed_over: Vec::new(),
                    },
                );
            }
            Some(owner) if owner.part != head.part => {
                if owner.handed_over.contains(&head.part) {
                    let (a, b) = (&self.parts[head.part].path, &self.parts[owner.part].path);
                    return Err(Error::run(
                        a,
                        format!(
                            "{topic} is also in {} over the same time (at log time {} ns): two \
                             sources on one topic; read the files as separate runs, or rename \
                             the topic in one of them",
                            b.display(),
                            head.time_ns
                        ),
                    ));
                }
                owner.handed_over.push(owner.part);
                owner.part = head.part;
            }
            Some(_) => {}
        }
        Ok((channel, false))
    }
}

/// A drift is measured from its input's first time: the earliest any of its parts holds.
fn set_drift_origins(parts: &mut [PartState], summaries: &[Option<LogSummary>]) {
    let starts: Vec<Option<u64>> = parts
        .iter()
        .zip(summaries)
        .map(|(p, s)| {
            p.start_ns
                .or(s.as_ref().and_then(|s| s.message_span_ns).map(|s| s.0))
        })
        .collect();
    for i in 0..parts.len() {
        if parts[i].clock.drift_ppm == 0.0 || parts[i].clock.origin_ns != 0 {
            continue;
        }
        let input = parts[i].input;
        let origin = (0..parts.len())
            .filter(|&j| parts[j].input == input)
            .filter_map(|j| starts[j])
            .min();
        parts[i].clock.origin_ns = origin.unwrap_or(0);
    }
}
