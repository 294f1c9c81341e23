//! A decoded message on its way to the log, and the JSON-lines format of sensor gateways.
//!
//! A JSON line names its channel and carries the message's fields:
//!
//! ```json
//! {"topic": "/radar/speed", "stamp_ns": 1780300800000000000, "speed_mps": 12.5, "quality": 1.0, "valid": true}
//! ```
//!
//! The message type follows from the standard topics (`/radar/speed` is a `RadarSpeed`, …); any
//! other topic names it with `"type": "RadarSpeed"`. A missing `stamp_ns` is the receive time.

use std::collections::HashMap;

use railfuse_catalog::log::{ChannelId, LogWriter};
use railfuse_catalog::messages::*;
use railfuse_catalog::topics;
use serde_json::Value;

use crate::error::JsonLineError;

/// A message ready to write: topic, receive time, message.
#[derive(Debug, Clone)]
pub struct Item {
    pub topic: String,
    pub log_time_ns: u64,
    pub message: AnyMessage,
}

/// Parses one JSON line; the error says what is wrong with it.
pub fn parse_json_line(line: &str, receive_ns: u64) -> Result<Item, JsonLineError> {
    let v: serde_json::Map<String, Value> =
        serde_json::from_str(line).map_err(JsonLineError::NotAnObject)?;
    from_object(v, receive_ns)
}

/// A message from a JSON object holding `topic`, optionally `type`, and the message's fields.
pub fn from_object(
    mut v: serde_json::Map<String, Value>,
    receive_ns: u64,
) -> Result<Item, JsonLineError> {
    let topic = match v.remove("topic") {
        Some(Value::String(t)) if t.starts_with('/') && t.len() <= 256 => t,
        Some(_) => return Err(JsonLineError::BadTopic),
        None => return Err(JsonLineError::NoTopic),
    };
    let kind = match v.remove("type") {
        Some(Value::String(t)) => {
            MessageKind::from_type_name(&t).ok_or(JsonLineError::UnknownType(t))?
        }
        Some(_) => return Err(JsonLineError::TypeNotAString),
        None => topics::standard_kind(&topic)
            .ok_or_else(|| JsonLineError::NotAStandardTopic(topic.clone()))?,
    };
    v.entry("stamp_ns").or_insert(Value::from(receive_ns));
    let message = match kind.from_value(Value::Object(v)) {
        Ok(m) => m,
        Err(source) => {
            return Err(JsonLineError::Invalid {
                topic,
                type_name: kind.type_name(),
                source,
            })
        }
    };
    Ok(Item {
        topic,
        log_time_ns: receive_ns,
        message,
    })
}

/// Writes items, adding each (topic, type) channel the first time it appears, and keeps the
/// last message of each channel: the state a new part of a split recording opens with.
pub struct ItemWriter {
    pub writer: LogWriter,
    channels: HashMap<(String, MessageKind), ChannelId>,
    latched: HashMap<(String, MessageKind), Item>,
    /// First and last log time of the messages written (the repeated state left out), and
    /// how many.
    pub span_ns: Option<(u64, u64)>,
    pub messages: u64,
}

impl ItemWriter {
    pub fn new(writer: LogWriter) -> Self {
        Self {
            writer,
            channels: HashMap::new(),
            latched: HashMap::new(),
            span_ns: None,
            messages: 0,
        }
    }

    /// Writes `item` and keeps it as its channel's latest; the kept item is returned.
    pub fn write(&mut self, item: Item) -> railfuse_catalog::Result<&Item> {
        self.write_item(&item)?;
        self.spans(item.log_time_ns);
        let key = (item.topic.clone(), item.message.kind());
        Ok(match self.latched.entry(key) {
            std::collections::hash_map::Entry::Occupied(mut e) => {
                e.insert(item);
                e.into_mut()
            }
            std::collections::hash_map::Entry::Vacant(e) => e.insert(item),
        })
    }

    /// A message of this part's own (not the repeated state) at `log_time_ns`, another
    /// message written outside [`write`](Self::write) included: the part's span and count.
    pub fn spans(&mut self, t: u64) {
        self.span_ns = Some(self.span_ns.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
        self.messages += 1;
    }

    /// The state this part ends on: the last message of each of its channels, in log-time
    /// order.
    pub fn latched_items(&self) -> Vec<Item> {
        let mut state: Vec<Item> = self.latched.values().cloned().collect();
        state.sort_by(|a, b| (a.log_time_ns, &a.topic).cmp(&(b.log_time_ns, &b.topic)));
        state
    }

    /// Opens a new part with the state the last one ended on ([`latched_items`]), at their own
    /// log times (as rosbag2 repeats latched topics and `mcap filter --last-per-channel`
    /// keeps them), in a chunk of its own. A reader of the whole run sees them as the repeats
    /// they are (the same message in two parts); a reader of this part alone starts from that
    /// state instead of cold.
    ///
    /// [`latched_items`]: Self::latched_items
    pub fn repeat_latched(&mut self, state: Vec<Item>) -> railfuse_catalog::Result<()> {
        for item in state {
            self.write_item(&item)?;
            self.latched
                .insert((item.topic.clone(), item.message.kind()), item);
        }
        self.writer.flush_chunk()
    }

    /// The (topic, type name, message encoding) of every channel written.
    pub fn channels(&self) -> impl Iterator<Item = (&str, MessageKind, ChannelId)> {
        self.channels.iter().map(|((t, k), &c)| (t.as_str(), *k, c))
    }

    fn channel(&mut self, topic: &str, kind: MessageKind) -> railfuse_catalog::Result<ChannelId> {
        if let Some(&c) = self.channels.get(&(topic.to_owned(), kind)) {
            return Ok(c);
        }
        let c = self.writer.add_channel_of(kind, topic)?;
        self.channels.insert((topic.to_owned(), kind), c);
        Ok(c)
    }

    fn write_item(&mut self, item: &Item) -> railfuse_catalog::Result<()> {
        let c = self.channel(&item.topic, item.message.kind())?;
        self.writer.write_any(c, item.log_time_ns, &item.message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_lines_name_their_channel_and_bad_ones_say_why() {
        let i = parse_json_line(
            r#"{"topic":"/radar/speed","speed_mps":12.5,"quality":1.0,"valid":true}"#,
            77,
        )
        .unwrap();
        assert!(
            matches!(i.message, AnyMessage::RadarSpeed(RadarSpeed { stamp_ns: 77, speed_mps, .. }) if speed_mps == 12.5)
        );
        let i = parse_json_line(r#"{"topic":"/radar/front","type":"RadarSpeed","stamp_ns":5,"speed_mps":1.0,"quality":1.0,"valid":false}"#, 9).unwrap();
        assert_eq!((i.topic.as_str(), i.log_time_ns), ("/radar/front", 9));
        assert!(parse_json_line("{]", 0)
            .unwrap_err()
            .to_string()
            .contains("not a JSON object"));
        assert!(parse_json_line(r#"{"topic":"/x","speed_mps":1}"#, 0)
            .unwrap_err()
            .to_string()
            .contains("name its \"type\""));
        assert!(
            parse_json_line(r#"{"topic":"/radar/speed","speed_mps":"fast"}"#, 0)
                .unwrap_err()
                .to_string()
                .contains("not a valid RadarSpeed")
        );
    }
}
