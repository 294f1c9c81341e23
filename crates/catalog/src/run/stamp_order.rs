//! `--time stamp`: a part's messages in the order of their own stamps (the sensor's time, as
//! PlotJuggler's header-stamp option orders them) rather than the order they were recorded.
//!
//! A file holds its messages in log-time order, and a sensor's stamp precedes its log time by
//! its latency, which differs between sensors. Each part's messages are read ahead and held
//! until no later message of the part can carry an earlier stamp: once the part's log time
//! is [`WINDOW_NS`] past a held stamp (no sensor is assumed later than that). A message whose
//! stamp is further back than that leaves as it comes, counted. Memory is bounded by the
//! messages of one window.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::Arc;

use super::ClockMap;
use crate::foreign::Translator;
use crate::log::{ChannelInfo, IdMap, LogMessage};
use crate::messages::StampClock;

/// The longest a sensor's stamp is taken to precede its log time: 2 s.
pub const WINDOW_NS: u64 = 2_000_000_000;

/// A message held for its stamp.
pub(super) struct Held {
    pub stamp_ns: u64,
    /// Its order in its part's file (ties keep it).
    pub order: u64,
    /// The part's channel id.
    pub channel: u16,
    pub sequence: u32,
    pub log_ns: u64,
    pub publish_ns: u64,
    pub data: Vec<u8>,
}

impl PartialEq for Held {
    fn eq(&self, o: &Self) -> bool {
        (self.stamp_ns, self.order) == (o.stamp_ns, o.order)
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Held {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (self.stamp_ns, self.order).cmp(&(o.stamp_ns, o.order))
    }
}

/// One part's messages in stamp order.
#[derive(Default)]
pub(super) struct StampOrder {
    waiting: BinaryHeap<Reverse<Held>>,
    newest_log_ns: u64,
    /// The message released as the part's head.
    pub head: Option<Held>,
    /// Messages whose stamp was more than the window behind the part's log time.
    pub late: u64,
}

impl StampOrder {
    pub fn hold(&mut self, held: Held) {
        self.newest_log_ns = self.newest_log_ns.max(held.log_ns);
        if held.stamp_ns.saturating_add(WINDOW_NS) < self.newest_log_ns {
            self.late += 1;
        }
        self.waiting.push(Reverse(held));
    }

    /// The earliest held message, once no later one can come before it (or, at the part's
    /// `end`, whatever is held).
    pub fn release(&mut self, end: bool) -> Option<&Held> {
        let due = self.waiting.peek().is_some_and(|Reverse(h)| {
            end || h.stamp_ns.saturating_add(WINDOW_NS) <= self.newest_log_ns
        });
        if !due {
            return None;
        }
        self.head = self.waiting.pop().map(|Reverse(h)| h);
        self.head.as_ref()
    }
}

/// Each channel's stamp reader: its catalogue kind, else the translator of its foreign
/// schema (a ROS message's `header.stamp`), else none (the log time stands in).
#[derive(Default)]
pub(super) struct Stamps {
    translators: IdMap<Option<Arc<Translator>>>,
}

impl Stamps {
    /// The stamp of `m` on the run's clock (a recorder's own stamps corrected with its
    /// `clock`, GNSS time as it is); its log time where it has none.
    pub fn of(
        &mut self,
        run_channel: u16,
        m: &LogMessage<'_>,
        clock: &ClockMap,
        log_ns: u64,
    ) -> u64 {
        let channel: &ChannelInfo = m.channel;
        if let Some(kind) = channel.kind() {
            return match (m.decode_any(std::path::Path::new("")), kind.stamp_clock()) {
                (Ok(Some(d)), StampClock::Recorder) => clock.correct(d.stamp_ns()),
                (Ok(Some(d)), _) => d.stamp_ns(),
                _ => log_ns,
            };
        }
        let translator = self.translators.entry(run_channel).or_insert_with(|| {
            Translator::for_channel(channel, None)
                .ok()
                .flatten()
                .map(Arc::new)
        });
        match translator
            .as_ref()
            .map(|t| t.translate(m.data, m.log_time_ns))
        {
            Some(Ok(crate::foreign::Translated::Message {
                message,
                took_log_time: false,
            })) => clock.correct(message.stamp_ns()),
            _ => log_ns,
        }
    }
}
