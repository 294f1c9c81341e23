//! Moving off from a standstill. A correlation window assumes the train moving through all of
//! it, and the constant-acceleration warp assumes it moving at both ends (`|k| < 1`). In the
//! first seconds of a start neither holds: the train stands, then moves off. Model the start:
//!
//! ```text
//! x(t) = ½ α (t − t₀)²   for t ≥ t₀,   0 before
//! ```
//!
//! and resample both sensors on an even distance grid of step `h = D / 32`: the trailing
//! sensor's signal is then the leading one's shifted by exactly 32 steps, since `D` is known.
//! The start `(t₀, α)` is the one that maximises the correlation at that shift. It is
//! searched as (time since the start `τ = t_e − t₀`, distance covered `x_e = ½ α τ²`) at
//! the window's end `t_e`, where the grid point `x` falls at `t₀ + τ √(x / x_e)`. The speed
//! there is `v_e = α τ = 2 x_e / τ`.
//!
//! Nothing can be measured before the trailing sensor has passed over track the leading one
//! saw while moving, and that track holds a clamp: `x_e ≥ D + 0.7 m`. At 1.1 m/s² that is
//! about 1.3 s after the start, at 1.4 m/s; before, the speed is not observable.
//!
//! A fit is believed when the next window's fit agrees with it on the start (within 0.2 s)
//! and on the acceleration (within 25 %): a chance alignment of clamps does not repeat.

use super::correlation::pearson_at;
use super::front_end::{FrontEnd, LEVELS};

/// A start's fit is no measurement below this correlation: its window has seen a few clamps
/// only, and a chance alignment of two of them can reach a middling ρ.
pub const MIN_RHO: f64 = 0.9;
/// Grid steps per `D` on the distance grid: the fine grid, and the coarse one searched first.
const FINE_STEPS: usize = 32;
const COARSE_STEPS: usize = 16;
/// Track the trailing sensor must have passed beyond `D`, m: a sleeper spacing and more.
const MIN_OVERLAP_M: f64 = 0.7;
/// The coarse search's steps: time since the start, s, and the distance's ratio.
const SINCE_STEP_S: f64 = 0.05;
const TRAVEL_RATIO: f64 = 1.03;
/// Starts this recent are not searched, s.
const MIN_SINCE_S: f64 = 0.3;
/// The lowest level searched (its window is 1.6 s at 10 kHz).
const FIRST_LEVEL: usize = 4;
/// The activity span a standstill is judged over, s: the start may lie this far before the
/// last quiet window.
const QUIET_SPAN_S: f64 = 1.5;
/// Two fits agree on the start within this, s, and on the acceleration within this share.
const AGREE_ONSET_S: f64 = 0.2;
const AGREE_ACCELERATION: f64 = 0.25;
/// The speed variance's share for what the model leaves out (the jerk of a real start).
const MODEL_SPEED_SHARE: f64 = 0.02;

/// One fitted start, its times in ns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Start {
    /// When the train moved off.
    pub onset_ns: u64,
    /// The window's end, where the speed is measured.
    pub at_ns: u64,
    pub acceleration_mps2: f64,
    pub speed_mps: f64,
    /// Distance covered since the start, m.
    pub travelled_m: f64,
    pub rho: f64,
    pub level: usize,
}

impl Start {
    /// The speed's variance, (m/s)²: the shift's resolution on the grid as the correlation
    /// falls (as for a correlation peak), and the model's own share.
    pub fn speed_variance(&self) -> f64 {
        let lag_std = 0.05 + 2.0 * (1.0 - self.rho).max(0.0);
        let v = self.speed_mps;
        (v * lag_std / FINE_STEPS as f64).powi(2) + (MODEL_SPEED_SHARE * v).powi(2)
    }

    /// The acceleration's variance, (m/s²)²: wide, for a real start ramps its acceleration
    /// up (jerk-limited) and the fitted α is the mean over the ramp, well below the one
    /// reached.
    pub fn acceleration_variance(&self) -> f64 {
        (0.3 * self.acceleration_mps2 + 0.05 * (2.0 - self.rho)).powi(2)
    }

