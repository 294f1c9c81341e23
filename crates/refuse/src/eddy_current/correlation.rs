//! Speed by cross-correlation of the two sensors (source 004 §3.2, §4.1): the trailing sensor
//! sees what the leading one saw `τ = D / v` earlier, so the lag that maximises their
//! correlation gives the speed.
//!
//! - Open loop: the normalised correlation at every lag (by FFT), its global maximum, refined
//!   to a fraction of a sample by a parabola through the peak and its neighbours (the
//!   quantisation of τ matters at speed: 75 samples at 33 m/s, 10 kHz, D = 0.25 m).
//! - Closed loop: tracks τ from the last estimate by driving the correlation's derivative to
//!   zero with Newton–Raphson steps (derivatives by central differences), three lags a step
//!   instead of all of them; it loses lock where the curvature stops being a maximum's.
//!
//! The normalisation is Pearson's over the overlapping part at each lag, so a lag with less
//! overlap is not favoured or penalised for its length.

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// A correlation maximum: the lag (samples, B behind A) and the correlation there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    pub lag: f64,
    pub rho: f64,
}

/// Pearson's correlation of `a[i]` with `b[i + lag]` over their overlap.
pub fn pearson_at(a: &[f64], b: &[f64], lag: usize) -> f64 {
    let n = a.len().min(b.len());
    if lag + 2 > n {
        return 0.0;
    }
    let (x, y) = (&a[..n - lag], &b[lag..n]);
    let m = x.len() as f64;
    let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&p, &q) in x.iter().zip(y) {
        sx += p;
        sy += q;
        sxx += p * p;
        syy += q * q;
        sxy += p * q;
    }
    let cov = sxy - sx * sy / m;
    let var = (sxx - sx * sx / m) * (syy - sy * sy / m);
    if var > 0.0 {
        cov / var.sqrt()
    } else {
        0.0
    }
}

/// The vertex of the parabola through `(−1, l)`, `(0, c)`, `(1, r)`: offset and value; none
/// where the three are no maximum.
pub fn parabolic(l: f64, c: f64, r: f64) -> Option<(f64, f64)> {
    let curvature = l - 2.0 * c + r;
    if curvature >= 0.0 {
        return None;
    }
    let offset = (0.5 * (l - r) / curvature).clamp(-0.5, 0.5);
    Some((offset, c - 0.25 * (l - r) * offset))
}

/// A transform size with its forward and inverse FFTs.
type Plans = (usize, Arc<dyn Fft<f64>>, Arc<dyn Fft<f64>>);

/// Normalised correlation at every lag, by FFT; the plans are kept for the next window.
pub struct Correlator {
    planner: FftPlanner<f64>,
    plans: Option<Plans>,
    fa: Vec<Complex<f64>>,
    fb: Vec<Complex<f64>>,
    r: Vec<f64>,
}

impl Default for Correlator {
    fn default() -> Self {
        Correlator {
            planner: FftPlanner::new(),
            plans: None,
            fa: Vec::new(),
            fb: Vec::new(),
            r: Vec::new(),
        }
    }
}

impl Correlator {
    /// `r[m]` for lags `0..=max_lag`: Pearson's correlation of `a[i]` with `b[i + m]`.
    pub fn correlate(&mut self, a: &[f64], b: &[f64], max_lag: usize) -> &[f64] {
        let n = a.len().min(b.len());
        let max_lag = max_lag.min(n.saturating_sub(2));
        let size = (2 * n).next_power_of_two();
        if self.plans.as_ref().is_none_or(|p| p.0 != size) {
            let fwd = self.planner.plan_fft_forward(size);
            let inv = self.planner.plan_fft_inverse(size);
            self.plans = Some((size, fwd, inv));
        }
        let (_, fwd, inv) = self.plans.clone().expect("planned");
        self.fa.clear();
        self.fa.extend(a[..n].iter().map(|&x| Complex::new(x, 0.0)));
        self.fa.resize(size, Complex::new(0.0, 0.0));
        self.fb.clear();
        self.fb.extend(b[..n].iter().map(|&x| Complex::new(x, 0.0)));
        self.fb.resize(size, Complex::new(0.0, 0.0));
        fwd.process(&mut self.fa);
        fwd.process(&mut self.fb);
        // Σ a[i] b[i + m] = IFFT(conj(A) · B)[m].
        for (x, y) in self.fa.iter_mut().zip(&self.fb) {
            *x = x.conj() * y;
        }
        inv.process(&mut self.fa);
        let scale = 1.0 / size as f64;
        // Sums and sums of squares over each lag's overlap, from running sums.
        let prefix = |v: &[f64]| -> (Vec<f64>, Vec<f64>) {
            let mut s = Vec::with_capacity(v.len() + 1);
            let mut q = Vec::with_capacity(v.len() + 1);
            let (mut a1, mut a2) = (0.0, 0.0);
            s.push(0.0);
            q.push(0.0);
            for &x in v {
                a1 += x;
                a2 += x * x;
                s.push(a1);
                q.push(a2);
            }
            (s, q)
        };
        let (sa, qa) = prefix(&a[..n]);
        let (sb, qb) = prefix(&b[..n]);
        self.r.clear();
        for m in 0..=max_lag {
            let len = (n - m) as f64;
            let sxy = self.fa[m].re * scale;
            let (sx, sxx) = (sa[n - m], qa[n - m]);
            let (sy, syy) = (sb[n] - sb[m], qb[n] - qb[m]);
            let var = (sxx - sx * sx / len) * (syy - sy * sy / len);
            self.r.push(if var > 0.0 {
                (sxy - sx * sy / len) / var.sqrt()
            } else {
                0.0
            });
        }
        &self.r
    }
}

