//! Recursive least squares with a forgetting factor λ (source 003, eqs. 1–5):
//!
//! ```text
//! y = wᵀx                      (the filter's output)
//! k = P x / (λ + xᵀ P x)       (gain)
//! e = d − wᵀx                  (a-priori error)
//! w ← w + k e
//! P ← (P − k xᵀ P) / λ
//! w₀ = 0,  P₀ = δ⁻¹ I           (δ small: the prior weighs little)
//! ```
//!
//! It minimises `Σᵢ λⁿ⁻ⁱ (dᵢ − wᵀxᵢ)²`: a sample `N` steps old weighs `λᴺ`, so the memory is
//! about `1 / (1 − λ)` samples. (The source prints the covariance step as `P − k w P`, an
//! extraction slip; `k xᵀ P` is the RLS update.)
//!
//! [`LocalTrend`] is the regression the pre-filters run: a quadratic in time around the
//! latest sample, the motion a train follows between changes of traction (constant
//! acceleration), so the filter has no lag on such a stretch.

use nalgebra::{SMatrix, SVector};

use crate::filter::symmetric;

/// The RLS estimate: weights `w` and the inverse weighted information `P`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rls<const M: usize> {
    pub weights: SVector<f64, M>,
    pub p: SMatrix<f64, M, M>,
}

impl<const M: usize> Rls<M> {
    /// `w = 0`, `P = δ⁻¹ I`.
    pub fn new(delta: f64) -> Self {
        Self {
            weights: SVector::zeros(),
            p: SMatrix::identity() / delta,
        }
    }

    pub fn output(&self, x: &SVector<f64, M>) -> f64 {
        self.weights.dot(x)
    }

    /// One step with regressor `x`, desired output `d` and forgetting factor `lambda`;
    /// returns the gain and the a-priori error `e = d − wᵀx`.
    pub fn update(&mut self, x: &SVector<f64, M>, d: f64, lambda: f64) -> (SVector<f64, M>, f64) {
        let px = self.p * x;
        let k = px / (lambda + x.dot(&px));
        let e = d - self.output(x);
        self.weights += k * e;
        // P symmetric, so xᵀP = (Px)ᵀ.
        self.p = symmetric((self.p - k * px.transpose()) / lambda);
        (k, e)
    }
}

/// Largest step over which a trend is carried without a sample, s: beyond it the old fit says
/// nothing about the signal and the filter starts again (a GNSS outage, say).
pub const MAX_GAP_S: f64 = 5.0;

/// RLS on a local quadratic in time: `d(t) ≈ w₀ + w₁ τ + w₂ τ²` with `τ = t − t_latest`, so
/// `x = [1, 0, 0]` at every sample and `w₀` is the filtered value, `w₁` its rate.
///
/// Moving the time origin to each new sample re-expresses the same fit (`w ← T w`,
/// `P ← T P Tᵀ` with `T` the shift of a polynomial by `dt`), which keeps the regressors of
/// order one over hours of log instead of growing with `t²`; irregular sample times enter
/// through `dt`.
///
/// The channel's first value is the origin of `d` (subtracted on the way in, added on the way
/// out), so `w₀ = 0` starts at the signal rather than at zero.
///
/// Beside the fit it carries `C`, the covariance of the weights' error when the samples carry
/// white noise of their reported variance and the signal is a quadratic (Joseph form:
/// `C ← (I − k xᵀ) T C Tᵀ (I − k xᵀ)ᵀ + σ² k kᵀ`). Its `C₀₀` is the variance the output is
/// passed on with. A signal that is not a quadratic over the memory makes the error larger
/// than `C` says: the forgetting factor trades that lag against noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalTrend {
    pub rls: Rls<3>,
    pub error_covariance: SMatrix<f64, 3, 3>,
    delta: f64,
    origin: Option<f64>,
    last_ns: Option<u64>,
}

/// The regressor at the latest sample.
const AT_LATEST: SVector<f64, 3> = SVector::<f64, 3>::new(1.0, 0.0, 0.0);

/// What one sample gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrendStep {
    /// The a-priori error `d − wᵀx` (before the update).
    pub error: f64,
    /// Its expected variance if the fit were right: `σ² + xᵀ T C Tᵀ x`.
    pub error_variance: f64,
    /// The filtered value and its variance.
    pub value: f64,
    pub variance: f64,
    /// The filtered rate (per second).
    pub rate: f64,
}

impl LocalTrend {
    pub fn new(delta: f64) -> Self {
        Self {
            rls: Rls::new(delta),
            error_covariance: SMatrix::identity() / delta,
            delta,
            origin: None,
            last_ns: None,
        }
    }

    /// `T(dt)`: the coefficients of `p(τ + dt)` from those of `p(τ)`.
    fn shift(dt: f64) -> SMatrix<f64, 3, 3> {
        SMatrix::<f64, 3, 3>::new(1.0, dt, dt * dt, 0.0, 1.0, 2.0 * dt, 0.0, 0.0, 1.0)
    }

    /// The trend moved to `t_ns` without a sample.
    pub fn at(&self, t_ns: u64) -> Self {
        let mut next = *self;
        if let Some(last) = self.last_ns {
            let dt = seconds_between(last, t_ns);
            let t = Self::shift(dt);
            next.rls.weights = t * next.rls.weights;
            next.rls.p = symmetric(t * next.rls.p * t.transpose());
            next.error_covariance = symmetric(t * next.error_covariance * t.transpose());
            next.last_ns = Some(t_ns);
        }
        next
    }

