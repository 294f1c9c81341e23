//! The adaptive Kalman filter (AKF), source 003's other baseline: the measurement noise `R`
//! estimated from the innovations instead of taken from the receiver (Mohamed and Schwarz's
//! innovation-based estimate):
//!
//! ```text
//! Ĉ_ν = (1/W) Σ νᵢ νᵢᵀ            over the last W innovations of one measurement pair
//! R̂  = Ĉ_ν − (1/W) Σ Hᵢ P⁻ᵢ Hᵢᵀ   (what the innovations show beyond the filter's own spread)
//! ```
//!
//! `R̂` is symmetrised and its eigenvalues kept at least `min_std²`: with few samples the
//! difference can go negative, and a zero `R` would make the filter take a fix as truth.
//! Until `W` innovations have been seen the receiver's own `R` is used.

use std::collections::VecDeque;

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// `[pipeline.gnss_ins.adaptive]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveNoiseSettings {
    /// Innovations averaged: 50 (5 s of 10 Hz fixes) gives R̂ a spread of about 20 %, and still
    /// follows the receiver into a street of buildings within seconds.
    pub window: usize,
    /// Floor of R̂'s standard deviation per axis (m for positions, m/s for velocities): an RTK
    /// fixed fix is good to about a centimetre, no better.
    pub min_std: f64,
}

impl Default for AdaptiveNoiseSettings {
    fn default() -> Self {
        Self {
            window: 50,
            min_std: 0.01,
        }
    }
}

/// The running estimate for one measurement pair.
#[derive(Debug, Clone)]
pub struct AdaptiveNoise {
    settings: AdaptiveNoiseSettings,
    recent: VecDeque<(SVector<f64, 2>, SMatrix<f64, 2, 2>)>,
    sum_outer: SMatrix<f64, 2, 2>,
    sum_projected: SMatrix<f64, 2, 2>,
}

impl AdaptiveNoise {
    pub fn new(settings: AdaptiveNoiseSettings) -> Self {
        Self {
            settings,
            recent: VecDeque::with_capacity(settings.window + 1),
            sum_outer: SMatrix::zeros(),
            sum_projected: SMatrix::zeros(),
        }
    }

    /// `R` for the next measurement: R̂ once the window is full, else `reported`.
    pub fn noise(&self, reported: SMatrix<f64, 2, 2>) -> SMatrix<f64, 2, 2> {
        let w = self.recent.len();
        if w < self.settings.window.max(1) {
            return reported;
        }
        let r = (self.sum_outer - self.sum_projected) / w as f64;
        let r = (r + r.transpose()) * 0.5;
        let eig = r.symmetric_eigen();
        let floor = self.settings.min_std * self.settings.min_std;
        let values = eig.eigenvalues.map(|l| l.max(floor));
        let q = eig.eigenvectors;
        q * SMatrix::from_diagonal(&values) * q.transpose()
    }

    /// One innovation `ν` (before the update) with the filter's projection `H P⁻ Hᵀ`.
    pub fn push(&mut self, innovation: SVector<f64, 2>, projected: SMatrix<f64, 2, 2>) {
        if !(innovation
            .iter()
            .chain(projected.iter())
            .all(|x| x.is_finite()))
        {
            return;
        }
        let outer = innovation * innovation.transpose();
        self.sum_outer += outer;
        self.sum_projected += projected;
        self.recent.push_back((innovation, projected));
        if self.recent.len() > self.settings.window {
            let (v, p) = self.recent.pop_front().expect("over full");
            self.sum_outer -= v * v.transpose();
            self.sum_projected -= p;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn recovers_the_noise_the_receiver_understates() {
        // Innovations of a filter with H P Hᵀ = 0.25 I and a true R of 4 I (the receiver says
        // 1 I): R̂ comes out near 4.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let total = Normal::new(0.0, (4.0f64 + 0.25).sqrt()).unwrap();
        let mut a = AdaptiveNoise::new(AdaptiveNoiseSettings {
            window: 400,
            min_std: 0.01,
        });
        let reported = SMatrix::<f64, 2, 2>::identity();
        assert_eq!(a.noise(reported), reported);
        for _ in 0..2000 {
            let v = SVector::<f64, 2>::new(total.sample(&mut rng), total.sample(&mut rng));
            a.push(v, SMatrix::identity() * 0.25);
        }
        let r = a.noise(reported);
        for i in 0..2 {
            assert!((r[(i, i)] - 4.0).abs() < 0.6, "{r}");
        }
        assert!(r[(0, 1)].abs() < 0.5);
    }

    #[test]
    fn never_below_its_floor() {
        let mut a = AdaptiveNoise::new(AdaptiveNoiseSettings {
            window: 5,
            min_std: 0.1,
        });
        for _ in 0..10 {
            a.push(SVector::zeros(), SMatrix::identity());
        }
        let r = a.noise(SMatrix::identity());
        assert!((r[(0, 0)] - 0.01).abs() < 1e-12 && (r[(1, 1)] - 0.01).abs() < 1e-12);
        a.push(SVector::<f64, 2>::new(f64::NAN, 0.0), SMatrix::identity());
        assert!(a.noise(SMatrix::identity()).iter().all(|x| x.is_finite()));
    }
}
