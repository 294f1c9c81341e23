//! IMU error learning (source 003, eq. 13): while GNSS is good, learn how the inertial
//! solution goes wrong, `ε = A δ + B σ + C ψ(m; j)`, and during a GNSS loss keep correcting
//! it with what was learnt.
//!
//! The three terms, and where each lives here:
//! - `δ`, the biases: the error-state filter's bias states, which the navigation keeps
//!   subtracting through an outage (`A = 1`);
//! - `σ`, the random walk: the spread of the corrections GNSS had to make, learnt below and
//!   reported; the filter's own process noise already grows the covariance through an outage;
//! - `ψ(m; j)`, the mean residual over the learning period `m … j`: what the filter kept
//!   correcting that its bias states did not absorb (a gradient the level-track model does not
//!   know pulls the forward accelerometer; a mounting error turns the heading). Learnt here
//!   as the mean rate of the speed and heading corrections and applied through the loss.
//!
//! Rates are exponential means with a time constant of `window_s`: each reference (RTK
//! fixed) update adds the correction it made, divided by the time since the previous one. A
//! learnt rate is applied only where it stands out of its own noise (`|mean| > 3` standard
//! errors over the samples in the window): a 30 Hz MEMS IMU's heading corrections scatter by
//! 3.6 mrad/s per update, and a mean of 0.19 mrad/s within that noise, applied through a
//! 150 s loss, put the train 50 m off the track (seed003 seed 2).

use railfuse_catalog::messages::ImuErrorModel;
use serde::{Deserialize, Serialize};

/// `[pipeline.gnss_ins.learning]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LearningSettings {
    pub enabled: bool,
    /// The learning period's time constant, s: two minutes spans a few curves and gradients
    /// but forgets a stretch of line the train has long left.
    pub window_s: f64,
    /// GNSS counts as lost after this long without a fused fix, s.
    pub loss_after_s: f64,
    /// Learning needs this many seconds of good GNSS before it is applied.
    pub min_learning_s: f64,
}

impl Default for LearningSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            window_s: 120.0,
            loss_after_s: 1.0,
            min_learning_s: 30.0,
        }
    }
}

/// An exponential mean and variance with time constant `tau`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Ewm {
    mean: f64,
    second: f64,
    weight: f64,
}

impl Ewm {
    fn push(&mut self, x: f64, dt: f64, tau: f64) {
        if !x.is_finite() {
            return;
        }
        let a = 1.0 - (-dt / tau).exp();
        self.weight += a * (1.0 - self.weight);
        let a = a / self.weight.max(a); // the first sample counts in full
        self.mean += a * (x - self.mean);
        self.second += a * (x * x - self.second);
    }

    fn std(&self) -> f64 {
        (self.second - self.mean * self.mean).max(0.0).sqrt()
    }
}

/// What has been learnt so far.
#[derive(Debug, Clone, Default)]
pub struct ErrorLearning {
    speed_rate: Ewm,
    heading_rate: Ewm,
    learnt_s: f64,
    samples: u64,
}

/// Standard errors a learnt mean must stand out by to be applied.
const SIGNIFICANCE: f64 = 3.0;

impl ErrorLearning {
    /// A GNSS update corrected speed by `dv` and heading by `dpsi`, `dt` after the previous.
    pub fn learn(&mut self, dv: f64, dpsi: f64, dt: f64, s: &LearningSettings) {
        // Too short an interval makes the rate all noise; a gap that long is not "good GNSS".
        if !(dt > 1e-3 && dt <= s.loss_after_s) {
            return;
        }
        self.speed_rate.push(dv / dt, dt, s.window_s);
        self.heading_rate.push(dpsi / dt, dt, s.window_s);
        self.learnt_s += dt;
        self.samples += 1;
    }

    /// `rate`'s mean where it stands out of its noise, else 0.
    fn significant(&self, rate: &Ewm, s: &LearningSettings) -> f64 {
        let in_window = self.samples as f64 * (s.window_s / self.learnt_s.max(1e-9)).min(1.0);
        let standard_error = rate.std() / in_window.max(1.0).sqrt();
        match rate.mean.abs() > SIGNIFICANCE * standard_error {
            true => rate.mean,
            false => 0.0,
        }
    }

    /// The corrections (speed, heading) to apply over an IMU step of `dt` during a loss.
    pub fn correction(&self, dt: f64, s: &LearningSettings) -> Option<(f64, f64)> {
        (s.enabled && self.learnt_s >= s.min_learning_s).then(|| {
            (
                self.significant(&self.speed_rate, s) * dt,
                self.significant(&self.heading_rate, s) * dt,
            )
        })
    }

    /// The learnt model as a message: with the biases `(accel, gyro)` and the standstill
    /// samples and seconds they rest on.
    pub fn message(
        &self,
        stamp_ns: u64,
        (accel_bias_mps2, gyro_bias_radps): (f64, f64),
        (standstill_samples, standstill_s): (u64, f64),
        applied: bool,
    ) -> ImuErrorModel {
        ImuErrorModel {
            stamp_ns,
            accel_bias_mps2,
            gyro_bias_radps,
            standstill_samples,
            standstill_s,
            speed_residual_mps2: self.speed_rate.mean,
            speed_residual_std_mps2: self.speed_rate.std(),
            heading_residual_radps: self.heading_rate.mean,
            heading_residual_std_radps: self.heading_rate.std(),
            learnt_s: self.learnt_s,
            applied,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learns_a_steady_residual_and_applies_it_only_when_learnt_enough() {
        let s = LearningSettings::default();
        let mut l = ErrorLearning::default();
        // A gradient of 0.5 % the level model misses: the speed is corrected by
        // +0.049 m/s² × 0.1 s at every 10 Hz fix.
        for i in 0..400 {
            l.learn(0.049 * 0.1, 0.0, 0.1, &s);
            if i == 100 {
                assert!(l.correction(1.0, &s).is_none(), "applied after 10 s");
            }
        }
        let (dv, dpsi) = l.correction(1.0, &s).unwrap();
        assert!((dv - 0.049).abs() < 1e-9 && dpsi == 0.0, "{dv} {dpsi}");
        let m = l.message(0, (0.0, 0.0), (0, 0.0), false);
        assert!(m.speed_residual_std_mps2 < 1e-6);
        // A 30 s gap is not good GNSS.
        let before = l.learnt_s;
        l.learn(1.0, 0.0, 30.0, &s);
        assert_eq!(l.learnt_s, before);
        // A mean buried in its noise is learnt but not applied.
        let mut noisy = ErrorLearning::default();
        for i in 0..400 {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            noisy.learn((0.001 + sign * 0.05) * 0.1, 0.0, 0.1, &s);
        }
        assert_eq!(noisy.correction(1.0, &s), Some((0.0, 0.0)));
        let off = LearningSettings {
            enabled: false,
            ..s
        };
        assert!(l.correction(1.0, &off).is_none());
    }
}