    /// One sample `d` with variance `variance` at `t_ns`, forgetting factor `lambda`.
    pub fn update(&mut self, t_ns: u64, d: f64, variance: f64, lambda: f64) -> TrendStep {
        let gap = self.last_ns.map(|l| seconds_between(l, t_ns));
        if gap.is_some_and(|g| !(0.0..=MAX_GAP_S).contains(&g)) {
            *self = Self::new(self.delta);
        }
        let origin = *self.origin.get_or_insert(d);
        if self.last_ns.is_none() {
            // The prior, in the units of the signal: as uncertain as δ⁻¹ samples' noise.
            self.error_covariance = SMatrix::identity() * (variance / self.delta);
        }
        *self = self.at(t_ns);
        self.last_ns = Some(t_ns);
        let c = self.error_covariance;
        let error_variance = variance + c[(0, 0)];
        let (k, error) = self.rls.update(&AT_LATEST, d - origin, lambda);
        let i_kx = SMatrix::<f64, 3, 3>::identity() - k * AT_LATEST.transpose();
        self.error_covariance =
            symmetric(i_kx * c * i_kx.transpose() + k * k.transpose() * variance);
        TrendStep {
            error,
            error_variance,
            value: origin + self.rls.weights[0],
            variance: self.error_covariance[(0, 0)],
            rate: self.rls.weights[1],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn rls_converges_to_known_coefficients() {
        // d = 2 x₁ − 0.5 x₂ + 0.25 x₃ + noise, regressors random.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let noise = Normal::new(0.0, 0.01).unwrap();
        let truth = SVector::<f64, 3>::new(2.0, -0.5, 0.25);
        let mut rls = Rls::<3>::new(1e-3);
        for _ in 0..2000 {
            let x = SVector::<f64, 3>::from_fn(|_, _| unit.sample(&mut rng));
            let d = truth.dot(&x) + noise.sample(&mut rng);
            rls.update(&x, d, 0.99);
        }
        for i in 0..3 {
            assert!(
                (rls.weights[i] - truth[i]).abs() < 5e-3,
                "w{i} = {} vs {}",
                rls.weights[i],
                truth[i]
            );
        }
        // P stays symmetric and positive definite.
        assert_eq!(rls.p, rls.p.transpose());
        assert!(rls.p.cholesky().is_some());
    }

    #[test]
    fn forgetting_follows_a_change_of_coefficients() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let run = |lambda: f64, rng: &mut rand_chacha::ChaCha8Rng| {
            let mut rls = Rls::<2>::new(1e-3);
            for n in 0..600 {
                let truth = if n < 500 { [1.0, 1.0] } else { [-1.0, 3.0] };
                let x = SVector::<f64, 2>::from_fn(|_, _| unit.sample(rng));
                rls.update(&x, truth[0] * x[0] + truth[1] * x[1], lambda);
            }
            (rls.weights[0] + 1.0).abs() + (rls.weights[1] - 3.0).abs()
        };
        let (forgets, remembers) = (run(0.9, &mut rng), run(1.0, &mut rng));
        assert!(forgets < 1e-3, "λ 0.9 left {forgets}");
        assert!(
            remembers > 0.5,
            "λ 1 should still average the old coefficients"
        );
    }

    #[test]
    fn local_trend_follows_a_constant_acceleration_without_lag_at_irregular_times() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.5).unwrap();
        let mut trend = LocalTrend::new(1e-2);
        let (mut t, mut sq, mut n) = (0.0f64, 0.0, 0);
        let pos = |t: f64| 5000.0 + 12.0 * t + 0.3 * t * t;
        let mut last = None;
        for i in 0..3000 {
            t += if i % 3 == 0 { 0.05 } else { 0.12 };
            let step = trend.update(
                (t * 1e9) as u64,
                pos(t) + noise.sample(&mut rng),
                0.25,
                0.98,
            );
            if i > 500 {
                sq += (step.value - pos(t)).powi(2);
                n += 1;
            }
            last = Some(step);
        }
        let rmse = (sq / n as f64).sqrt();
        // Memory ~50 samples: noise 0.5 m down to about 0.1–0.15 m, and no lag on the ramp.
        assert!(rmse < 0.2, "rmse {rmse}");
        let last = last.unwrap();
        assert!(
            (last.rate - (12.0 + 0.6 * t)).abs() < 0.5,
            "rate {}",
            last.rate
        );
        // The error covariance it reports matches the error it makes (within a factor).
        let reported = last.variance.sqrt();
        assert!(
            reported > 0.5 * rmse && reported < 2.0 * rmse,
            "{reported} vs {rmse}"
        );
    }

    #[test]
    fn local_trend_starts_again_after_a_gap() {
        let mut trend = LocalTrend::new(1e-2);
        for i in 0..100 {
            trend.update(i * 100_000_000, 10.0, 0.01, 0.99);
        }
        let after = trend.update(100 * 100_000_000 + 60_000_000_000, 500.0, 0.01, 0.99);
        assert!((after.value - 500.0).abs() < 1e-6, "{}", after.value);
    }
}

/// Seconds from `a_ns` to `b_ns` (negative when `b` is earlier).
fn seconds_between(a_ns: u64, b_ns: u64) -> f64 {
    (b_ns as i128 - a_ns as i128) as f64 / 1e9
}
