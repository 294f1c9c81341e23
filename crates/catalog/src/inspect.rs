//! What a log holds: per-channel counts, rates and gaps, metadata, attachments, and which
//! fused pipelines it carries. One streaming pass; memory grows with channels, not messages.
//! Log times may run out of file order (MCAP allows it): spans are minimum to maximum, and gaps
//! are measured in log-time order, through a bounded reorder window per channel.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap};
use std::path::Path;

use serde::Serialize;

use crate::error::Result;
use crate::log::{ChannelInfo, LogReader, LogRecord};
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

#[derive(Debug, Clone, Serialize)]
pub struct LogSummary {
    pub file: String,
    pub file_bytes: u64,
    pub messages: u64,
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
    pub duration_s: f64,
    pub channels: Vec<ChannelSummary>,
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    pub attachments: Vec<AttachmentSummary>,
    pub fused_pipelines: Vec<String>,
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

/// Reads the whole file once and summarises it.
pub fn summarise(path: &Path) -> Result<LogSummary> {
    let mut reader = LogReader::open(path)?;
    let mut channels: BTreeMap<u16, ChannelSummary> = BTreeMap::new();
    let mut metadata = Vec::new();
    let mut attachments = Vec::new();
    let mut messages = 0u64;
    let mut gaps: HashMap<u16, Gaps> = HashMap::new();
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                channels.insert(c.id, ChannelSummary::new(&c));
            }
            LogRecord::Message(m) => {
                messages += 1;
                let c = channels
                    .get_mut(&m.channel.id)
                    .expect("the reader checks channel ids");
                c.add(m.log_time_ns);
                gaps.entry(m.channel.id).or_default().push(m.log_time_ns);
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
    Ok(LogSummary {
        file: path.display().to_string(),
        file_bytes: std::fs::metadata(path).map(|m| m.len()).unwrap_or(0),
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
    })
}
