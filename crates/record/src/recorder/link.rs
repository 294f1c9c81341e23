//! What a source's thread shares with the recorder: its bounded queue, its figures, the stop
//! flag and the alerts said at once; and the few rules every source follows (how long it
//! drains on a stop, what a read that found nothing is).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use railfuse_catalog::messages::*;

use super::message::Item;

pub type Stats = Arc<Mutex<SourceStats>>;

/// A source's figures. A thread that panicked while holding them leaves them usable: they are
/// counters, and the recorder must go on reporting the other sources.
pub fn lock(stats: &Stats) -> MutexGuard<'_, SourceStats> {
    stats.lock().unwrap_or_else(PoisonError::into_inner)
}

pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// How long stream sources keep reading what their peers already sent once the recording
/// stops.
pub const DRAIN: Duration = Duration::from_secs(2);

/// What a source's thread shares with the recorder.
#[derive(Clone)]
pub struct Link {
    pub queue: flume::Sender<Item>,
    pub stats: Stats,
    pub stop: Arc<AtomicBool>,
    /// Said at once on the recorder's status line (a listener that cannot accept, a UDP
    /// buffer the kernel keeps small).
    pub alerts: flume::Sender<String>,
}

impl Link {
    pub(super) fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    pub(super) fn alert(&self, text: String) {
        lock(&self.stats).last_error = Some(text.clone());
        let _ = self.alerts.send(text);
    }

    /// Queues decoded items, GNSS fixes on `gnss_topic` when the source is mapped to one;
    /// false when the recorder has gone.
    pub(super) fn send(&self, items: &mut Vec<Item>, gnss_topic: Option<&str>) -> bool {
        let mut dropped = 0;
        for mut item in items.drain(..) {
            if let (Some(t), AnyMessage::GnssFix(_)) = (gnss_topic, &item.message) {
                item.topic = t.to_owned();
            }
            match self.queue.try_send(item) {
                Ok(()) => {}
                Err(flume::TrySendError::Full(_)) => dropped += 1,
                Err(flume::TrySendError::Disconnected(_)) => return false,
            }
        }
        if dropped > 0 {
            lock(&self.stats).dropped += dropped;
        }
        true
    }
}

/// A read that found nothing waiting (a time-out, a non-blocking socket with no data, a
/// signal): not an error of the source.
pub(super) fn nothing_waiting(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::{Interrupted, TimedOut, WouldBlock};
    matches!(e.kind(), WouldBlock | TimedOut | Interrupted)
}

/// A source's end once the recorder stops: it reads on what its peer already sent, for
/// [`DRAIN`] at most.
#[derive(Default)]
pub struct Drain {
    until: Option<Instant>,
}

impl Drain {
    /// Whether the source should end now (`stopping`: the recorder has said stop).
    pub fn over(&mut self, stopping: bool) -> bool {
        if self.until.is_none() && stopping {
            self.until = Some(Instant::now() + DRAIN);
        }
        self.until.is_some_and(|t| Instant::now() >= t)
    }

    /// Draining: a read that finds nothing ends the source.
    pub fn draining(&self) -> bool {
        self.until.is_some()
    }
}
