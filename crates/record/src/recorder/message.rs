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

/// Writes items, adding each (topic, type) channel the first time it appears.
pub struct ItemWriter {
    pub writer: LogWriter,
    channels: HashMap<(String, MessageKind), ChannelId>,
}

impl ItemWriter {
    pub fn new(writer: LogWriter) -> Self {
        Self {
            writer,
            channels: HashMap::new(),
        }
    }

    fn channel(&mut self, topic: &str, kind: MessageKind) -> railfuse_catalog::Result<ChannelId> {
        if let Some(&c) = self.channels.get(&(topic.to_owned(), kind)) {
            return Ok(c);
        }
        let c = self.writer.add_channel_of(kind, topic)?;
        self.channels.insert((topic.to_owned(), kind), c);
        Ok(c)
    }

    pub fn write(&mut self, item: &Item) -> railfuse_catalog::Result<()> {
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
