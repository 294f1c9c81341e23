//! The run's one reader: a streaming k-way merge of its parts by (corrected) time, handing out
//! records as [`LogReader`] does, under the run's ids.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};
use std::hash::BuildHasher;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::channels::Ids;
use super::stamp_order::{Held, StampOrder, Stamps, WINDOW_NS};
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
    /// With `--time stamp`: messages whose stamp came more than the window (2 s) behind their
    /// part's log time, handed out as they came.
    #[serde(skip_serializing_if = "is_zero")]
    pub stamps_beyond_window: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// A part as the merge walks it.
pub(super) struct PartState {
    /// What is read: the part itself, or its temporary MCAP.
    path: PathBuf,
    /// The part as the run names it.
    name: PathBuf,
    input: usize,
    clock: ClockMap,
    /// Earliest (corrected) time it can hold, where known: it is opened when the merge gets
    /// there.
    start_ns: Option<u64>,
    size: u64,
    pub(super) reader: Option<LogReader>,
    /// Messages taken from it so far (its file order).
    taken: u64,
    /// With `--time stamp`: its messages held until they leave in stamp order.
    stamped: Option<StampOrder>,
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
    /// A message whose stamp was moved onto the run's clock, re-encoded.
    restamped: Vec<u8>,
    /// With `--time stamp`: each channel's stamp reader.
    stamps: Stamps,
}

