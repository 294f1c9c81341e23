//! CAN frames into the log: each frame whole on `/can/<bus>/frames`, and, with the vehicle's
//! DBC, each known message's signals on `/can/<bus>/<Message>`. One piece of code for the live
//! sources (SocketCAN, SLCAN, socketcand, cannelloni) and for the imported logs (candump,
//! ASC, BLF).
//!
//! What the DBC does not know is kept raw and counted, never dropped: a frame whose id it
//! has not, one shorter than its message, a signal outside its declared range (written, and
//! flagged in its channel). Error frames are written and counted too. Bus names come from
//! untrusted input, so at most [`MAX_BUSES`] buses get channels; frames of any further one
//! are counted and skipped.

use std::collections::HashMap;

use railfuse_can::dbc::BusDbcs;
use railfuse_can::decode::Decoded;
use railfuse_can::frame::Frame;
use railfuse_catalog::foreign::can::{frames_topic, signals_topic};
use railfuse_catalog::messages::{AnyMessage, CanFrame, CanSignals, SourceStats};

use crate::recorder::message::Item;

/// The most buses one source writes channels for.
pub const MAX_BUSES: usize = 16;

/// The reasons counted, as the report and `/recorder/diagnostics` name them.
pub const UNKNOWN_ID: &str = "CAN id not in the DBC (kept raw)";
pub const TOO_SHORT: &str = "CAN frame shorter than its DBC message (kept raw)";
pub const OUT_OF_RANGE: &str = "CAN signal outside its DBC range (kept, flagged)";
pub const ERROR_FRAME: &str = "CAN error frame";
pub const TOO_MANY_BUSES: &str = "CAN frame of a bus past the 16th (skipped)";

/// Turns frames into log items.
#[derive(Default)]
pub struct CanDecoder {
    dbcs: BusDbcs,
    /// Each bus's frame topic, and each (bus, id, extended)'s signal topic.
    frame_topics: HashMap<String, String>,
    signal_topics: HashMap<(String, u32, bool), String>,
}

impl CanDecoder {
    /// Decoding each bus with its DBC (none: frames only).
    pub fn new(dbcs: BusDbcs) -> Self {
        Self {
            dbcs,
            ..Default::default()
        }
    }

    /// The items of `frame`, received at `receive_ns` (its log time), into `out`.
    pub fn frame(
        &mut self,
        frame: &Frame,
        receive_ns: u64,
        stats: &mut SourceStats,
        out: &mut Vec<Item>,
    ) {
        let topic = match self.frame_topics.get(&frame.bus) {
            Some(t) => t.clone(),
            None if self.frame_topics.len() >= MAX_BUSES => {
                stats.count(TOO_MANY_BUSES);
                return;
            }
            None => {
                let t = frames_topic(&frame.bus);
                self.frame_topics.insert(frame.bus.clone(), t.clone());
                t
            }
        };
        if frame.error {
            stats.warn(ERROR_FRAME);
        }
        stats.received += 1;
        out.push(Item {
            topic,
            log_time_ns: receive_ns,
            message: AnyMessage::CanFrame(CanFrame::from_frame(frame, receive_ns)),
        });
        let Some(db) = self.dbcs.for_bus(&frame.bus) else {
            return;
        };
        match db.decode(frame) {
            Decoded::Signals { message, values } => {
                if values.iter().any(|v| v.out_of_range) {
                    stats.warn(OUT_OF_RANGE);
                }
                let key = (frame.bus.clone(), frame.id, frame.extended);
                let topic = self
                    .signal_topics
                    .entry(key)
                    .or_insert_with(|| signals_topic(&frame.bus, &message.name))
                    .clone();
                stats.received += 1;
                out.push(Item {
                    topic,
                    log_time_ns: receive_ns,
                    message: AnyMessage::CanSignals(CanSignals::new(frame, &message.name, values)),
                });
            }
            Decoded::Unknown if !frame.error && !frame.rtr => stats.warn(UNKNOWN_ID),
            Decoded::Unknown => {}
            Decoded::TooShort { .. } => stats.warn(TOO_SHORT),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_can::dbc::Database;
    use std::sync::Arc;

    fn frame(bus: &str, id: u32, data: &[u8]) -> Frame {
        Frame {
            stamp_ns: 5,
            bus: bus.into(),
            id,
            extended: false,
            rtr: false,
            error: false,
            fd: false,
            brs: false,
            esi: false,
            data: data.to_vec(),
        }
    }

    #[test]
    fn unknown_short_and_out_of_range_frames_are_kept_and_counted() {
        let db = Database::parse(
            "vehicle.dbc",
            include_str!("../../../../samples/vehicle.dbc"),
        )
        .unwrap();
        let mut d = CanDecoder::new(BusDbcs::every_bus(Some(Arc::new(db))));
        let (mut stats, mut out) = (SourceStats::default(), Vec::new());
        // AxleSpeed1 = 200 m/s, past its [0|120].
        d.frame(
            &frame("can0", 0x100, &[0x20, 0x4E, 0, 0, 0, 0, 0, 0]),
            9,
            &mut stats,
            &mut out,
        );
        d.frame(&frame("can0", 0x7FF, &[1]), 10, &mut stats, &mut out);
        d.frame(&frame("can0", 0x100, &[1, 2]), 11, &mut stats, &mut out);
        let topics: Vec<&str> = out.iter().map(|i| i.topic.as_str()).collect();
        assert_eq!(
            topics,
            [
                "/can/can0/frames",
                "/can/can0/WheelSpeed",
                "/can/can0/frames",
                "/can/can0/frames"
            ]
        );
        let AnyMessage::CanSignals(s) = &out[1].message else {
            panic!("{:?}", out[1]);
        };
        assert!(s.signals[0].out_of_range && (s.signals[0].value - 200.0).abs() < 1e-9);
        assert_eq!(stats.warnings[OUT_OF_RANGE], 1);
        assert_eq!(stats.warnings[UNKNOWN_ID], 1);
        assert_eq!(stats.warnings[TOO_SHORT], 1);
        assert_eq!(out[2].log_time_ns, 10);
        for bus in 0..20 {
            d.frame(&frame(&format!("b{bus}"), 1, &[]), 12, &mut stats, &mut out);
        }
        assert_eq!(stats.skipped[TOO_MANY_BUSES], 5);
    }
}
