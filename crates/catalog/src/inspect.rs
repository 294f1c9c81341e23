//! What a run holds: per-channel counts, rates and gaps, metadata, attachments, which fused
//! pipelines it carries, and for a run of several files one line per file (its span,
//! messages and clock) and the gaps between files. One streaming pass; memory grows with
//! channels and files, not messages.
//! Log times may run out of file order (MCAP allows it): spans are minimum to maximum, and gaps
//! are measured in log-time order, through a bounded reorder window per channel.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap};

use serde::Serialize;

use crate::error::Result;
use crate::log::{ChannelInfo, LogRecord};
use crate::run::{ClockMap, Run};
use crate::{seconds_between, topics};

#[derive(Debug, Clone, Serialize)]
pub struct ChannelSummary {
    pub topic: String,
    pub schema: String,
    pub message_encoding: String,
    pub messages: u64,
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
    /// Messages per second over the channel's own span.
    pub mean_rate_hz: Option<f64>,
    /// Longest interval between consecutive messages, s.
    pub largest_gap_s: Option<f64>,
    /// Log time at which the largest gap begins.
    pub largest_gap_start_ns: Option<u64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AttachmentSummary {
    pub name: String,
    pub media_type: String,
    pub bytes: usize,
}

/// One file of a run.
#[derive(Debug, Clone, Serialize)]
pub struct FileSummary {
    pub path: String,
    pub bytes: u64,
    pub messages: u64,
    /// Log times on the run's clock (its offset applied).
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
    pub clock: ClockMap,
}

/// A stretch of the run that no file covers (after one file ends and before the next
/// begins), or that a part the bag lists but lacks held.
#[derive(Debug, Clone, Serialize)]
pub struct GapBetweenFiles {
    pub after: String,
    pub before: String,
    pub start_ns: u64,
    pub end_ns: u64,
    /// The part that is not there, where the bag's metadata.yaml lists one.
    pub missing: Option<String>,
}

/// A gap between files shorter than this is the interval between two messages.
pub const GAP_BETWEEN_FILES_NS: u64 = 1_000_000_000;

#[derive(Debug, Clone, Serialize)]
pub struct LogSummary {
    pub file: String,
    pub file_bytes: u64,
    /// Each file of the run, in the run's order (one for a one-file run).
    pub files: Vec<FileSummary>,
    pub gaps_between_files: Vec<GapBetweenFiles>,
    pub messages: u64,
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
    pub duration_s: f64,
    pub channels: Vec<ChannelSummary>,
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    pub attachments: Vec<AttachmentSummary>,
    pub fused_pipelines: Vec<String>,
    /// The train the run carries on `/vehicle` (its last), where it has one; else the one
    /// its `/tf_static` places (every stamped topic whose frame is in the tree).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<crate::messages::Vehicle>,
    /// What was assumed to place the train of a `/tf_static` (named "from /tf_static"), or
    /// why it places none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub vehicle_notes: Vec<String>,
    /// Each input's clock against GNSS time, for a run of several inputs (as `--align gnss`
    /// applied them, or estimated to be shown).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clocks: Option<crate::run::Alignment>,
}

/// Log times held per channel to put them back in order before measuring gaps: a message more
/// than this many messages out of order is measured where it stands.
const REORDER_WINDOW: usize = 1 << 16;

/// A channel's largest gap between consecutive log times, in log-time order.
#[derive(Default)]
struct Gaps {
    pending: BinaryHeap<Reverse<u64>>,
    last: Option<u64>,
    /// (start, length) of the largest gap so far, ns.
    largest: Option<(u64, u64)>,
}

impl Gaps {
    fn push(&mut self, t: u64) {
        self.pending.push(Reverse(t));
        if self.pending.len() > REORDER_WINDOW {
            self.take_earliest();
        }
    }

    fn take_earliest(&mut self) {
        let Some(Reverse(t)) = self.pending.pop() else {
            return;
        };
        if let Some(last) = self.last {
            let gap = t.saturating_sub(last);
            if self.largest.is_none_or(|(_, g)| gap > g) {
                self.largest = Some((last, gap));
            }
        }
        self.last = Some(self.last.map_or(t, |l| l.max(t)));
    }

    fn finish(mut self) -> Option<(u64, u64)> {
        while !self.pending.is_empty() {
            self.take_earliest();
        }
        self.largest
    }
}

impl ChannelSummary {
    fn new(c: &ChannelInfo) -> Self {
        ChannelSummary {
            topic: c.topic.clone(),
            schema: c.schema_name().to_owned(),
            message_encoding: c.message_encoding.clone(),
            messages: 0,
            first_log_time_ns: None,
            last_log_time_ns: None,
            mean_rate_hz: None,
            largest_gap_s: None,
            largest_gap_start_ns: None,
        }
    }

    /// One message at log time `t` (a log need not be in time order).
    fn add(&mut self, t: u64) {
        self.messages += 1;
        self.first_log_time_ns = Some(self.first_log_time_ns.map_or(t, |f| f.min(t)));
        self.last_log_time_ns = Some(self.last_log_time_ns.map_or(t, |l| l.max(t)));
    }

