//! A short, moving window of a reference trajectory (ground truth or another pipeline), to
//! evaluate it at the stamps of estimates that arrive a little late. Bounded: samples older
//! than the retention span behind the newest one are dropped.
//!
//! The reference is interpolated only between samples at most [`MAX_GAP_PERIODS`] of its own
//! periods apart (the median of its recent sample intervals): a GNSS receiver silent in a
//! tunnel for 27 s is a gap, and an estimate inside it is not scored against a straight line
//! drawn across it.

use std::collections::VecDeque;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSample {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
}

/// Two reference samples further apart than this many of the reference's periods bound a gap.
pub const MAX_GAP_PERIODS: u64 = 5;

/// Recent sample intervals kept to estimate the reference's period.
const INTERVALS: usize = 31;

#[derive(Debug, Clone)]
pub struct ReferenceTrack {
    samples: VecDeque<ReferenceSample>,
    retain_ns: u64,
    /// The latest sample intervals, for the median period.
    intervals: VecDeque<u64>,
    period_ns: Option<u64>,
}

/// The reference at a stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lookup {
    /// Chainage and speed, interpolated.
    At(f64, f64),
    /// Between two samples further apart than [`MAX_GAP_PERIODS`] periods.
    Gap,
    /// Before or after the samples held.
    Outside,
}

impl ReferenceTrack {
    pub fn new(retain_s: f64) -> Self {
        Self {
            samples: VecDeque::new(),
            retain_ns: (retain_s * 1e9) as u64,
            intervals: VecDeque::with_capacity(INTERVALS),
            period_ns: None,
        }
    }

    /// Adds a sample; samples must move forward in time (others are ignored).
    pub fn push(&mut self, sample: ReferenceSample) -> bool {
        if self
            .samples
            .back()
            .is_some_and(|r| sample.stamp_ns <= r.stamp_ns)
        {
            return false;
        }
        if let Some(last) = self.samples.back() {
            let interval = sample.stamp_ns - last.stamp_ns;
            let dropped = match self.intervals.len() == INTERVALS {
                true => self.intervals.pop_front(),
                false => None,
            };
            self.intervals.push_back(interval);
            // A regular reference drops the interval it adds: the median stands.
            if dropped != Some(interval) || self.period_ns.is_none() {
                // The median, on the stack.
                let mut recent = [0u64; INTERVALS];
                let n = self.intervals.len();
                for (slot, &i) in recent.iter_mut().zip(&self.intervals) {
                    *slot = i;
                }
                self.period_ns = Some(*recent[..n].select_nth_unstable(n / 2).1);
            }
        }
        self.samples.push_back(sample);
        let keep_from = sample.stamp_ns.saturating_sub(self.retain_ns);
        while self.samples.len() > 2 && self.samples[1].stamp_ns < keep_from {
            self.samples.pop_front();
        }
        true
    }

    pub fn newest_ns(&self) -> Option<u64> {
        self.samples.back().map(|s| s.stamp_ns)
    }

    /// Chainage and speed at `stamp_ns`, linearly interpolated; `None` outside the window or
    /// in a gap.
    pub fn at(&self, stamp_ns: u64) -> Option<(f64, f64)> {
        match self.lookup(stamp_ns) {
            Lookup::At(s, v) => Some((s, v)),
            Lookup::Gap | Lookup::Outside => None,
        }
    }

    /// The reference at `stamp_ns`, or why there is none.
    pub fn lookup(&self, stamp_ns: u64) -> Lookup {
        let (Some(first), Some(last)) = (self.samples.front(), self.samples.back()) else {
            return Lookup::Outside;
        };
        if stamp_ns < first.stamp_ns || stamp_ns > last.stamp_ns {
            return Lookup::Outside;
        }
        let i = self.samples.partition_point(|r| r.stamp_ns < stamp_ns);
        let b = self.samples[i];
        let a = if i == 0 { b } else { self.samples[i - 1] };
        let span = b.stamp_ns - a.stamp_ns;
        if self
            .period_ns
            .is_some_and(|p| span > p.saturating_mul(MAX_GAP_PERIODS))
        {
            return Lookup::Gap;
        }
        let f = if span > 0 {
            (stamp_ns - a.stamp_ns) as f64 / span as f64
        } else {
            0.0
        };
        Lookup::At(
            a.chainage_m + f * (b.chainage_m - a.chainage_m),
            a.speed_mps + f * (b.speed_mps - a.speed_mps),
        )
    }
}
