//! The signal path from raw samples to what the correlator and the sleeper counter read:
//! each sensor low-passed, then kept at several rates (a pyramid of pairwise averages) so
//! that a correlation window always spans a few metres of track whatever the speed, and
//! band-passed around the sleeper frequency for counting.
//!
//! Why a pyramid: the delay between the sensors is `D / v`: 7.5 ms at 33 m/s, 2.5 s at
//! 0.1 m/s. Correlating 1024 samples at the rate that puts the delay near 64 samples keeps
//! the window at about 16 delays (3–4 m of track, five or six sleepers) at every speed, the
//! work per window constant, and the delay's resolution the same share of it.

use std::collections::VecDeque;

use super::butterworth::{sleeper_band, Butterworth};

/// Samples in a correlation window, at every level.
pub const WINDOW: usize = 1024;
/// Levels of the pyramid: level ℓ runs at `f_s / 2^ℓ`.
pub const LEVELS: usize = 8;
/// The standstill test's level and span, s.
const ACTIVITY_LEVEL: usize = 4;
const ACTIVITY_S: f64 = 1.5;

/// One sample of both sensors after the filters: (sensor a, sensor b) each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filtered {
    pub low: (f64, f64),
    pub band: (f64, f64),
}

/// One level: both sensors' samples, the latest `WINDOW`.
#[derive(Debug, Clone, Default)]
struct Level {
    a: VecDeque<f64>,
    b: VecDeque<f64>,
    /// The first of a pair waiting for its second, to go up a level.
    half: Option<(f64, f64)>,
    /// Samples this level has had since the stream started.
    count: u64,
}

impl Level {
    fn push(&mut self, a: f64, b: f64) {
        if self.a.len() == WINDOW {
            self.a.pop_front();
            self.b.pop_front();
        }
        self.a.push_back(a);
        self.b.push_back(b);
        self.count += 1;
    }
}

/// Both sensors' signal at every level, and band-passed.
pub struct FrontEnd {
    pub fs_hz: f64,
    /// The stream's first sample time.
    pub start_ns: u64,
    lowpass: [Butterworth; 2],
    bandpass: [Butterworth; 2],
    /// The sleeper frequency the band-pass is tuned to.
    tuned_hz: f64,
    levels: Vec<Level>,
    /// Level-0 samples since the stream started.
    pub samples: u64,
    /// Activity: the variance of the level-4 signal over the latest 1.5 s (a sleeper passes
    /// in that time above 0.4 m/s), and its quietest value so far (the noise floor).
    activity: VecDeque<f64>,
    pub noise_floor: Option<f64>,
    floor_hz: f64,
}

impl FrontEnd {
    /// `lowpass_hz` is clipped below the Nyquist frequency of slow converters.
    pub fn new(fs_hz: f64, start_ns: u64, lowpass_hz: f64, floor_hz: f64) -> Result<Self, String> {
        let lp = Butterworth::lowpass(lowpass_hz.min(0.45 * fs_hz), fs_hz)?;
        let (lo, hi) = sleeper_band(0.0, 0.6, floor_hz, fs_hz);
        let bp = Butterworth::bandpass(lo, hi, fs_hz)?;
        Ok(FrontEnd {
            fs_hz,
            start_ns,
            lowpass: [lp.clone(), lp],
            bandpass: [bp.clone(), bp],
            tuned_hz: 0.0,
            levels: vec![Level::default(); LEVELS],
            samples: 0,
            activity: VecDeque::new(),
            noise_floor: None,
            floor_hz,
        })
    }

    /// The band-pass follows `speed` over sleepers `spacing` apart (retuned when the
    /// sleeper frequency moved by more than 5 %).
    pub fn tune(&mut self, speed_mps: f64, spacing_m: f64) {
        let f = speed_mps.abs() / spacing_m;
        if (f - self.tuned_hz).abs() <= 0.05 * self.tuned_hz.max(self.floor_hz) {
            return;
        }
        let (lo, hi) = sleeper_band(speed_mps, spacing_m, self.floor_hz, self.fs_hz);
        if let Ok(bp) = Butterworth::bandpass(lo, hi, self.fs_hz) {
            for f in &mut self.bandpass {
                f.retune(&bp);
            }
            self.tuned_hz = f;
        }
    }