    /// The end of the log: the mean rate, and the largest gap `(start, length)` if any.
    fn close(&mut self, gap: Option<(u64, u64)>) {
        if let Some((start, gap)) = gap {
            self.largest_gap_s = Some(seconds_between(start, start + gap));
            self.largest_gap_start_ns = Some(start);
        }
        if let (Some(a), Some(b)) = (self.first_log_time_ns, self.last_log_time_ns) {
            let span = seconds_between(a, b);
            if self.messages > 1 && span > 0.0 {
                self.mean_rate_hz = Some((self.messages - 1) as f64 / span);
            }
        }
    }
}

/// Each file of the run, before its messages are counted.
fn file_summaries(run: &Run) -> Vec<FileSummary> {
    run.parts()
        .iter()
        .map(|p| FileSummary {
            path: p.path.display().to_string(),
            bytes: std::fs::metadata(&p.path).map_or(0, |m| m.len()),
            messages: 0,
            first_log_time_ns: None,
            last_log_time_ns: None,
            clock: p.clock,
        })
        .collect()
}

impl FileSummary {
    /// One more message of the file, logged at `t`.
    fn add(&mut self, t: u64) {
        self.messages += 1;
        self.first_log_time_ns = Some(self.first_log_time_ns.map_or(t, |a| a.min(t)));
        self.last_log_time_ns = Some(self.last_log_time_ns.map_or(t, |b| b.max(t)));
    }
}

/// Reads the whole run once and summarises it.
pub fn summarise(run: &Run) -> Result<LogSummary> {
    let mut reader = run.reader()?;
    let mut files = file_summaries(run);
    let mut channels: BTreeMap<u16, ChannelSummary> = BTreeMap::new();
    let mut metadata = Vec::new();
    let mut attachments = Vec::new();
    let mut messages = 0u64;
    let mut vehicle = None;
    let mut frames = crate::foreign::frames::FrameCollector::default();
    let mut gaps: HashMap<u16, Gaps> = HashMap::new();
    while let Some(record) = reader.next_with_part() {
        let (part, record) = record?;
        match record {
            LogRecord::Channel(c) => {
                channels.insert(c.id, ChannelSummary::new(&c));
            }
            LogRecord::Message(m) => {
                messages += 1;
                files[part].add(m.log_time_ns);
                let c = channels
                    .get_mut(&m.channel.id)
                    .expect("the reader checks channel ids");
                c.add(m.log_time_ns);
                gaps.entry(m.channel.id).or_default().push(m.log_time_ns);
                if m.is::<crate::messages::Vehicle>() {
                    vehicle = Some(m.decode(std::path::Path::new(&run.display()))?);
                }
                frames.add(&m);
            }
            LogRecord::Metadata { name, metadata: m } => metadata.push((name, m)),
            LogRecord::Attachment {
                name,
                media_type,
                data,
                ..
            } => attachments.push(AttachmentSummary {
                name,
                media_type,
                bytes: data.len(),
            }),
            LogRecord::Schema(_) => {}
        }
    }
    for (id, c) in channels.iter_mut() {
        c.close(gaps.remove(id).and_then(Gaps::finish));
    }
    let first = channels.values().filter_map(|c| c.first_log_time_ns).min();
    let last = channels.values().filter_map(|c| c.last_log_time_ns).max();
    let fused: BTreeSet<String> = channels
        .values()
        .filter_map(|c| topics::fused_pipeline_of(&c.topic))
        .map(str::to_owned)
        .collect();
    let (vehicle, vehicle_notes) = recorded_vehicle(vehicle, &frames);
    let gaps_between_files = gaps_between(&files, run);
    let clocks = clocks_of(run)?;
    Ok(LogSummary {
        file: run.display(),
        file_bytes: run.total_bytes(),
        files,
        gaps_between_files,
        messages,
        first_log_time_ns: first,
        last_log_time_ns: last,
        duration_s: match (first, last) {
            (Some(a), Some(b)) => seconds_between(a, b),
            _ => 0.0,
        },
        channels: channels.into_values().collect(),
        metadata,
        attachments,
        fused_pipelines: fused.into_iter().collect(),
        vehicle,
        vehicle_notes,
        clocks,
    })
}

/// Each input's clock against GNSS time for a run of several inputs: as `--align gnss`
/// applied them, or estimated to be shown.
fn clocks_of(run: &Run) -> Result<Option<crate::run::Alignment>> {
    Ok(match (run.alignment(), run.inputs().len()) {
        (Some(a), _) => Some(a.clone()),
        (None, 1) => None,
        (None, _) => Some(run.estimate_clocks()?),
    })
}

/// The run's `/vehicle`, else the train its `/tf_static` places, with where it comes from.
fn recorded_vehicle(
    logged: Option<crate::messages::Vehicle>,
    frames: &crate::foreign::frames::FrameCollector,
) -> (Option<crate::messages::Vehicle>, Vec<String>) {
    if logged.is_some() {
        return (logged, Vec::new());
    }
    match frames.vehicle("from /tf_static", None) {
        None => (None, Vec::new()),
        Some(Ok((v, notes))) => (Some(v), notes),
        Some(Err(e)) => (None, vec![e.to_string()]),
    }
}

/// Stretches no file covers, longer than [`GAP_BETWEEN_FILES_NS`], and the spans of the parts
/// a bag lists but lacks.
fn gaps_between(files: &[FileSummary], run: &Run) -> Vec<GapBetweenFiles> {
    let mut spans: Vec<(u64, u64, &str)> = files
        .iter()
        .filter_map(|f| Some((f.first_log_time_ns?, f.last_log_time_ns?, f.path.as_str())))
        .collect();
    spans.sort();
    let mut gaps = Vec::new();
    let mut covered: Option<(u64, &str)> = None;
    for &(first, last, path) in &spans {
        if let Some((end, before)) = covered {
            if first > end && first - end > GAP_BETWEEN_FILES_NS {
                let missing = run
                    .missing()
                    .iter()
                    .find(|m| m.start_ns.is_some_and(|t| t >= end && t <= first));
                gaps.push(GapBetweenFiles {
                    after: before.to_owned(),
                    before: path.to_owned(),
                    start_ns: end,
                    end_ns: first,
                    missing: missing.map(|m| m.path.display().to_string()),
                });
            }
        }
        if covered.is_none_or(|(end, _)| last >= end) {
            covered = Some((last, path));
        }
    }
    gaps
}
