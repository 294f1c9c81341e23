//! Sensors made from the CAN bus (`[sensor."<topic>"] from = "can:Message.Signal"`): every
//! frame of a `railfuse.CanFrame` channel goes through the configuration's DBC, and each
//! message it makes is read by the pipelines as if the log had that sensor's channel, and
//! written to the output on it, so the fused log shows what was fused.

use std::sync::Arc;

use railfuse_catalog::foreign::can::SensorBridge;
use railfuse_catalog::log::{ChannelId, ChannelInfo, LogMessage, LogWriter, SchemaInfo};
use railfuse_catalog::messages::{AnyMessage, CanFrame, ChannelMessage, MessageKind};

use crate::error::{Error, Result};

use super::Replay;

/// A topic the bridge makes: its output channel, whose id is also the channel the pipelines
/// read it on (free of the log's ids).
struct Made {
    topic: String,
    kind: MessageKind,
    output: ChannelId,
    /// The channel the pipelines read, once the log's first frame channel is met.
    info: Option<Arc<ChannelInfo>>,
}

/// The metadata of a made channel in the output: a later re-fusion of that output with the
/// same configuration makes it again (and drops this one) rather than refusing two sources.
const MADE_FROM: (&str, &str) = ("made_from", "can");

pub(super) struct CanSensors {
    bridge: SensorBridge,
    made: Vec<Made>,
}

impl CanSensors {
    /// The bridge of `spec`, its made topics' output channels registered on free ids.
    pub(super) fn register(
        spec: &crate::spec::CanSensors,
        mut next_id: impl FnMut() -> Result<u16>,
        writer: &mut LogWriter,
    ) -> Result<Self> {
        let bridge = spec.bridge();
        let mut made = Vec::new();
        let metadata = [(MADE_FROM.0.to_owned(), MADE_FROM.1.to_owned())].into();
        for (topic, kind) in bridge.topics() {
            let (schema, id) = (next_id()?, next_id()?);
            let output = writer.add_channel_of_with_ids(kind, schema, id, topic, &metadata)?;
            made.push(Made {
                topic: topic.to_owned(),
                kind,
                output,
                info: None,
            });
        }
        Ok(Self { bridge, made })
    }

    /// What the bridge counted (unknown ids, short frames, out-of-range signals).
    pub(super) fn counts(&self) -> &railfuse_catalog::foreign::can::BridgeCounts {
        &self.bridge.counts
    }
}

/// The channel a made topic is read on: JSON of its catalogue kind.
fn made_channel(id: u16, topic: &str, kind: MessageKind) -> Arc<ChannelInfo> {
    Arc::new(ChannelInfo {
        id,
        topic: topic.to_owned(),
        message_encoding: railfuse_catalog::log::MESSAGE_ENCODING.to_owned(),
        metadata: Default::default(),
        schema: Some(Arc::new(SchemaInfo {
            id: 0,
            name: kind.schema_name().to_owned(),
            encoding: railfuse_catalog::log::SCHEMA_ENCODING.to_owned(),
            data: kind.schema_bytes(),
        })),
    })
}

/// How the replay takes a log channel, where CAN sensors are configured.
pub(super) enum CanRoute {
    /// Not the bus's, nor on a made topic.
    Other,
    /// Frames: the bridge reads them.
    Frames,
    /// A made topic from an earlier re-fusion of the same bus: left out, made again.
    MadeBefore,
}

impl Replay<'_> {
    /// How the log channel `info` is taken. On the first frame channel the made topics'
    /// channels are routed to the pipelines. A log channel on a made topic that was not made
    /// from the bus is an error: the sensor would come from two places.
    pub(super) fn route_can(&mut self, info: &ChannelInfo) -> Result<CanRoute> {
        let Some(can) = &self.can else {
            return Ok(CanRoute::Other);
        };
        if can.made.iter().any(|m| m.topic == info.topic) {
            if info.metadata.get(MADE_FROM.0).map(String::as_str) == Some(MADE_FROM.1) {
                return Ok(CanRoute::MadeBefore);
            }
            return Err(Error::ConfigSyntax {
                path: self.opts.config.path.clone(),
                message: format!(
                    "[sensor.\"{0}\"] makes {0} from the CAN bus, and {1} has that channel \
                     too: map another topic, or leave the [sensor] table out",
                    info.topic,
                    self.input().display()
                ),
            });
        }
        if info.schema_name() != CanFrame::SCHEMA_NAME {
            return Ok(CanRoute::Other);
        }
        let unrouted: Vec<(usize, Arc<ChannelInfo>)> = can
            .made
            .iter()
            .enumerate()
            .filter(|(_, m)| m.info.is_none())
            .map(|(i, m)| (i, made_channel(m.output.0, &m.topic, m.kind)))
            .collect();
        for (i, channel) in unrouted {
            // Known as made before it is routed (see `is_made`).
            self.can.as_mut().expect("checked above").made[i].info = Some(channel.clone());
            self.route(channel)?;
        }
        Ok(CanRoute::Frames)
    }

    /// `info` is a channel the bridge makes (not the log's).
    pub(super) fn is_made(&self, info: &Arc<ChannelInfo>) -> bool {
        self.can.as_ref().is_some_and(|can| {
            can.made
                .iter()
                .any(|m| m.info.as_ref().is_some_and(|c| Arc::ptr_eq(c, info)))
        })
    }

    /// A frame: the sensor messages it makes, written and fused.
    pub(super) fn can_frame(&mut self, msg: &LogMessage<'_>) -> Result<()> {
        let frame: CanFrame = match msg.decode(self.input()) {
            Ok(f) => f,
            Err(e) => {
                self.report
                    .undecodable
                    .add(&msg.channel.topic, "decode", || e.to_string());
                return Ok(());
            }
        };
        let can = self.can.as_mut().expect("routed as CAN");
        let made: Vec<(Arc<ChannelInfo>, ChannelId, AnyMessage)> = can
            .bridge
            .frame(&frame)
            .into_iter()
            .filter_map(|(topic, m)| {
                let made = can.made.iter().find(|c| c.topic == topic)?;
                Some((made.info.clone()?, made.output, m))
            })
            .collect();
        for (info, output, message) in made {
            self.writer.write_any(output, msg.log_time_ns, &message)?;
            let json = message.to_json();
            if let Some(observe) = self.opts.observer {
                observe(&info.topic, info.schema_name(), msg.log_time_ns, &json);
            }
            let made = LogMessage {
                channel: &info,
                sequence: 0,
                log_time_ns: msg.log_time_ns,
                publish_time_ns: msg.log_time_ns,
                data: &json,
            };
            self.sensor_message(info.id, &made)?;
        }
        Ok(())
    }
}
