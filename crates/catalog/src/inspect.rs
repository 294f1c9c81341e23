//! What a log holds: per-channel counts, rates and gaps, metadata, attachments, and which
//! fused pipelines it carries. One streaming pass; memory grows with channels, not messages.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use serde::Serialize;

use crate::error::Result;
use crate::log::{LogReader, LogRecord};
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

/// Reads the whole file once and summarises it.
pub fn summarise(path: &Path) -> Result<LogSummary> {
    let mut reader = LogReader::open(path)?;
    let mut channels: BTreeMap<u16, ChannelSummary> = BTreeMap::new();
    let mut metadata = Vec::new();
    let mut attachments = Vec::new();
    let mut messages = 0u64;
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                channels.insert(
                    c.id,
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
                    },
                );
            }
            LogRecord::Message(m) => {
                messages += 1;
                let c = channels
                    .get_mut(&m.channel.id)
                    .expect("the reader checks channel ids");
                c.messages += 1;
                if let Some(last) = c.last_log_time_ns {
                    let gap = seconds_between(last, m.log_time_ns);
                    if c.largest_gap_s.is_none_or(|g| gap > g) {
                        c.largest_gap_s = Some(gap);
                        c.largest_gap_start_ns = Some(last);
                    }
                }
                c.first_log_time_ns.get_or_insert(m.log_time_ns);
                c.last_log_time_ns = Some(m.log_time_ns);
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
    for c in channels.values_mut() {
        if let (Some(a), Some(b)) = (c.first_log_time_ns, c.last_log_time_ns) {
            let span = seconds_between(a, b);
            if c.messages > 1 && span > 0.0 {
                c.mean_rate_hz = Some((c.messages - 1) as f64 / span);
            }
        }
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
