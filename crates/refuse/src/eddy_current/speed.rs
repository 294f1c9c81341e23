//! One speed measurement from the latest signal: the pyramid level that puts the delay near
//! 64 samples, the open- or closed-loop correlator on its window, then (if asked) the warp
//! search; or a standstill, when the signal is as quiet as its noise floor.

use serde::{Deserialize, Serialize};

use super::correlation::{closed_loop, open_loop, Correlator, Peak};
use super::front_end::{FrontEnd, LEVELS, WINDOW};
use super::warping::WarpSearch;

/// Which correlator finds the delay.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CorrelatorKind {
    /// The global maximum over every lag, each window afresh.
    OpenLoop,
    /// Newton–Raphson from the last delay; the open loop when it loses lock.
    ClosedLoop,
}

/// A standstill is believed from below this speed only, m/s: the quiet span (1.5 s) holds
/// a sleeper above 0.4 m/s.
const STANDSTILL_FROM_MPS: f64 = 0.5;
/// The delay a window is chosen to hold, samples.
const TARGET_LAG: f64 = 64.0;
/// Lags searched without a speed to go by.
const ACQUIRE_LAGS: std::ops::Range<usize> = 8..(WINDOW / 2);
/// Track a window must span at acquisition, m (three to four sleepers).
const MIN_WINDOW_TRAVEL_M: f64 = 2.0;
/// Levels agree on a delay within this share of it.
const ACQUIRE_AGREEMENT: f64 = 0.05;
/// The share by which the speed may change across a tracked window.
const MAX_SPEED_CHANGE: f64 = 0.5;
/// A tracked peak this good is warped even below `min_rho`: under hard acceleration at low
/// speed the unwarped peak smears (the delay changes twofold across the window), and it is
/// the warped correlation that must reach `min_rho`.
const WARP_FROM_RHO: f64 = 0.2;

/// A level's peak: level, peak, the window's signals and middle, whether acquired afresh.
type Found = (usize, Peak, Vec<f64>, Vec<f64>, u64, bool);