impl RunReader {
    /// Reads every part's summary (one seek to each file's end) and orders the parts by the
    /// earliest time each can hold.
    pub(super) fn open(run: &Run) -> Result<Self> {
        let mut parts = Vec::with_capacity(run.parts.len());
        let mut summaries = Vec::with_capacity(run.parts.len());
        for p in &run.parts {
            let path = p.mcap_path().to_owned();
            let summary = match read_summary(&path) {
                Ok(s) => s,
                // A damaged part is read up to its damage, where the reader names it.
                Err(Error::Damaged { .. }) => None,
                Err(e) => return Err(e),
            };
            let span = summary.as_ref().and_then(|s| s.message_span_ns);
            parts.push(PartState {
                path,
                name: p.path.clone(),
                input: p.input,
                clock: p.clock,
                start_ns: match run.time {
                    TimeBasis::Log => p.listed_start_ns.or(span.map(|s| s.0)),
                    // A message is sent (and stamped) before it is logged: by at most the
                    // window, taken as that of `--time stamp`.
                    TimeBasis::Publish | TimeBasis::Stamp => p
                        .listed_start_ns
                        .or(span.map(|s| s.0))
                        .map(|t| t.saturating_sub(WINDOW_NS)),
                },
                size: std::fs::metadata(&p.path).map_or(0, |m| m.len()),
                reader: None,
                taken: 0,
                stamped: (run.time == TimeBasis::Stamp).then(StampOrder::default),
            });
            summaries.push(summary);
        }
        if run.parts.len() > 1 {
            same_run(run)?;
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
            restamped: Vec::new(),
            stamps: Stamps::default(),
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
            Some((_, head)) => &self.parts[head.part].name,
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
                let part = &self.parts[head.part];
                let (_, sequence, data) = head_of(part);
                let mut message = LogMessage {
                    channel: &self.ids.channels[&channel],
                    sequence,
                    log_time_ns: head.time_ns,
                    publish_time_ns: head.publish_ns,
                    data,
                };
                if !part.clock.is_identity() && restamp(&message, &part.clock, &mut self.restamped)
                {
                    message.data = &self.restamped;
                }
                LogRecord::Message(message)
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
        if self.release_held(p, false) {
            return Ok(None);
        }
        let part = &mut self.parts[p];
        // Only a part read in stamp order outlives its file: what it holds leaves now.
        let Some(reader) = part.reader.as_mut() else {
            self.release_rest(p);
            return Ok(None);
        };
        let Some(record) = reader.next() else {
            self.part_ended(p);
            return Ok(None);
        };
        let step = match record? {
            LogRecord::Message(m) => {
                let (log, publish) = (
                    part.clock.correct(m.log_time_ns),
                    part.clock.correct(m.publish_time_ns),
                );
                part.taken += 1;
                if let Some(order) = part.stamped.as_mut() {
                    let channel = self
                        .ids
                        .channel_of(p, m.channel.id)
                        .expect("its channel came before it");
                    order.hold(Held {
                        stamp_ns: self.stamps.of(channel, &m, &part.clock, log),
                        order: part.taken,
                        channel: m.channel.id,
                        sequence: m.sequence,
                        log_ns: log,
                        publish_ns: publish,
                        data: m.data.to_vec(),
                    });
                    // Read on: the part's head is what its window releases.
                    return Ok(None);
                }
                let head = Head {
                    time_ns: match self.time {
                        TimeBasis::Publish => publish,
                        TimeBasis::Log | TimeBasis::Stamp => log,
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
            LogRecord::Schema(s) => self.schema_read(p, &s)?,
            LogRecord::Channel(c) => self.channel_read(p, &c)?,
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

    /// Part `p`'s file is read to its end: closed, and what it holds for its stamps left to
    /// leave.
    fn part_ended(&mut self, p: usize) {
        let part = &mut self.parts[p];
        self.finished_bytes += part.size;
        self.counts.parts_read += 1;
        self.counts.stamps_beyond_window += part.stamped.as_ref().map_or(0, |o| o.late);
        part.reader = None;
        self.release_rest(p);
    }

    /// A read part's next held message becomes its head; without one, the part is done.
    fn release_rest(&mut self, p: usize) {
        if !self.release_held(p, true) {
            self.to_advance.pop();
        }
    }

    /// A schema of part `p`: the run's, handed out the first time the run meets it.
    fn schema_read(&mut self, p: usize, s: &Arc<crate::log::SchemaInfo>) -> Result<Option<Step>> {
        let (s, _) = self.ids.schema(p, s).ok_or_else(|| self.full(p))?;
        Ok(self
            .announced_schemas
            .insert(s.id, ())
            .is_none()
            .then_some(Step::Schema(s)))
    }

    /// A channel of part `p`: the run's, handed out (after its schema, where that is new to
    /// the run) the first time the run meets it.
    fn channel_read(&mut self, p: usize, c: &Arc<ChannelInfo>) -> Result<Option<Step>> {
        let c = self.run_channel(p, c)?;
        let channel = self
            .announced_channels
            .insert(c.id, ())
            .is_none()
            .then(|| Step::Channel(c.clone()));
        Ok(match c.schema.as_ref() {
            // A schema this part shares with an earlier one, said before its channel.
            Some(s) if self.announced_schemas.insert(s.id, ()).is_none() => {
                self.queued = channel;
                Some(Step::Schema(s.clone()))
            }
            _ => channel,
        })
    }

    /// Makes the earliest message part `p` holds for its stamp its head, where one is due
    /// (at the file's `end`, any); false where none is.
    fn release_held(&mut self, p: usize, end: bool) -> bool {
        let part = &mut self.parts[p];
        let Some(held) = part.stamped.as_mut().and_then(|o| o.release(end)) else {
            return false;
        };
        let head = Head {
            time_ns: held.stamp_ns,
            input: part.input,
            part: p,
            order: held.order,
            publish_ns: held.publish_ns,
        };
        self.heads.push(Reverse(head));
        self.to_advance.pop();
        true
    }

    /// The run's channel for part `p`'s, with its topic's owner noted.
    fn run_channel(&mut self, p: usize, c: &Arc<ChannelInfo>) -> Result<Arc<ChannelInfo>> {
        let (c, _) = self.ids.channel(p, c).ok_or_else(|| self.full(p))?;
        Ok(c)
    }

    fn full(&self, p: usize) -> Error {
        Error::run(
            &self.parts[p].name,
            "the run has more than 65535 channels or schemas: read fewer files at once",
        )
    }

    /// The run channel of a head, and whether it repeats a message handed out already; a
    /// topic taken back by a part that had handed it over is two sources on one topic.
    fn check_message(&mut self, head: &Head) -> Result<(u16, bool)> {
        let (part_channel, _, data) = head_of(&self.parts[head.part]);
        let channel = self
            .ids
            .channel_of(head.part, part_channel)
            .expect("its channel came before it");
        if self.parts.len() == 1 {
            return Ok((channel, false));
        }
        let hash = foldhash::fast::FixedState::with_seed(0).hash_one(data);
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
                    let (a, b) = (&self.parts[head.part].name, &self.parts[owner.part].name);
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

/// A part's head message: (its channel id in the part, sequence, payload), held for its stamp
/// or in its reader.
fn head_of(part: &PartState) -> (u16, u32, &[u8]) {
    if let Some(h) = part.stamped.as_ref().and_then(|o| o.head.as_ref()) {
        return (h.channel, h.sequence, &h.data);
    }
    let m = part
        .reader
        .as_ref()
        .and_then(LogReader::current_message)
        .expect("a head's reader holds its message");
    (m.channel.id, m.sequence, m.data)
}

/// Moves the stamp of a message that its recorder stamped (see
/// [`StampClock`](crate::messages::StampClock), and a ROS 2 message's `header.stamp`) onto
/// the run's clock, re-encoding it into `out`; false (the message as it is) for a stamp on
/// GNSS time, a derived one, another foreign schema, or a payload that does not decode (its
/// reader names it).
fn restamp(m: &LogMessage<'_>, clock: &ClockMap, out: &mut Vec<u8>) -> bool {
    use crate::messages::{AnyMessage, StampClock};
    let channel = m.channel;
    if channel.kind().is_none() {
        // A ROS message's header.stamp is its node's clock: the recorder's machine.
        return match &channel.schema {
            Some(s) if channel.message_encoding == "cdr" && s.encoding == "ros2msg" => {
                crate::foreign::ros2::restamp_header(&s.data, m.data, |t| clock.correct(t), out)
            }
            Some(s) if channel.message_encoding == "ros1" && s.encoding == "ros1msg" => {
                crate::foreign::ros1::restamp_header(&s.data, m.data, |t| clock.correct(t), out)
            }
            _ => false,
        };
    }
    let Ok(Some(mut message)) = m.decode_any(Path::new("")) else {
        return false;
    };
    let stamp_clock = message.kind().stamp_clock();
    match (&mut message, stamp_clock) {
        (AnyMessage::TimeReference(r), _) => r.local_ns = clock.correct(r.local_ns),
        (m, StampClock::Recorder) => {
            let stamp = m.stamp_ns_mut();
            *stamp = clock.correct(*stamp);
        }
        _ => return false,
    }
    let protobuf =
        channel.message_encoding == crate::protobuf::Encoding::Protobuf.message_encoding();
    out.clear();
    out.extend_from_slice(&match protobuf {
        true => message.to_protobuf(),
        false => message.to_json(),
    });
    true
}

/// Every part that names its run (`railfuse.run`'s `run_id`) names the same one: a file of
/// another run mixed in is refused before anything is read.
pub(super) fn same_run(run: &Run) -> Result<()> {
    let mut first: Option<(&Path, String)> = None;
    for p in run.parts.iter().filter(|p| p.storage == Storage::Mcap) {
        let id = match crate::log::read_metadata(&p.path, crate::topics::metadata::RUN) {
            Ok(m) => m.and_then(|mut m| m.remove("run_id")),
            // A damaged part is read up to its damage, where the reader names it.
            Err(Error::Damaged { .. }) => None,
            Err(e) => return Err(e),
        };
        let Some(id) = id else { continue };
        match &first {
            None => first = Some((&p.path, id)),
            Some((path, other)) if *other != id => {
                return Err(Error::run(
                    &p.path,
                    format!(
                        "of run '{id}', {} of run '{other}': a file of another run mixed in; \
                         read each run on its own",
                        path.display()
                    ),
                ))
            }
            Some(_) => {}
        }
    }
    Ok(())
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
