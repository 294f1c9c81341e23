//! The stream of one receiver's sentences into fixes: which cycle each sentence belongs to
//! (the module doc's placement rules) and the date of each fix.

use std::collections::VecDeque;

use railfuse_catalog::messages::GnssFix;

use super::cycle::Cycle;
use super::sentences::{decode, Kind, Report, Talker};
use super::{Decoded, NmeaError, Sentence};
use crate::decode::time::Date;

/// Fixes held while no date is known (a minute at 10 Hz); older ones are dropped and counted.
pub const MAX_HELD: usize = 600;

const DAY_NS: u64 = 86_400_000_000_000;

/// The Unix time of midnight at the start of `date`.
fn midnight((y, mo, d): Date) -> Option<u64> {
    crate::decode::time::unix_ns(y, mo, d, 0, 0, 0, 0)
}

/// The stamp of time of day `tod_ns` on the day (of the days around `reference_ns`) that puts
/// it nearest that reference.
fn nearest_day(reference_ns: u64, tod_ns: u64) -> u64 {
    let at = reference_ns - reference_ns % DAY_NS + tod_ns;
    [at.checked_sub(DAY_NS), Some(at), at.checked_add(DAY_NS)]
        .into_iter()
        .flatten()
        .min_by_key(|t| t.abs_diff(reference_ns))
        .unwrap_or(at)
}

/// Assembles fixes from a stream of sentences of one receiver, one per reporting cycle.
#[derive(Debug, Default, Clone)]
pub struct FixAssembler {
    cycle: Option<Cycle>,
    /// The date an import was given, for fixes before any dated cycle.
    given_date: Option<Date>,
    /// The stamp of the latest dated or stamped cycle: the reference for the next undated one.
    last_ns: Option<u64>,
    held: VecDeque<(u64, GnssFix)>,
    ready: VecDeque<GnssFix>,
    /// Fixes dropped for want of a date.
    pub undated: u64,
    /// Epochs the receiver reported without a time (no fix can be stamped): ended there,
    /// nothing of them carried into the next epoch.
    pub untimed: u64,
}

impl FixAssembler {
    /// An assembler that knows the date from the start (an import given `--date`).
    pub fn with_date(date: Option<Date>) -> Self {
        Self {
            given_date: date,
            ..Self::default()
        }
    }

    /// The next fix ready, in the order of their cycles.
    pub fn next_fix(&mut self) -> Option<GnssFix> {
        self.ready.pop_front()
    }

    /// End of the stream: the open cycle's fix is made; fixes still waiting for a date are
    /// dropped. Returns how many were dropped for want of one in all.
    pub fn finish(&mut self, clock_ns: Option<u64>) -> u64 {
        self.close(clock_ns);
        self.undated += self.held.len() as u64;
        self.held.clear();
        self.undated
    }

    /// Feeds one sentence. `clock_ns` is a UTC clock near the sentence's time when there is
    /// one (a live recorder's receive time).
    pub fn feed(&mut self, s: &Sentence<'_>, clock_ns: Option<u64>) -> Result<Decoded, NmeaError> {
        let Some(Report {
            kind,
            talker,
            tod_ns,
            part,
        }) = decode(s)?
        else {
            return Ok(Decoded::Skipped);
        };
        self.enter(kind, talker, tod_ns, clock_ns);
        let cycle = self.cycle.get_or_insert_with(Cycle::default);
        if tod_ns.is_none() && kind.carries_time() && cycle.tod_ns.is_none() {
            cycle.untimed_epoch = true;
        }
        cycle.add(talker, kind, part);
        Ok(Decoded::Used)
    }

    /// A sentence arrives: the cycle it belongs to is opened (rules 1 to 3).
    fn enter(&mut self, kind: Kind, talker: Talker, tod: Option<u64>, clock_ns: Option<u64>) {
        let open = self.cycle.as_ref().map(|c| (c.tod_ns, c.untimed_epoch));
        let begins = match (tod, open) {
            (_, None) => true,
            // Rule 1 and 2: untimed, it joins the open cycle unless that holds its kind.
            (None, Some(_)) => self.cycle.as_ref().is_some_and(|c| c.holds(talker, kind)),
            (Some(t), Some((Some(open), _))) => t != open,
            // Rule 3: an epoch without a time ends; sentences placed before a time take it.
            (Some(_), Some((None, untimed_epoch))) => untimed_epoch,
        };
        if begins {
            self.close(clock_ns);
            self.cycle = Some(Cycle::at(tod));
        } else if let Some(c) = self.cycle.as_mut() {
            c.tod_ns = c.tod_ns.or(tod);
        }
    }

    /// Ends the open cycle: its fix is stamped (or held for a date) and queued.
    fn close(&mut self, clock_ns: Option<u64>) {
        let Some(c) = self.cycle.take() else { return };
        let Some(tod) = c.tod_ns else {
            self.untimed += u64::from(c.has_position_report());
            return;
        };
        let stamp = if let Some(date) = c.date {
            midnight(date).map(|m| m + tod)
        } else if let Some(reference) = clock_ns.or(self.last_ns) {
            Some(nearest_day(reference, tod))
        } else {
            self.given_date.and_then(midnight).map(|m| m + tod)
        };
        let Some(stamp) = stamp else {
            if let Some(fix) = c.fix(0) {
                if self.held.len() == MAX_HELD {
                    self.held.pop_front();
                    self.undated += 1;
                }
                self.held.push_back((tod, fix));
            }
            return;
        };
        // Fixes that waited for a date take the day nearest this one.
        for (held_tod, fix) in std::mem::take(&mut self.held) {
            self.ready.push_back(GnssFix {
                stamp_ns: nearest_day(stamp, held_tod),
                ..fix
            });
        }
        self.last_ns = Some(stamp);
        if let Some(fix) = c.fix(stamp) {
            self.ready.push_back(fix);
        }
    }
}