    /// One sample of each sensor: both low-passed, and both band-passed.
    pub fn push(&mut self, a: f64, b: f64) -> Filtered {
        let (la, lb) = (self.lowpass[0].step(a), self.lowpass[1].step(b));
        let out = Filtered {
            low: (la, lb),
            band: (self.bandpass[0].step(la), self.bandpass[1].step(lb)),
        };
        self.samples += 1;
        let (mut x, mut y) = (la, lb);
        for l in 0..LEVELS {
            if l == ACTIVITY_LEVEL {
                self.activity_sample(x);
            }
            let level = &mut self.levels[l];
            level.push(x, y);
            match level.half.take() {
                Some((px, py)) => (x, y) = (0.5 * (px + x), 0.5 * (py + y)),
                None => {
                    level.half = Some((x, y));
                    break;
                }
            }
        }
        out
    }

    fn activity_sample(&mut self, x: f64) {
        let rate = self.rate(ACTIVITY_LEVEL);
        let span = (ACTIVITY_S * rate).max(8.0) as usize;
        if self.activity.len() == span {
            self.activity.pop_front();
        }
        self.activity.push_back(x);
        // Every tenth of the span: the variance against the floor.
        if self.activity.len() == span
            && self.levels[ACTIVITY_LEVEL]
                .count
                .is_multiple_of((span as u64 / 10).max(1))
        {
            let a = self.activity();
            // The floor follows the quietest span, and drifts up slowly (about doubling in
            // ten minutes) so one quiet spell does not hold it down for ever.
            let drift = 1.0 + 0.7 / (600.0 * 10.0 / ACTIVITY_S);
            self.noise_floor = Some(self.noise_floor.map_or(a, |f| (f * drift).min(a)));
        }
    }

    /// The signal's variance over the latest 1.5 s.
    pub fn activity(&self) -> f64 {
        let n = self.activity.len().max(1) as f64;
        let mean = self.activity.iter().sum::<f64>() / n;
        self.activity
            .iter()
            .map(|x| (x - mean) * (x - mean))
            .sum::<f64>()
            / n
    }

    /// The latest `WINDOW` samples of both sensors at level `l`, if it has that many, and the
    /// time of the window's middle.
    pub fn window(&self, l: usize) -> Option<(Vec<f64>, Vec<f64>, u64)> {
        let level = self.levels.get(l)?;
        if level.a.len() < WINDOW {
            return None;
        }
        let a: Vec<f64> = level.a.iter().copied().collect();
        let b: Vec<f64> = level.b.iter().copied().collect();
        // Level-ℓ sample j averages level-0 samples j·2^ℓ … (j+1)·2^ℓ − 1.
        let step = (1u64 << l) as f64;
        let first = (level.count - WINDOW as u64) as f64 * step;
        let middle = first + (WINDOW as f64 * step - 1.0) / 2.0;
        Some((
            a,
            b,
            self.start_ns + (middle * 1e9 / self.fs_hz).round() as u64,
        ))
    }

    /// The rate of level `l`.
    pub fn rate(&self, l: usize) -> f64 {
        self.fs_hz / (1u64 << l) as f64
    }

    /// The time a window at level `l` spans, first sample to last, s.
    pub fn span_s(&self, l: usize) -> f64 {
        (WINDOW - 1) as f64 / self.rate(l)
    }

    /// Time of the latest sample.
    pub fn now_ns(&self) -> u64 {
        self.start_ns + ((self.samples.max(1) - 1) as f64 * 1e9 / self.fs_hz).round() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_level_halves_the_rate_and_its_window_is_centred_on_its_samples() {
        let mut f = FrontEnd::new(1000.0, 0, 400.0, 0.5).unwrap();
        for k in 0..(WINDOW * 4) {
            let x = k as f64;
            f.push(x, x);
        }
        assert!(f.window(3).is_none());
        let (a, _, mid) = f.window(2).unwrap();
        assert_eq!(a.len(), WINDOW);
        // Level 2 holds all 4096 samples as 1024 averages of four: the window's middle is
        // the middle of the stream, 2.0475 s.
        assert_eq!(mid, 2_047_500_000);
        assert_eq!(f.rate(2), 250.0);
        // The averages of a ramp follow it (after the low-pass's lag).
        assert!((a[WINDOW - 1] - a[WINDOW - 2] - 4.0).abs() < 1e-6);
    }
}
