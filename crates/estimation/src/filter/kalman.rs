//! The linear Kalman filter, with scalar measurement updates in Joseph form.
//!
//! Predict:
//! ```text
//! x⁻ = F x,          P⁻ = F P Fᵀ + Q
//! ```
//! Update with `z = H x + v`, `v ~ N(0, R)`:
//! ```text
//! ν = z − H x⁻,      S = H P⁻ Hᵀ + R,      K = P⁻ Hᵀ S⁻¹
//! x = x⁻ + K ν,      P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ      (Joseph form)
//! ```
//! The Joseph form keeps `P` symmetric and positive semi-definite under rounding, where the
//! short form `(I − KH)P⁻` can lose both; `P` is also re-symmetrised after every step.

use nalgebra::{RowSVector, SMatrix, SVector};

use super::{symmetric, Innovation, LocalFilter, StateAndCovariance};
use crate::model::TransitionModel;

/// A Kalman filter over an `N`-state, its estimate and covariance kept together.
///
/// ```
/// use nalgebra::{Matrix2, RowVector2, Vector2};
/// use railfuse_estimation::filter::KalmanFilter;
/// use railfuse_estimation::model::ConstantVelocity;
///
/// // A train at chainage 0 m and 10 m/s, a second later seen by a loop at 10.2 m.
/// let mut kf = KalmanFilter::new(Vector2::new(0.0, 10.0), Matrix2::identity());
/// kf.predict(&ConstantVelocity { acceleration_psd: 0.1 }, 1.0);
/// let innovation = kf.update(&RowVector2::new(1.0, 0.0), 0.25, 10.2);
/// assert!((innovation.residual - 0.2).abs() < 1e-12);
/// assert!(innovation.nis < 1.0);
/// // Between the prediction (10 m) and the fix (10.2 m), and surer than either.
/// let e = &kf.estimate;
/// assert!(e.state[0] > 10.0 && e.state[0] < 10.2);
/// assert!(e.covariance[(0, 0)] < 0.25);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanFilter<const N: usize> {
    pub estimate: StateAndCovariance<N>,
}

impl<const N: usize> KalmanFilter<N> {
    pub fn new(state: SVector<f64, N>, covariance: SMatrix<f64, N, N>) -> Self {
        Self {
            estimate: StateAndCovariance { state, covariance },
        }
    }

    pub fn predict(&mut self, model: &(impl TransitionModel<N> + ?Sized), dt: f64) {
        self.predict_scaled(model.transition(dt), model.process_noise(dt));
    }

    /// Predict with a known input: `x⁻ = F x + B u` (`bu` is `B u`), `P⁻ = F P Fᵀ + Q`.
    pub fn predict_with_input(
        &mut self,
        model: &(impl TransitionModel<N> + ?Sized),
        dt: f64,
        bu: &SVector<f64, N>,
    ) {
        self.predict_scaled(model.transition(dt), model.process_noise(dt));
        self.estimate.state += bu;
    }

    /// Predict with a transition `f` and process noise `q` already computed (a model whose
    /// `Q` is built from its `Φ`, computed once).
    pub fn predict_matrices(&mut self, f: SMatrix<f64, N, N>, q: SMatrix<f64, N, N>) {
        self.predict_scaled(f, q);
    }

    fn predict_scaled(&mut self, f: SMatrix<f64, N, N>, q: SMatrix<f64, N, N>) {
        let e = &mut self.estimate;
        e.state = f * e.state;
        e.covariance = symmetric(f * e.covariance * f.transpose() + q);
    }

    /// The innovation `z` would produce, without changing the estimate (for gating).
    pub fn innovation(&self, h: &RowSVector<f64, N>, r: f64, z: f64) -> Innovation {
        let e = &self.estimate;
        Innovation::new(
            z - (h * e.state)[0],
            (h * e.covariance * h.transpose())[0] + r,
        )
    }

    /// Joseph-form update with a scalar measurement; returns the innovation it used.
    pub fn update(&mut self, h: &RowSVector<f64, N>, r: f64, z: f64) -> Innovation {
        let innovation = self.innovation(h, r, z);
        let e = &mut self.estimate;
        let k: SVector<f64, N> = e.covariance * h.transpose() / innovation.variance;
        e.state += k * innovation.residual;
        let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
        e.covariance = symmetric(i_kh * e.covariance * i_kh.transpose() + k * r * k.transpose());
        innovation
    }
}

impl<const N: usize> LocalFilter<N> for KalmanFilter<N> {
    fn predict(&mut self, model: &dyn TransitionModel<N>, dt: f64, q_scale: f64) {
        self.predict_scaled(model.transition(dt), model.process_noise(dt) * q_scale);
    }

    fn innovation(&self, h: &RowSVector<f64, N>, r: f64, z: f64) -> Innovation {
        KalmanFilter::innovation(self, h, r, z)
    }

    fn update(&mut self, h: &RowSVector<f64, N>, r: f64, z: f64) -> bool {
        let before = self.estimate.clone();
        KalmanFilter::update(self, h, r, z);
        if !self.estimate.is_finite() {
            self.estimate = before;
            return false;
        }
        true
    }

    fn estimate(&self) -> StateAndCovariance<N> {
        self.estimate.clone()
    }

    fn reset(&mut self, to: &StateAndCovariance<N>) {
        self.estimate = to.clone();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ConstantAcceleration, ProcessNoise};
    use nalgebra::{Matrix3, RowVector3, Vector3};

    #[test]
    fn a_position_update_pulls_the_state_by_the_gain_and_shrinks_the_variance() {
        let mut kf = KalmanFilter::new(
            Vector3::new(0.0, 10.0, 0.0),
            Matrix3::from_diagonal(&Vector3::new(4.0, 1.0, 0.1)),
        );
        let i = kf.update(&RowVector3::new(1.0, 0.0, 0.0), 4.0, 2.0);
        assert_eq!(i.residual, 2.0);
        assert_eq!(i.variance, 8.0);
        assert!((kf.estimate.state[0] - 1.0).abs() < 1e-12);
        assert!((kf.estimate.covariance[(0, 0)] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn covariance_stays_symmetric_and_positive_over_many_irregular_steps() {
        let model = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(0.05),
        };
        let mut kf = KalmanFilter::new(Vector3::zeros(), Matrix3::identity() * 1e6);
        for k in 0..20_000 {
            let dt = 0.001 + (k % 7) as f64 * 0.013;
            kf.predict(&model, dt);
            let h = if k % 3 == 0 {
                RowVector3::new(1.0, 0.0, 0.0)
            } else {
                RowVector3::new(0.0, 1.0, 0.0)
            };
            kf.update(&h, 1e-6, k as f64);
            let p = kf.estimate.covariance;
            assert_eq!(p, p.transpose());
            assert!(p.symmetric_eigenvalues().min() > -1e-12, "{p}");
        }
    }
}