/// The standard deviation (samples) of a correlation peak's lag: a twentieth of a sample at a
/// perfect match, growing as the correlation ρ falls.
fn lag_std(rho: f64) -> f64 {
    0.05 + 2.0 * (1.0 - rho).max(0.0)
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedMeasurement {
    pub stamp_ns: u64,
    pub speed_mps: f64,
    pub speed_variance: f64,
    /// From the warp: acceleration and its variance.
    pub acceleration: Option<(f64, f64)>,
    pub rho: f64,
    /// The warp factor and the correlation without warping.
    pub warp_k: Option<f64>,
    pub unwarped_rho: Option<f64>,
    pub level: usize,
    /// The delay, samples of the level.
    pub lag: f64,
    /// Whether the open loop had to (re)acquire.
    pub acquired: bool,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    Moving(SpeedMeasurement),
    /// As quiet as the noise floor: nothing passes under the sensors.
    Standstill {
        stamp_ns: u64,
    },
    /// Moving (or not sure) but no correlation peak good enough.
    NoLock {
        stamp_ns: u64,
        best_rho: f64,
    },
}

#[derive(Default)]
pub struct SpeedEstimator {
    correlator: Correlator,
    warp: WarpSearch,
    /// The last lock: level and delay.
    lock: Option<(usize, f64)>,
}

/// What the estimator needs to know besides the signal.
#[derive(Debug, Clone, Copy)]
pub struct Request {
    pub spacing_m: f64,
    /// The speed expected now (the filter's prediction, or the last measurement).
    pub prior_mps: Option<f64>,
    /// The acceleration expected now: a window's delay is its middle's, half a window ago.
    pub prior_acceleration_mps2: f64,
    pub correlator: CorrelatorKind,
    pub warp: bool,
    pub max_acceleration_mps2: f64,
    pub min_rho: f64,
    /// Activity below this many times the noise floor is a standstill.
    pub standstill_factor: f64,
}

impl SpeedEstimator {
    pub fn forget(&mut self) {
        self.lock = None;
    }

    /// The level whose window holds a delay of about 64 samples at `speed`.
    pub fn level_for(fe: &FrontEnd, spacing_m: f64, speed: f64) -> usize {
        let lag0 = spacing_m * fe.fs_hz / speed.max(1e-3);
        (lag0 / TARGET_LAG)
            .log2()
            .round()
            .clamp(0.0, (LEVELS - 1) as f64) as usize
    }

    /// The level for `speed` under `acceleration`: [`level_for`](Self::level_for), or up to
    /// two levels finer (a delay of up to 256 samples) so that the speed changes by at most
    /// half across the window: under hard braking at walking pace a window of several seconds
    /// spans a threefold change of speed that no warp straightens.
    pub fn level_for_motion(fe: &FrontEnd, spacing_m: f64, speed: f64, acceleration: f64) -> usize {
        let l = Self::level_for(fe, spacing_m, speed);
        let longest = MAX_SPEED_CHANGE * speed / acceleration.abs().max(1e-9);
        (l.saturating_sub(2)..=l)
            .rev()
            .find(|&k| fe.span_s(k) <= longest)
            .unwrap_or(l.saturating_sub(2))
    }

    /// Whether the signal is as quiet as its noise floor, and the train not coming from a
    /// speed it cannot lose within the quiet span: a standstill.
    pub fn quiet(fe: &FrontEnd, q: &Request) -> bool {
        fe.noise_floor
            .is_some_and(|f| fe.activity() < q.standstill_factor * f.max(1e-12))
            && q.prior_mps.is_none_or(|v| v < STANDSTILL_FROM_MPS)
    }

    pub fn measure(&mut self, fe: &FrontEnd, q: &Request) -> Outcome {
        let now = fe.now_ns();
        let quiet = Self::quiet(fe, q);
        // Tracking: the level the expected speed asks for, lags about it; when that finds
        // nothing, acquisition over every level.
        let tracked = q.prior_mps.filter(|v| *v > 0.05).and_then(|v| {
            let l = Self::level_for_motion(fe, q.spacing_m, v, q.prior_acceleration_mps2);
            // The speed at the window's middle: under hard braking at low speed it is
            // several times the speed now.
            let half = 0.5 * fe.span_s(l);
            let v_mid = (v - q.prior_acceleration_mps2 * half).max(0.5 * v);
            self.at_level(fe, q, l, Some(v_mid))
        });
        let mut best_rho = tracked.as_ref().map_or(0.0, |t| t.1.rho);
        let found = tracked.or_else(|| self.acquire(fe, q, &mut best_rho));
        let Some((level, peak, a, b, mid, acquired)) = found else {
            self.lock = None;
            return match quiet {
                true => Outcome::Standstill { stamp_ns: now },
                false => Outcome::NoLock {
                    stamp_ns: now,
                    best_rho,
                },
            };
        };
        let rate = fe.rate(level);
        let span_s = fe.span_s(level);
        let mut m = SpeedMeasurement {
            stamp_ns: mid,
            speed_mps: q.spacing_m * rate / peak.lag,
            speed_variance: 0.0,
            acceleration: None,
            rho: peak.rho,
            warp_k: None,
            unwarped_rho: None,
            level,
            lag: peak.lag,
            acquired,
        };
        m.speed_variance = (m.speed_mps * lag_std(peak.rho) / peak.lag).powi(2);
        if q.warp {
            self.refine_by_warp(q, rate, span_s, (&a, &b), &mut m);
        }
        if m.rho < q.min_rho {
            self.lock = None;
            return Outcome::NoLock {
                stamp_ns: now,
                best_rho: m.rho,
            };
        }
        self.lock = Some((level, m.lag));
        Outcome::Moving(m)
    }

    /// Acquisition when tracking finds nothing: every level's peak (the best correlation
    /// seen goes to `best_rho`).
    /// Every level's peak; the delay is real where levels of different window lengths
    /// agree on it (a chance peak of one short window is not confirmed by the longer
    /// ones), and its window spans enough track. The finest such level is taken.
    fn acquire(&mut self, fe: &FrontEnd, q: &Request, best_rho: &mut f64) -> Option<Found> {
        let peaks: Vec<_> = (0..LEVELS)
            .filter_map(|l| self.at_level(fe, q, l, None))
            .collect();
        let delay = |f: &Found| f.1.lag / fe.rate(f.0);
        for f in &peaks {
            *best_rho = best_rho.max(f.1.rho);
        }
        peaks
            .iter()
            .position(|f| {
                let travel = q.spacing_m / delay(f) * WINDOW as f64 / fe.rate(f.0);
                let agree = peaks
                    .iter()
                    .filter(|g| (delay(g) / delay(f) - 1.0).abs() < ACQUIRE_AGREEMENT)
                    .count();
                travel >= MIN_WINDOW_TRAVEL_M && agree >= 2
            })
            .map(|i| peaks[i].clone())
    }

    /// Source 004's warping: the window's second signal stretched by the factor k that best
    /// matches the first, which gives the speed at the window's middle and the acceleration
    /// over it, with variances that grow as the correlation falls.
    fn refine_by_warp(
        &mut self,
        q: &Request,
        rate: f64,
        span_s: f64,
        (a, b): (&[f64], &[f64]),
        m: &mut SpeedMeasurement,
    ) {
        let k_max = q.max_acceleration_mps2 * span_s / (2.0 * m.speed_mps);
        if let Some(w) = self.warp.search(a, b, m.lag, k_max) {
            let v = q.spacing_m * rate / w.peak.lag;
            let acc = 2.0 * w.k * v / span_s;
            // The warp factor's uncertainty grows as the correlation falls.
            let k_std = 0.01 + 0.5 * (1.0 - w.peak.rho).max(0.0);
            m.speed_mps = v;
            m.speed_variance = (v * lag_std(w.peak.rho) / w.peak.lag).powi(2);
            m.acceleration = Some((acc, (2.0 * k_std * v / span_s).powi(2)));
            m.rho = w.peak.rho;
            m.lag = w.peak.lag;
            m.warp_k = Some(w.k);
            m.unwarped_rho = Some(w.unwarped_rho);
        }
    }

    /// The correlation peak at level `l` (about `prior`'s delay, or over every lag), if one
    /// reaches `min_rho`: level, peak, the window's signals and middle, and whether it was
    /// acquired afresh.
    fn at_level(
        &mut self,
        fe: &FrontEnd,
        q: &Request,
        l: usize,
        prior: Option<f64>,
    ) -> Option<Found> {
        let (a, b, mid) = fe.window(l)?;
        let rate = fe.rate(l);
        let (lags, share) = match prior {
            Some(v) => {
                let expect = q.spacing_m * rate / v;
                let lo = (0.6 * expect).floor().max(2.0) as usize;
                let hi = ((1.6 * expect).ceil() as usize).min(WINDOW / 2);
                (lo..hi, 1.0)
            }
            None => (ACQUIRE_LAGS, 0.85),
        };
        if lags.start + 2 >= lags.end {
            return None;
        }
        // Acquired afresh: found over every lag, not about the expected delay.
        let mut acquired = prior.is_none();
        let mut peak = None;
        if q.correlator == CorrelatorKind::ClosedLoop {
            if let (Some((ll, lag)), Some(v)) = (self.lock, prior) {
                // The last delay, carried to this level and speed.
                let guess = if ll == l { lag } else { q.spacing_m * rate / v };
                peak = closed_loop(&a, &b, guess, lags.clone());
                acquired = peak.is_none();
            }
        }
        if peak.is_none() {
            let r = self.correlator.correlate(&a, &b, lags.end);
            peak = open_loop(r, lags, share);
        }
        let floor = match q.warp && prior.is_some() {
            true => WARP_FROM_RHO.min(q.min_rho),
            false => q.min_rho,
        };
        let p = peak.filter(|p| p.rho >= floor)?;
        Some((l, p, a, b, mid, acquired))
    }
}
