//! S3: the three divergence tests on the innovation sequence, all of which must pass.
//!
//! - (a) variance inequality `Σ νᵀν ≤ r Σ tr(S)` over the last `divergence_window` updates
//!   (S = H P⁻ Hᵀ + R, the innovation's covariance the filter predicts, so `E[ννᵀ] = S` when it
//!   is consistent), reserve coefficient `r ≥ 1`: a filter whose innovations are larger than
//!   it expects has diverged.
//! - (b) error inequality: every component of the latest innovation within the preset limit
//!   (m for positions, m/s for speeds).
//! - (c) covariance norm: `‖P‖`, the largest eigenvalue of the position covariance (the
//!   squared semi-major axis of its error ellipse; the other components have other units),
//!   below the preset limit.

use std::collections::VecDeque;

use nalgebra::Matrix2;
use railfuse_catalog::messages::SafetyCheck;

use super::diagnosis::compared;
use super::settings::SafetySettings;
use crate::filter::Innovation;

/// The kind of an update's innovation, for test (b)'s limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InnovationKind {
    Position,
    Speed,
}

/// The innovation sequence of the last updates.
#[derive(Debug, Clone, Default)]
pub struct DivergenceTests {
    /// (νᵀν, tr S) of each update, newest last.
    window: VecDeque<(f64, f64)>,
    /// The latest update's largest |ν| and its kind.
    latest: Option<(f64, InnovationKind)>,
}

impl DivergenceTests {
    /// One update's innovations (its components: east and north).
    pub fn update(&mut self, kind: InnovationKind, innovations: &[Innovation], window: usize) {
        let nu2: f64 = innovations.iter().map(|i| i.residual * i.residual).sum();
        let trace: f64 = innovations.iter().map(|i| i.variance).sum();
        self.window.push_back((nu2, trace));
        while self.window.len() > window {
            self.window.pop_front();
        }
        let largest = innovations
            .iter()
            .map(|i| i.residual.abs())
            .fold(0.0, f64::max);
        self.latest = Some((largest, kind));
    }

    /// The three tests with position covariance `p`.
    pub fn checks(&self, p: &Matrix2<f64>, s: &SafetySettings) -> [SafetyCheck; 3] {
        let (nu2, trace) = self
            .window
            .iter()
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let ratio = if trace > 0.0 { nu2 / trace } else { 0.0 };
        let a = compared("s3a_variance", ratio, s.reserve_coefficient, || {
            format!(
                "innovations {ratio:.2} times the variance the filter predicts over the last \
                 {} updates (limit r = {})",
                self.window.len(),
                s.reserve_coefficient
            )
        });
        let b = match self.latest {
            Some((nu, kind)) => {
                let (limit, unit) = match kind {
                    InnovationKind::Position => (s.innovation_limit_m, "m"),
                    InnovationKind::Speed => (s.innovation_limit_mps, "m/s"),
                };
                compared("s3b_innovation", nu, limit, || {
                    format!("innovation {nu:.2} {unit}, limit {limit} {unit}")
                })
            }
            None => compared("s3b_innovation", 0.0, s.innovation_limit_m, String::new),
        };
        let norm = p.symmetric_eigenvalues().max();
        let limit = s.max_position_std_m * s.max_position_std_m;
        let c = compared("s3c_covariance", norm, limit, || {
            format!(
                "position σ {:.2} m, limit {} m",
                norm.max(0.0).sqrt(),
                s.max_position_std_m
            )
        });
        [a, b, c]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::KalmanFilter;
    use crate::model::{ConstantAcceleration, ProcessNoise};
    use nalgebra::{Matrix3, RowVector3, Vector3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A 1-D truth `10 t + A sin(t / 20)` fixed at 1 Hz with σ = 1 m, through a
    /// constant-acceleration filter with little jerk noise that believes the fixes are
    /// `believed_std` precise; the share of epochs test (a) fails.
    fn share_failing(believed_std: f64, amplitude_m: f64) -> f64 {
        let s = SafetySettings::default();
        let model = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(1e-4),
        };
        let mut kf = KalmanFilter::new(
            Vector3::new(0.0, 10.0, 0.0),
            Matrix3::from_diagonal(&Vector3::new(1.0, 0.01, 1e-4)),
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let mut tests = DivergenceTests::default();
        let (mut failed, n) = (0, 2000);
        let h = RowVector3::new(1.0, 0.0, 0.0);
        let truth = |t: f64| 10.0 * t + amplitude_m * (t / 20.0).sin();
        for k in 1..=n {
            kf.predict(&model, 1.0);
            let t = k as f64;
            // Two components per epoch, as east and north.
            let i: Vec<Innovation> = (0..2)
                .map(|_| {
                    let z = truth(t) + noise.sample(&mut rng);
                    kf.innovation(&h, believed_std * believed_std, z)
                })
                .collect();
            let z = truth(t) + noise.sample(&mut rng);
            kf.update(&h, believed_std * believed_std, z);
            tests.update(InnovationKind::Position, &i, s.divergence_window);
            let p = Matrix2::from_diagonal_element(kf.estimate.covariance[(0, 0)]);
            if !tests.checks(&p, &s)[0].passed {
                failed += 1;
            }
        }
        failed as f64 / n as f64
    }

    #[test]
    fn the_variance_test_stays_quiet_on_a_consistent_filter_and_fires_on_a_diverging_one() {
        assert_eq!(share_failing(1.0, 0.0), 0.0);
        // Believing 1 m fixes are 10 cm precise: its innovations are 10× what it predicts.
        assert!(share_failing(0.1, 0.0) > 0.9);
        // Accelerations of ±0.5 m/s² its tiny jerk noise cannot follow: it falls behind.
        let lagging = share_failing(1.0, 200.0);
        assert!(lagging > 0.3, "{lagging}");
    }

    #[test]
    fn the_innovation_and_covariance_limits_fire_beyond_their_presets() {
        let s = SafetySettings::default();
        let mut t = DivergenceTests::default();
        let small = Matrix2::from_diagonal_element(1.0);
        t.update(InnovationKind::Position, &[Innovation::new(3.0, 4.0)], 10);
        let c = t.checks(&small, &s);
        assert!(c.iter().all(|c| c.passed), "{c:?}");
        t.update(
            InnovationKind::Position,
            &[Innovation::new(16.0, 400.0)],
            10,
        );
        let c = t.checks(&small, &s);
        assert!(c[0].passed && !c[1].passed && c[2].passed, "{c:?}");
        t.update(InnovationKind::Speed, &[Innovation::new(2.5, 10.0)], 10);
        assert!(!t.checks(&small, &s)[1].passed, "2.5 m/s > 2 m/s");
        let wide = Matrix2::new(4.5, 0.0, 0.0, 1.0);
        let c = t.checks(&wide, &s)[2].clone();
        assert!(!c.passed && c.reason.unwrap().contains("position σ 2.12 m"));
    }
}
