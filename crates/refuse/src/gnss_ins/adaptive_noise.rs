//! The adaptive Kalman filter (AKF), source 003's other baseline: the measurement noise `R`
//! adapted from the innovations (Mohamed and Schwarz's innovation-based estimate):
//!
//! ```text
//! Ĉ_ν = (1/W) Σ νᵢ νᵢᵀ                  over the last W innovations of one measurement pair
//! R̂  = Ĉ_ν − (1/W) Σ Hᵢ P⁻ᵢ Hᵢᵀ         (what the innovations show beyond the filter's spread)
//! ```
//!
//! A receiver's `R` changes by two orders of magnitude from one fix to the next (RTK fixed
//! to single point), faster than any window of innovations can follow: an `R̂` learnt over
//! RTK fixes takes the first single-point fix for centimetres (tried: the filter then ran
//! tens of metres off through every correction outage). So what is estimated is the scale
//! of the receiver's own `R`, `α = tr R̂ / tr R̄` (`R̄` the mean reported `R` over the same
//! window), applied to each fix's reported `R`: the AKF corrects a receiver that
//! understates or overstates its noise and still follows its fix types. `α` is kept within
//! `[min_scale, max_scale]`; until `W` innovations have been seen it is 1.

use std::collections::VecDeque;

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// `[pipeline.gnss_ins.adaptive]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveNoiseSettings {
    /// Innovations averaged: 50 (5 s of 10 Hz fixes) gives the scale a spread of about 20 %,
    /// and still follows the receiver into a street of buildings within seconds.
    pub window: usize,
    /// The range the scale may take: a receiver a hundred times too pessimistic or too
    /// optimistic is broken, not mis-tuned.
    pub min_scale: f64,
    pub max_scale: f64,
}

impl Default for AdaptiveNoiseSettings {
    fn default() -> Self {
        Self {
            window: 50,
            min_scale: 0.01,
            max_scale: 100.0,
        }
    }
}

/// One innovation: `ν`, the filter's `H P⁻ Hᵀ` and the reported `R`.
type Sample = (SVector<f64, 2>, SMatrix<f64, 2, 2>, SMatrix<f64, 2, 2>);

/// The running estimate for one measurement pair.
#[derive(Debug, Clone)]
pub struct AdaptiveNoise {
    settings: AdaptiveNoiseSettings,
    recent: VecDeque<Sample>,
    /// Σ (ννᵀ − H P Hᵀ) traces and Σ tr R over the window.
    excess: f64,
    reported: f64,
}

impl AdaptiveNoise {
    pub fn new(settings: AdaptiveNoiseSettings) -> Self {
        Self {
            settings,
            recent: VecDeque::with_capacity(settings.window + 1),
            excess: 0.0,
            reported: 0.0,
        }
    }

    /// The current scale `α` of the reported `R`.
    pub fn scale(&self) -> f64 {
        let s = &self.settings;
        if self.recent.len() < s.window.max(1) || !(self.reported > 0.0) {
            return 1.0;
        }
        (self.excess / self.reported).clamp(s.min_scale, s.max_scale)
    }

    /// `R` for the next measurement: the reported one, scaled.
    pub fn noise(&self, reported: SMatrix<f64, 2, 2>) -> SMatrix<f64, 2, 2> {
        reported * self.scale()
    }

    /// One innovation `ν` (before the update) with the filter's projection `H P⁻ Hᵀ` and the
    /// `R` the receiver reported for it.
    pub fn push(
        &mut self,
        innovation: SVector<f64, 2>,
        projected: SMatrix<f64, 2, 2>,
        reported: SMatrix<f64, 2, 2>,
    ) {
        let all = innovation
            .iter()
            .chain(projected.iter())
            .chain(reported.iter());
        if !all.clone().all(|x| x.is_finite()) {
            return;
        }
        self.excess += innovation.norm_squared() - projected.trace();
        self.reported += reported.trace();
        self.recent.push_back((innovation, projected, reported));
        if self.recent.len() > self.settings.window {
            let (v, p, r) = self.recent.pop_front().expect("over full");
            self.excess -= v.norm_squared() - p.trace();
            self.reported -= r.trace();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn recovers_the_scale_of_a_receiver_that_understates_its_noise() {
        // Innovations of a filter with H P Hᵀ = 0.25 I and a true R of 4 I while the
        // receiver says 1 I: the scale comes out near 4.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let total = Normal::new(0.0, (4.0f64 + 0.25).sqrt()).unwrap();
        let mut a = AdaptiveNoise::new(AdaptiveNoiseSettings {
            window: 400,
            ..Default::default()
        });
        let reported = SMatrix::<f64, 2, 2>::identity();
        assert_eq!(a.noise(reported), reported);
        for _ in 0..2000 {
            let v = SVector::<f64, 2>::new(total.sample(&mut rng), total.sample(&mut rng));
            a.push(v, SMatrix::identity() * 0.25, reported);
        }
        assert!((a.scale() - 4.0).abs() < 0.6, "{}", a.scale());
        // It follows the receiver's own changes: a fix reported at 100 I gets about 400 I.
        let r = a.noise(reported * 100.0);
        assert!((r[(0, 0)] / 100.0 - a.scale()).abs() < 1e-12);
    }

    #[test]
    fn the_scale_stays_in_its_range_and_ignores_non_finite_samples() {
        let mut a = AdaptiveNoise::new(AdaptiveNoiseSettings {
            window: 5,
            min_scale: 0.1,
            max_scale: 10.0,
        });
        for _ in 0..10 {
            a.push(SVector::zeros(), SMatrix::identity(), SMatrix::identity());
        }
        assert_eq!(a.scale(), 0.1);
        a.push(
            SVector::<f64, 2>::new(f64::NAN, 0.0),
            SMatrix::identity(),
            SMatrix::identity(),
        );
        assert_eq!(a.scale(), 0.1);
    }
}