    fn agrees(&self, other: &Start) -> bool {
        let onset = (self.onset_ns as f64 - other.onset_ns as f64).abs() / 1e9;
        let acc = (self.acceleration_mps2 - other.acceleration_mps2).abs();
        onset < AGREE_ONSET_S && acc < AGREE_ACCELERATION * self.acceleration_mps2.max(0.1)
    }
}

/// A confirmed start with where the train stood: the dead-reckoned distance and the
/// filter's chainage (if it had one) then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Moved {
    pub start: Start,
    pub stood_odometer_m: f64,
    pub stood_chainage_m: Option<f64>,
}

/// What a window of a start gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fit {
    /// Not enough track passed both sensors yet, or no fit good enough.
    Nothing {
        best_rho: f64,
    },
    /// A fit not yet confirmed by the next window's.
    Unconfirmed(Start),
    Confirmed(Start),
}

/// A start under way: when and where the train was last seen standing, and the latest fit.
#[derive(Debug, Clone)]
pub struct Departure {
    /// The last window judged a standstill.
    pub quiet_ns: u64,
    pub stood_odometer_m: f64,
    pub stood_chainage_m: Option<f64>,
    last: Option<Start>,
    ra: Vec<f64>,
    rb: Vec<f64>,
}

impl Departure {
    pub fn new(quiet_ns: u64, stood_odometer_m: f64, stood_chainage_m: Option<f64>) -> Self {
        Departure {
            quiet_ns,
            stood_odometer_m,
            stood_chainage_m,
            last: None,
            ra: Vec::new(),
            rb: Vec::new(),
        }
    }

    /// How long the start may have been going at `now_ns`, s.
    pub fn since_quiet_s(&self, now_ns: u64) -> f64 {
        now_ns.saturating_sub(self.quiet_ns) as f64 / 1e9 + QUIET_SPAN_S
    }

    /// The start's fit on the latest signal, sensors `spacing_m` apart, accelerating at
    /// most at `max_acceleration`; `min_rho` is the correlation a fit must reach. None when
    /// no level's window reaches back to the standstill any more: the start is over (or was
    /// missed) and the ordinary correlator takes over.
    pub fn fit(
        &mut self,
        fe: &FrontEnd,
        spacing_m: f64,
        max_acceleration: f64,
        min_rho: f64,
    ) -> Option<Fit> {
        let since_max = self.since_quiet_s(fe.now_ns());
        let level = (FIRST_LEVEL..LEVELS).find(|&l| fe.span_s(l) >= since_max)?;
        let rate = fe.rate(level);
        let (a, b, mid) = fe.window(level)?;
        let end_ns = mid + (0.5 * fe.span_s(level) * 1e9) as u64;
        let Some((since, travel, rho)) =
            self.search(&a, &b, rate, spacing_m, since_max, max_acceleration)
        else {
            return Some(Fit::Nothing { best_rho: 0.0 });
        };
        if rho < min_rho {
            return Some(Fit::Nothing { best_rho: rho });
        }
        let start = Start {
            onset_ns: end_ns.saturating_sub((since * 1e9) as u64),
            at_ns: end_ns,
            acceleration_mps2: 2.0 * travel / (since * since),
            speed_mps: 2.0 * travel / since,
            travelled_m: travel,
            rho,
            level,
        };
        let confirmed = self.last.is_some_and(|l| l.agrees(&start));
        self.last = Some(start);
        Some(match confirmed {
            true => Fit::Confirmed(start),
            false => Fit::Unconfirmed(start),
        })
    }

