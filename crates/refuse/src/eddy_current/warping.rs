//! Constant-acceleration resampling ("warping", source 004 §4.1). Plain correlation assumes
//! the speed constant over its window; under hard acceleration at low speed the delay between
//! the sensors changes across the window and the peak smears. Assume constant acceleration
//! instead: over a window of `T` with mean speed `v̄` and acceleration `a`, the distance
//! covered by normalised time `u ∈ [0, 1]`, as a share of the window's, is
//!
//! ```text
//! d(u) = (1 − k) u + k u²,   k = a T / (2 v̄) ∈ (−1, 1)
//! ```
//!
//! (`k` is the relative change of speed across the window: `v(0) = v̄ (1 − k)`,
//! `v(T) = v̄ (1 + k)`; `|k| < 1` while the train keeps moving). Resampling both signals at
//! the times that make `d` grow evenly puts them on an even distance grid, where the trailing
//! sensor's signal is the leading one's shifted by a constant `D`. The warp factor `k` is
//! the one that maximises the correlation of the resampled signals; the peak's lag `L`
//! (resampled samples) then gives
//!
//! ```text
//! v̄ = D f_s / L,   â = 2 k v̄ / T
//! ```
//!
//! at the window's middle (for constant acceleration, the mean speed is the speed at
//! mid-window). The search: a grid of `k` over the plausible range, then golden-section
//! steps around the best point of the grid.

use super::correlation::{parabolic, pearson_at, Peak};

/// Normalised time at which the share `d` of the window's distance is covered under warp
/// `k`: the root in [0, 1] of `k u² + (1 − k) u − d = 0`.
pub fn time_of(d: f64, k: f64) -> f64 {
    if k.abs() < 1e-9 {
        return d;
    }
    let b = 1.0 - k;
    // The cancellation-free form of (−b + √(b² + 4kd)) / 2k.
    2.0 * d / (b + (b * b + 4.0 * k * d).sqrt())
}

/// `x` resampled at the times that cover even shares of the window's distance under `k`
/// (linear interpolation between samples).
pub fn resample(x: &[f64], k: f64, out: &mut Vec<f64>) {
    out.clear();
    let n = x.len();
    if n < 2 {
        out.extend_from_slice(x);
        return;
    }
    let last = (n - 1) as f64;
    out.extend((0..n).map(|i| {
        let t = time_of(i as f64 / last, k) * last;
        let j = (t.floor() as usize).min(n - 2);
        let f = t - j as f64;
        x[j] + f * (x[j + 1] - x[j])
    }));
}

/// The best warp of one window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Warp {
    pub k: f64,
    /// The correlation peak of the resampled signals.
    pub peak: Peak,
    /// The correlation peak without warping (k = 0), for comparison.
    pub unwarped_rho: f64,
}

/// Scratch space for the search.
#[derive(Default)]
pub struct WarpSearch {
    ra: Vec<f64>,
    rb: Vec<f64>,
}

