//! A split run whose parts simply follow one another: read part after part, chunk by chunk,
//! as one file is, instead of record by record through the merge. That holds where every
//! part is read as it is (log time, its own clock, MCAP) and lists its channels, where a
//! channel or schema id means the same in every part (a recorder's split keeps its ids), and
//! where each part begins after the one before ends (nothing at a boundary twice, nothing to
//! interleave). Anything else is read through [`RunReader`](super::RunReader).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use super::{Run, Storage, TimeBasis};
use crate::error::Result;
use crate::log::{read_summary, ChannelInfo, LogSummary, SchemaInfo};

/// A run to read part after part: its files in order, and its summary as one file's.
#[derive(Debug)]
pub struct Sequential<'a> {
    pub files: Vec<&'a Path>,
    pub summary: LogSummary,
}

impl Run {
    /// The parts, in order, and the run's summary, where the run can be read part after part
    /// as they are. Each part's summary is read once and only what the run's needs is kept
    /// (a channel, its schema, the span), so that this costs no more memory for 1000 parts
    /// than for two. A file of another run is refused here too.
    pub fn sequential_files(&self) -> Result<Option<Sequential<'_>>> {
        let plain = self.time == TimeBasis::Log
            && self
                .parts
                .iter()
                .all(|p| p.storage == Storage::Mcap && p.clock.is_identity());
        if !plain || self.parts.len() < 2 {
            return Ok(None);
        }
        let mut channels: BTreeMap<u16, Arc<ChannelInfo>> = BTreeMap::new();
        let mut schemas: BTreeMap<u16, Arc<SchemaInfo>> = BTreeMap::new();
        let (mut first_start, mut last_end, mut longest_chunk_ns) = (None, None::<u64>, None);
        for p in &self.parts {
            let Some(summary) = read_summary(&p.path).ok().flatten() else {
                return Ok(None);
            };
            let (Some(list), Some((start, end))) = (summary.channels, summary.message_span_ns)
            else {
                return Ok(None);
            };
            if last_end.is_some_and(|e| start <= e) {
                return Ok(None);
            }
            first_start.get_or_insert(start);
            last_end = Some(end);
            longest_chunk_ns = longest_chunk_ns.max(summary.longest_chunk_ns);
            for c in list {
                if let Some(s) = &c.schema {
                    if **schemas.entry(s.id).or_insert_with(|| s.clone()) != **s {
                        return Ok(None); // one schema id, one schema
                    }
                }
                if **channels.entry(c.id).or_insert_with(|| c.clone()) != *c {
                    return Ok(None); // one channel id, one channel
                }
            }
        }
        super::reader::same_run(self)?;
        Ok(Some(Sequential {
            files: self.parts.iter().map(|p| p.path.as_path()).collect(),
            summary: LogSummary {
                channels: Some(channels.into_values().collect()),
                longest_chunk_ns,
                message_span_ns: first_start.zip(last_end),
            },
        }))
    }
}