/// The open-loop estimate: within `lags`, the first local maximum whose correlation is at
/// least `share` of the largest (1.0: the global maximum; below it, the earliest of several
/// near-equal peaks, which is the true one when the sensors are closer than half a sleeper
/// apart: the others are the sleeper grid's aliases, a whole sleeper later), refined by the
/// parabola through it.
pub fn open_loop(r: &[f64], lags: std::ops::Range<usize>, share: f64) -> Option<Peak> {
    let lo = lags.start.max(1);
    let hi = lags.end.min(r.len().saturating_sub(1));
    if lo >= hi {
        return None;
    }
    let is_max = |m: usize| r[m] >= r[m - 1] && r[m] >= r[m + 1];
    let best = (lo..hi)
        .filter(|&m| is_max(m))
        .map(|m| r[m])
        .fold(f64::NEG_INFINITY, f64::max);
    if best.is_nan() || best <= 0.0 {
        return None;
    }
    let m = (lo..hi).find(|&m| is_max(m) && r[m] >= share * best)?;
    let (offset, rho) = parabolic(r[m - 1], r[m], r[m + 1]).unwrap_or((0.0, r[m]));
    Some(Peak {
        lag: m as f64 + offset,
        rho,
    })
}

/// The closed loop: from `lag`, Newton–Raphson steps on the correlation's derivative
/// (`τ ← τ − R′/R″` at the nearest whole lag, each step the parabola's vertex) until the step
/// stays within half a sample; none where the correlation has no maximum nearby or the lag
/// leaves `lags`.
pub fn closed_loop(a: &[f64], b: &[f64], lag: f64, lags: std::ops::Range<usize>) -> Option<Peak> {
    let mut m = lag.round() as i64;
    for _ in 0..8 {
        if m < lags.start.max(1) as i64 || m + 1 >= lags.end as i64 {
            return None;
        }
        let mu = m as usize;
        let (l, c, r) = (
            pearson_at(a, b, mu - 1),
            pearson_at(a, b, mu),
            pearson_at(a, b, mu + 1),
        );
        let derivative = 0.5 * (r - l);
        let curvature = l - 2.0 * c + r;
        if curvature >= 0.0 {
            return None;
        }
        let step = -derivative / curvature;
        if step.abs() <= 0.5 {
            return Some(Peak {
                lag: m as f64 + step,
                rho: c - 0.5 * derivative * step,
            });
        }
        m += step.round().clamp(-4.0, 4.0) as i64;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A band-limited random signal and a copy delayed by `delay` samples (fractional, by
    /// linear interpolation of a smooth signal), each with its own white noise.
    pub(crate) fn delayed_pair(
        n: usize,
        delay: f64,
        noise: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        use rand_distr::{Distribution, StandardNormal};
        let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
        let total = n + delay.ceil() as usize + 64;
        // White noise smoothed by three passes of a 9-tap average: content well below Nyquist.
        let mut x: Vec<f64> = (0..total).map(|_| g()).collect();
        for _ in 0..3 {
            x = (0..total)
                .map(|i| {
                    x[i.saturating_sub(4)..(i + 5).min(total)]
                        .iter()
                        .sum::<f64>()
                        / 9.0
                })
                .collect();
        }
        let at = |t: f64| {
            let i = t.floor() as usize;
            let f = t - i as f64;
            x[i] * (1.0 - f) + x[i + 1] * f
        };
        let start = delay.ceil() + 8.0;
        let a: Vec<f64> = (0..n).map(|i| at(start + i as f64) + noise * g()).collect();
        let b: Vec<f64> = (0..n)
            .map(|i| at(start + i as f64 - delay) + noise * g())
            .collect();
        (a, b)
    }

    #[test]
    fn the_open_loop_recovers_a_known_delay_to_a_fraction_of_a_sample() {
        let mut c = Correlator::default();
        for (k, &delay) in [12.3, 40.0, 75.62, 180.25].iter().enumerate() {
            let (a, b) = delayed_pair(1024, delay, 0.02, k as u64);
            let r = c.correlate(&a, &b, 400).to_vec();
            let p = open_loop(&r, 1..400, 1.0).unwrap();
            assert!((p.lag - delay).abs() < 0.1, "{delay}: {p:?}");
            assert!(p.rho > 0.9, "{p:?}");
            // The FFT's correlation equals the direct sum at the peak.
            let m = p.lag.round() as usize;
            assert!((r[m] - pearson_at(&a, &b, m)).abs() < 1e-9);
        }
    }

    #[test]
    fn the_closed_loop_tracks_the_delay_from_a_nearby_start_and_says_when_it_cannot() {
        let (a, b) = delayed_pair(1024, 75.62, 0.02, 9);
        let p = closed_loop(&a, &b, 73.0, 1..400).unwrap();
        assert!((p.lag - 75.62).abs() < 0.1, "{p:?}");
        // A start at the edge of the lags allowed, or a peak outside them: no lock.
        assert!(closed_loop(&a, &b, 399.0, 1..400).is_none());
        assert!(closed_loop(&a, &b, 73.0, 1..60).is_none());
    }

    #[test]
    fn the_earliest_near_peak_is_chosen_over_a_later_alias() {
        // Two peaks: the true one at 20 (0.9) and an alias at 70 (0.95).
        let r: Vec<f64> = (0..100)
            .map(|m| {
                let m = m as f64;
                0.9 * (-(m - 20.0).powi(2) / 8.0).exp() + 0.95 * (-(m - 70.0).powi(2) / 8.0).exp()
            })
            .collect();
        assert!((open_loop(&r, 1..99, 1.0).unwrap().lag - 70.0).abs() < 0.1);
        assert!((open_loop(&r, 1..99, 0.8).unwrap().lag - 20.0).abs() < 0.1);
    }
}