impl WarpSearch {
    /// The correlation peak under warp `k`, looked for within `radius` lags of `lag`.
    fn peak(&mut self, a: &[f64], b: &[f64], k: f64, lag: f64, radius: usize) -> Option<Peak> {
        resample(a, k, &mut self.ra);
        resample(b, k, &mut self.rb);
        let centre = lag.round() as usize;
        let lo = centre.saturating_sub(radius).max(1);
        let hi = (centre + radius).min(a.len().saturating_sub(3));
        if lo >= hi {
            return None;
        }
        let r: Vec<f64> = (lo - 1..=hi + 1)
            .map(|m| pearson_at(&self.ra, &self.rb, m))
            .collect();
        let (i, _) = r[1..r.len() - 1]
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))?;
        let i = i + 1;
        let (offset, rho) = parabolic(r[i - 1], r[i], r[i + 1]).unwrap_or((0.0, r[i]));
        Some(Peak {
            lag: (lo - 1 + i) as f64 + offset,
            rho,
        })
    }

    /// The warp in `[−k_max, k_max]` that maximises the correlation, starting from the
    /// unwarped peak's lag `lag`.
    pub fn search(&mut self, a: &[f64], b: &[f64], lag: f64, k_max: f64) -> Option<Warp> {
        let k_max = k_max.clamp(0.0, 0.95);
        // Under warp the peak moves by up to about k·L: look that far around it.
        let radius = (k_max * lag).ceil() as usize + 3;
        let unwarped = self.peak(a, b, 0.0, lag, radius)?;
        let mut best = (0.0, unwarped);
        // Below this the speed changes by less than 1 % across the window: the delay moves by
        // less than the lag's own resolution, and warping cannot be told from noise.
        if k_max < 0.005 {
            return Some(Warp {
                k: 0.0,
                peak: unwarped,
                unwarped_rho: unwarped.rho,
            });
        }
        const GRID: i32 = 4;
        let step = k_max / GRID as f64;
        for i in -GRID..=GRID {
            let k = i as f64 * step;
            if i == 0 {
                continue;
            }
            if let Some(p) = self.peak(a, b, k, lag, radius) {
                if p.rho > best.1.rho {
                    best = (k, p);
                }
            }
        }
        // Golden-section refinement within one grid step either side.
        let phi = 0.618_033_988_749_895;
        let (mut lo, mut hi) = ((best.0 - step).max(-k_max), (best.0 + step).min(k_max));
        let eval = |s: &mut Self, k: f64| s.peak(a, b, k, lag, radius).map_or(-1.0, |p| p.rho);
        let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
        let (mut f1, mut f2) = (eval(self, x1), eval(self, x2));
        for _ in 0..10 {
            if f1 > f2 {
                hi = x2;
                (x2, f2) = (x1, f1);
                x1 = hi - phi * (hi - lo);
                f1 = eval(self, x1);
            } else {
                lo = x1;
                (x1, f1) = (x2, f2);
                x2 = lo + phi * (hi - lo);
                f2 = eval(self, x2);
            }
        }
        let k = 0.5 * (lo + hi);
        if let Some(p) = self.peak(a, b, k, lag, radius) {
            if p.rho > best.1.rho {
                best = (k, p);
            }
        }
        Some(Warp {
            k: best.0,
            peak: best.1,
            unwarped_rho: unwarped.rho,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eddy_current::correlation::{open_loop, Correlator};
    use crate::eddy_current::test_track::Track;

    /// Two sensors `d` apart moving with constant acceleration from `v0`: `n` samples at `fs`.
    fn accelerating_pair(v0: f64, a: f64, d: f64, fs: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
        let x0 = 1.0 + d;
        Track::new(5).sensor_pair(|t| x0 + v0 * t + 0.5 * a * t * t, d, fs, n)
    }

    #[test]
    fn warping_recovers_a_known_constant_acceleration_where_plain_correlation_smears() {
        // From 0.5 m/s at 1.0 m/s² over a 1.5 s window: the speed triples across it.
        let (fs, n, d, v0, acc) = (400.0, 600, 0.25, 0.5, 1.0);
        let (a, b) = accelerating_pair(v0, acc, d, fs, n);
        let t = (n - 1) as f64 / fs;
        let v_mid = v0 + acc * t / 2.0;
        let r = Correlator::default().correlate(&a, &b, 300).to_vec();
        let plain = open_loop(&r, 1..300, 1.0).unwrap();
        let mut s = WarpSearch::default();
        let w = s.search(&a, &b, plain.lag, 0.9).unwrap();
        let v = d * fs / w.peak.lag;
        let a_hat = 2.0 * w.k * v / t;
        assert!((v - v_mid).abs() / v_mid < 0.01, "v {v} against {v_mid}");
        assert!((a_hat - acc).abs() < 0.05, "a {a_hat} against {acc}");
        assert!(
            w.peak.rho > 0.98 && w.peak.rho > w.unwarped_rho + 0.1,
            "{w:?}"
        );
        let v_plain = d * fs / plain.lag;
        assert!(
            (v_plain - v_mid).abs() > 3.0 * (v - v_mid).abs(),
            "{v_plain} {v}"
        );
        // Braking the same way: the warp factor turns negative.
        let (a2, b2) = accelerating_pair(v0 + acc * t, -acc, d, fs, n);
        let w2 = s.search(&a2, &b2, plain.lag, 0.9).unwrap();
        assert!(
            (2.0 * w2.k * (d * fs / w2.peak.lag) / t + acc).abs() < 0.05,
            "{w2:?}"
        );
    }

    #[test]
    fn time_of_inverts_the_distance_share() {
        for k in [-0.9, -0.3, 0.0, 0.4, 0.95] {
            for d in [0.0, 0.1, 0.5, 0.99, 1.0] {
                let u = time_of(d, k);
                assert!(((1.0 - k) * u + k * u * u - d).abs() < 1e-12, "{k} {d}");
                assert!((0.0..=1.0 + 1e-12).contains(&u));
            }
        }
    }
}