    /// The best (τ, x_e, ρ): a coarse grid, then a pattern search on the fine grid.
    fn search(
        &mut self,
        a: &[f64],
        b: &[f64],
        rate: f64,
        d: f64,
        since_max: f64,
        max_acceleration: f64,
    ) -> Option<(f64, f64, f64)> {
        let min_travel = d + MIN_OVERLAP_M;
        let allowed = |s: f64, x: f64| {
            (MIN_SINCE_S..=since_max).contains(&s)
                && x >= min_travel
                && 2.0 * x / (s * s) <= max_acceleration
        };
        let mut best: Option<(f64, f64, f64)> = None;
        let mut since = MIN_SINCE_S;
        while since <= since_max {
            let mut travel = min_travel;
            while allowed(since, travel) {
                if let Some(r) = self.rho(a, b, rate, d, since, travel, COARSE_STEPS) {
                    if best.is_none_or(|b| r > b.2) {
                        best = Some((since, travel, r));
                    }
                }
                travel *= TRAVEL_RATIO;
            }
            since += SINCE_STEP_S;
        }
        let (mut since, mut travel, _) = best?;
        let mut rho = self.rho(a, b, rate, d, since, travel, FINE_STEPS)?;
        // Pattern search: the four neighbours, the steps halved when none is better.
        let (mut ds, mut dx) = (SINCE_STEP_S, TRAVEL_RATIO - 1.0);
        while ds > 1e-3 {
            let mut moved = false;
            for (s, x) in [
                (since + ds, travel),
                (since - ds, travel),
                (since, travel * (1.0 + dx)),
                (since, travel / (1.0 + dx)),
            ] {
                if !allowed(s, x) {
                    continue;
                }
                if let Some(r) = self.rho(a, b, rate, d, s, x, FINE_STEPS) {
                    if r > rho {
                        (since, travel, rho, moved) = (s, x, r, true);
                    }
                }
            }
            if !moved {
                (ds, dx) = (ds / 2.0, dx / 2.0);
            }
        }
        Some((since, travel, rho))
    }

    /// The correlation at the shift `D` of both sensors resampled on the distance grid
    /// (`steps` per `D`) of a start `since` s before the window's last sample that has
    /// covered `travel` m by it.
    #[allow(clippy::too_many_arguments)]
    fn rho(
        &mut self,
        a: &[f64],
        b: &[f64],
        rate: f64,
        d: f64,
        since: f64,
        travel: f64,
        steps: usize,
    ) -> Option<f64> {
        let h = d / steps as f64;
        let n = (travel / h) as usize + 1;
        let last = (a.len() - 1) as f64;
        let span = since * rate;
        let onset = last - span;
        if onset < 0.0 || n < steps + 3 {
            return None;
        }
        let at = |x: &[f64], t: f64| {
            let j = (t as usize).min(x.len() - 2);
            let f = t - j as f64;
            x[j] + f * (x[j + 1] - x[j])
        };
        self.ra.clear();
        self.rb.clear();
        for j in 0..n {
            let t = onset + span * (j as f64 * h / travel).sqrt();
            self.ra.push(at(a, t));
            self.rb.push(at(b, t));
        }
        Some(pearson_at(&self.ra, &self.rb, steps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eddy_current::test_track::Track;

    #[test]
    fn a_start_from_standstill_is_fitted_once_the_trailing_sensor_passed_the_leading_ones_track() {
        // Standing 1 s, then 1.1 m/s² for 1.5 s, sensors 0.25 m apart, 625 Hz.
        let (fs, d, acc, stand) = (625.0, 0.25, 1.1, 1.0);
        let track = Track::new(3);
        let pos = |t: f64| 2.0 + 0.5 * acc * (t - stand).max(0.0).powi(2);
        let n = (2.5 * fs) as usize;
        let (a, b) = track.sensor_pair(pos, d, fs, n);
        let mut dep = Departure::new(0, 0.0, None);
        let since_true = (n - 1) as f64 / fs - stand;
        let (since, travel, rho) = dep.search(&a, &b, fs, d, 2.4, 2.5).unwrap();
        let (alpha, v) = (2.0 * travel / (since * since), 2.0 * travel / since);
        assert!(rho > 0.95, "ρ {rho}");
        assert!(
            (since - since_true).abs() < 0.05,
            "τ {since} against {since_true}"
        );
        assert!((alpha - acc).abs() < 0.05 * acc, "α {alpha}");
        assert!((v - acc * since_true).abs() < 0.03, "v {v}");
        // 0.9 s after the start the trailing sensor has covered 0.2 m: no fit believable.
        let n_early = ((stand + 0.9) * fs) as usize;
        let (a, b) = track.sensor_pair(pos, d, fs, n_early);
        let early = dep.search(&a, &b, fs, d, 1.8, 2.5);
        assert!(early.is_none_or(|(_, _, rho)| rho < 0.8), "{early:?}");
    }
}
