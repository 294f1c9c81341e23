//! One id per schema and channel for the whole run. A channel that several parts define alike
//! (one topic, encoding, schema and metadata: a split run's parts all define the recorder's)
//! is one channel of the run; a part's id is kept where the run has not given it to another,
//! so a one-file run keeps every id of its file and a split run its recorder's.

use std::collections::HashMap;
use std::sync::Arc;

use crate::log::{ChannelInfo, IdMap, SchemaInfo};

#[derive(Default)]
pub struct Ids {
    pub schemas: IdMap<Arc<SchemaInfo>>,
    pub channels: IdMap<Arc<ChannelInfo>>,
    /// (part, the part's id) → the run's id.
    part_schemas: HashMap<(usize, u16), u16>,
    part_channels: HashMap<(usize, u16), u16>,
    /// The parts that map to each run channel.
    channel_parts: IdMap<Vec<usize>>,
}

impl Ids {
    /// The run's schema for a part's; true when it is new to the run.
    pub fn schema(&mut self, part: usize, s: &Arc<SchemaInfo>) -> Option<(Arc<SchemaInfo>, bool)> {
        if let Some(id) = self.part_schemas.get(&(part, s.id)) {
            return Some((self.schemas[id].clone(), false));
        }
        let same = self
            .schemas
            .values()
            .find(|g| g.name == s.name && g.encoding == s.encoding && g.data == s.data)
            .map(|g| g.id);
        let (id, new) = match same {
            Some(id) => (id, false),
            None => (free_id(&self.schemas, s.id, 1)?, true),
        };
        if new {
            let info = Arc::new(SchemaInfo {
                id,
                ..(**s).clone()
            });
            self.schemas.insert(id, info);
        }
        self.part_schemas.insert((part, s.id), id);
        Some((self.schemas[&id].clone(), new))
    }

    /// The run's channel for a part's; true when it is new to the run. `None` when the run
    /// has no id left for it.
    pub fn channel(
        &mut self,
        part: usize,
        c: &Arc<ChannelInfo>,
    ) -> Option<(Arc<ChannelInfo>, bool)> {
        if let Some(id) = self.part_channels.get(&(part, c.id)) {
            return Some((self.channels[id].clone(), false));
        }
        let schema = match &c.schema {
            Some(s) => Some(self.schema(part, s)?.0),
            None => None,
        };
        let schema_id = schema.as_ref().map(|s| s.id);
        let parts = &self.channel_parts;
        // Alike, and not already one of this part's own (a file may define twins).
        let same = self
            .channels
            .values()
            .find(|g| {
                g.topic == c.topic
                    && g.message_encoding == c.message_encoding
                    && g.metadata == c.metadata
                    && g.schema.as_ref().map(|s| s.id) == schema_id
                    && !parts.get(&g.id).is_some_and(|p| p.contains(&part))
            })
            .map(|g| g.id);
        let (id, new) = match same {
            Some(id) => (id, false),
            None => (free_id(&self.channels, c.id, 0)?, true),
        };
        if new {
            let info = Arc::new(ChannelInfo {
                id,
                topic: c.topic.clone(),
                message_encoding: c.message_encoding.clone(),
                metadata: c.metadata.clone(),
                schema,
            });
            self.channels.insert(id, info);
        }
        self.part_channels.insert((part, c.id), id);
        self.channel_parts.entry(id).or_default().push(part);
        Some((self.channels[&id].clone(), new))
    }

    /// The run's id of a part's channel, once [`channel`](Self::channel) has met it.
    pub fn channel_of(&self, part: usize, id: u16) -> Option<u16> {
        self.part_channels.get(&(part, id)).copied()
    }
}

/// `wanted` if the table has not given it, else the lowest id from `lowest` it has not (a
/// schema's is never 0, which means "no schema").
fn free_id<V>(table: &IdMap<V>, wanted: u16, lowest: u16) -> Option<u16> {
    if wanted >= lowest && !table.contains_key(&wanted) {
        return Some(wanted);
    }
    (lowest..=u16::MAX).find(|id| !table.contains_key(id))
}
