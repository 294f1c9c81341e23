//! An axle pulse generator's count as it comes off the bus, turned into what an odometer
//! reports: the count unwrapped past its signal's bits, the distance since the last count
//! (from the configured wheel), and the speed over a window of counts, as the odometer's own
//! electronics average it.

use std::collections::VecDeque;

/// A count implying more than this is not motion but a counter that restarted.
const MAX_SPEED_MPS: f64 = 200.0;

/// What one count gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Reading {
    /// Pulses since the first count read.
    pub total: u64,
    pub increment_m: f64,
    pub speed_mps: f64,
}

/// Why a count gave no reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum NoReading {
    /// The first count: nothing to measure against yet.
    First,
    /// Not after the last one in time.
    Stale,
    /// A jump no wheel makes: the counter restarted (counted; the next count starts anew).
    Restarted,
}

pub(super) struct PulseCounter {
    bits: u32,
    metres_per_pulse: f64,
    window_ns: u64,
    last_raw: Option<u64>,
    total: u64,
    /// (time, total) of the counts within the window, the oldest first.
    history: VecDeque<(u64, u64)>,
}

impl PulseCounter {
    /// A counter of `bits` bits on a wheel of `diameter_m` giving `per_revolution` pulses,
    /// its speed averaged over `window_s`.
    pub(super) fn new(bits: u32, per_revolution: u32, diameter_m: f64, window_s: f64) -> Self {
        Self {
            bits: bits.clamp(1, 64),
            metres_per_pulse: std::f64::consts::PI * diameter_m / f64::from(per_revolution),
            window_ns: (window_s * 1e9) as u64,
            last_raw: None,
            total: 0,
            history: VecDeque::new(),
        }
    }

    /// The count `raw` read at `t_ns`.
    pub(super) fn count(&mut self, t_ns: u64, raw: u64) -> Result<Reading, NoReading> {
        let Some(last_raw) = self.last_raw else {
            self.restart(t_ns, raw);
            return Err(NoReading::First);
        };
        let &(last_t, _) = self.history.back().expect("a count was kept");
        if t_ns <= last_t {
            return Err(NoReading::Stale);
        }
        let delta = match self.bits {
            64 => raw.wrapping_sub(last_raw),
            b => raw.wrapping_sub(last_raw) & ((1u64 << b) - 1),
        };
        let increment_m = delta as f64 * self.metres_per_pulse;
        if increment_m / ((t_ns - last_t) as f64 / 1e9) > MAX_SPEED_MPS {
            self.restart(t_ns, raw);
            return Err(NoReading::Restarted);
        }
        self.total += delta;
        self.last_raw = Some(raw);
        self.history.push_back((t_ns, self.total));
        // Keep the newest count at least a window old, and nothing older.
        while self.history.len() > 2 && t_ns - self.history[1].0 >= self.window_ns {
            self.history.pop_front();
        }
        let (t0, total0) = self.history[0];
        let span_s = (t_ns - t0) as f64 / 1e9;
        Ok(Reading {
            total: self.total,
            increment_m,
            speed_mps: (self.total - total0) as f64 * self.metres_per_pulse / span_s,
        })
    }

    fn restart(&mut self, t_ns: u64, raw: u64) {
        self.last_raw = Some(raw);
        self.history.clear();
        self.history.push_back((t_ns, self.total));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_give_distance_and_a_windowed_speed_past_the_counter_s_wrap() {
        // 200 pulses a turn of a 0.85 m wheel: 13.35 mm a pulse; 20 m/s is 1498 pulses/s.
        let mut c = PulseCounter::new(16, 200, 0.85, 0.2);
        let per_pulse = std::f64::consts::PI * 0.85 / 200.0;
        let rate = 20.0 / per_pulse;
        assert_eq!(c.count(0, 65_000), Err(NoReading::First));
        let mut last = None;
        for k in 1..=50u64 {
            let t = k * 40_000_000;
            let raw = (65_000.0 + rate * t as f64 / 1e9).floor() as u64 % 65_536;
            let r = c.count(t, raw).unwrap();
            if k > 5 {
                assert!((r.speed_mps - 20.0).abs() < 0.1, "{k}: {r:?}");
            }
            last = Some(r);
        }
        let r = last.unwrap();
        // Two seconds at 20 m/s, across the 16-bit wrap.
        assert!((r.total as f64 * per_pulse - 40.0).abs() < 0.02, "{r:?}");
        assert_eq!(c.count(50 * 40_000_000, 7), Err(NoReading::Stale));
        // A restarted counter is not a leap of the train.
        assert_eq!(c.count(51 * 40_000_000, 3), Err(NoReading::Restarted));
        assert!(c.count(52 * 40_000_000, 63).is_ok());
    }
}
