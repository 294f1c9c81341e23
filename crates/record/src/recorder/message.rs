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

/// One message of any catalogue type, with its topic.
#[derive(Debug, Clone)]
pub enum Message {
    Gnss(GnssFix),
    Imu(Imu),
    Radar(RadarSpeed),
    Odometer(Odometer),
    Loop(LoopPosition),
    Balise(BalisePassage),
    Eddy(EddyCurrentBlock),
    Event(Event),
    Truth(GroundTruth),
    Map(TrackMap),
}

impl Message {
    /// Its schema name and JSON payload (for live viewers).
    pub fn schema_and_json(&self) -> (&'static str, Vec<u8>) {
        fn j<M: ChannelMessage + serde::Serialize>(m: &M) -> (&'static str, Vec<u8>) {
            (
                M::SCHEMA_NAME,
                serde_json::to_vec(m).expect("a message serialises"),
            )
        }
        match self {
            Message::Gnss(m) => j(m),
            Message::Imu(m) => j(m),
            Message::Radar(m) => j(m),
            Message::Odometer(m) => j(m),
            Message::Loop(m) => j(m),
            Message::Balise(m) => j(m),
            Message::Eddy(m) => j(m),
            Message::Event(m) => j(m),
            Message::Truth(m) => j(m),
            Message::Map(m) => j(m),
        }
    }
}

/// A message ready to write: topic, receive time, message.
#[derive(Debug, Clone)]
pub struct Item {
    pub topic: String,
    pub log_time_ns: u64,
    pub message: Message,
}

/// The type a standard topic carries.
fn type_of_topic(topic: &str) -> Option<&'static str> {
    Some(match topic {
        topics::GNSS_FIX => "GnssFix",
        topics::IMU => "Imu",
        topics::RADAR_SPEED => "RadarSpeed",
        topics::ODOMETER_1 | topics::ODOMETER_2 => "Odometer",
        topics::LOOP_POSITION => "LoopPosition",
        topics::BALISE => "BalisePassage",
        topics::EDDY_CURRENT => "EddyCurrentBlock",
        topics::EVENTS => "Event",
        topics::GROUND_TRUTH => "GroundTruth",
        topics::TRACK_MAP => "TrackMap",
        _ => return None,
    })
}

/// Parses one JSON line; the error says what is wrong with it.
pub fn parse_json_line(line: &str, receive_ns: u64) -> Result<Item, String> {
    let v: serde_json::Map<String, Value> =
        serde_json::from_str(line).map_err(|e| format!("not a JSON object: {e}"))?;
    from_object(v, receive_ns)
}

/// A message from a JSON object holding `topic`, optionally `type`, and the message's fields.
pub fn from_object(mut v: serde_json::Map<String, Value>, receive_ns: u64) -> Result<Item, String> {
    let topic = match v.remove("topic") {
        Some(Value::String(t)) if t.starts_with('/') && t.len() <= 256 => t,
        Some(_) => return Err("\"topic\" must be a string starting with '/'".into()),
        None => return Err("no \"topic\"".into()),
    };
    let ty = match v.remove("type") {
        Some(Value::String(t)) => t,
        Some(_) => return Err("\"type\" must be a string".into()),
        None => type_of_topic(&topic)
            .ok_or_else(|| format!("{topic} is not a standard topic: name its \"type\""))?
            .to_owned(),
    };
    v.entry("stamp_ns").or_insert(Value::from(receive_ns));
    let obj = Value::Object(v);
    let bad = |e: serde_json::Error| format!("{topic}: not a valid {ty}: {e}");
    let message = match ty.as_str() {
        "GnssFix" => Message::Gnss(serde_json::from_value(obj).map_err(bad)?),
        "Imu" => Message::Imu(serde_json::from_value(obj).map_err(bad)?),
        "RadarSpeed" => Message::Radar(serde_json::from_value(obj).map_err(bad)?),
        "Odometer" => Message::Odometer(serde_json::from_value(obj).map_err(bad)?),
        "LoopPosition" => Message::Loop(serde_json::from_value(obj).map_err(bad)?),
        "BalisePassage" => Message::Balise(serde_json::from_value(obj).map_err(bad)?),
        "EddyCurrentBlock" => Message::Eddy(serde_json::from_value(obj).map_err(bad)?),
        "Event" => Message::Event(serde_json::from_value(obj).map_err(bad)?),
        other => return Err(format!("unknown type {other}")),
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
    channels: HashMap<(String, &'static str), ChannelId>,
}

impl ItemWriter {
    pub fn new(writer: LogWriter) -> Self {
        Self {
            writer,
            channels: HashMap::new(),
        }
    }

    fn channel<M: ChannelMessage>(&mut self, topic: &str) -> railfuse_catalog::Result<ChannelId> {
        if let Some(&c) = self.channels.get(&(topic.to_owned(), M::SCHEMA_NAME)) {
            return Ok(c);
        }
        let c = self.writer.add_channel::<M>(topic)?;
        self.channels.insert((topic.to_owned(), M::SCHEMA_NAME), c);
        Ok(c)
    }

    pub fn write_message<M: ChannelMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        m: &M,
    ) -> railfuse_catalog::Result<()> {
        let c = self.channel::<M>(topic)?;
        self.writer.write(c, log_time_ns, m)
    }

    pub fn write(&mut self, item: &Item) -> railfuse_catalog::Result<()> {
        let (t, lt) = (item.topic.as_str(), item.log_time_ns);
        match &item.message {
            Message::Gnss(m) => self.write_message(t, lt, m),
            Message::Imu(m) => self.write_message(t, lt, m),
            Message::Radar(m) => self.write_message(t, lt, m),
            Message::Odometer(m) => self.write_message(t, lt, m),
            Message::Loop(m) => self.write_message(t, lt, m),
            Message::Balise(m) => self.write_message(t, lt, m),
            Message::Eddy(m) => self.write_message(t, lt, m),
            Message::Event(m) => self.write_message(t, lt, m),
            Message::Truth(m) => self.write_message(t, lt, m),
            Message::Map(m) => self.write_message(t, lt, m),
        }
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
            matches!(i.message, Message::Radar(RadarSpeed { stamp_ns: 77, speed_mps, .. }) if speed_mps == 12.5)
        );
        let i = parse_json_line(r#"{"topic":"/radar/front","type":"RadarSpeed","stamp_ns":5,"speed_mps":1.0,"quality":1.0,"valid":false}"#, 9).unwrap();
        assert_eq!((i.topic.as_str(), i.log_time_ns), ("/radar/front", 9));
        assert!(parse_json_line("{]", 0)
            .unwrap_err()
            .contains("not a JSON object"));
        assert!(parse_json_line(r#"{"topic":"/x","speed_mps":1}"#, 0)
            .unwrap_err()
            .contains("name its \"type\""));
        assert!(
            parse_json_line(r#"{"topic":"/radar/speed","speed_mps":"fast"}"#, 0)
                .unwrap_err()
                .contains("not a valid RadarSpeed")
        );
    }
}
