//! A short, moving window of a reference trajectory (ground truth or another pipeline), to
//! evaluate it at the stamps of estimates that arrive a little late. Bounded: samples older
//! than the retention span behind the newest one are dropped.

use std::collections::VecDeque;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSample {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
}

#[derive(Debug, Clone)]
pub struct ReferenceTrack {
    samples: VecDeque<ReferenceSample>,
    retain_ns: u64,
}

impl ReferenceTrack {
    pub fn new(retain_s: f64) -> Self {
        Self {
            samples: VecDeque::new(),
            retain_ns: (retain_s * 1e9) as u64,
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

    /// Chainage and speed at `stamp_ns`, linearly interpolated; `None` outside the window.
    pub fn at(&self, stamp_ns: u64) -> Option<(f64, f64)> {
        let (first, last) = (self.samples.front()?, self.samples.back()?);
        if stamp_ns < first.stamp_ns || stamp_ns > last.stamp_ns {
            return None;
        }
        let i = self.samples.partition_point(|r| r.stamp_ns < stamp_ns);
        let b = self.samples[i];
        let a = if i == 0 { b } else { self.samples[i - 1] };
        let f = if b.stamp_ns > a.stamp_ns {
            (stamp_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64
        } else {
            0.0
        };
        Some((
            a.chainage_m + f * (b.chainage_m - a.chainage_m),
            a.speed_mps + f * (b.speed_mps - a.speed_mps),
        ))
    }
}
