//! A split run whose parts simply follow one another: read part after part, chunk by chunk,
//! as one file is, instead of record by record through the merge. That holds where every
//! part is read as it is (log time, its own clock, MCAP) and lists its channels, where a
//! channel or schema id means the same in every part (a recorder's split keeps its ids), and
//! where each part begins after the one before ends (nothing at a boundary twice, nothing to
//! interleave). Anything else is read through [`RunReader`](super::RunReader).

use std::collections::HashMap;
use std::path::Path;

use super::{Run, Storage, TimeBasis};
use crate::error::Result;
use crate::log::read_summary;

impl Run {
    /// The parts, in order, where the run can be read part after part as they are.
    pub fn sequential_files(&self) -> Result<Option<Vec<&Path>>> {
        let plain = self.time == TimeBasis::Log
            && self
                .parts
                .iter()
                .all(|p| p.storage == Storage::Mcap && p.clock.is_identity());
        if !plain || self.parts.len() < 2 {
            return Ok(None);
        }
        // (topic, encoding, metadata, schema name, encoding, data) by channel id.
        let mut channels = HashMap::new();
        let mut last_end: Option<u64> = None;
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
            last_end = Some(end);
            for c in list {
                let schema = c.schema.as_ref().map(|s| (s.id, s.name.clone(), s.encoding.clone(), s.data.clone()));
                let key = (c.topic.clone(), c.message_encoding.clone(), c.metadata.clone(), schema);
                if *channels.entry(c.id).or_insert_with(|| key.clone()) != key {
                    return Ok(None);
                }
            }
        }
        // One schema id, one schema.
        let mut schemas = HashMap::new();
        for (id, name, encoding, data) in channels.values().filter_map(|k| k.3.clone()) {
            if *schemas.entry(id).or_insert_with(|| (name.clone(), encoding.clone(), data.clone()))
                != (name, encoding, data)
            {
                return Ok(None);
            }
        }
        Ok(Some(self.parts.iter().map(|p| p.path.as_path()).collect()))
    }
}
