//! Expectation–maximisation of the noise of a linear-Gaussian state-space model
//! (Shumway & Stoffer 1982; what pykalman's `KalmanFilter.em` computes).
//!
//! E-step: a Kalman filter forward and an RTS smoother back, with the lag-one covariances
//! ```text
//! J_t = P_t|t Fᵀ_{t+1} (P_{t+1|t})⁻¹
//! x_t|T = x_t|t + J_t (x_{t+1|T} − x_{t+1|t}),   P_t|T = P_t|t + J_t (P_{t+1|T} − P_{t+1|t}) J_tᵀ
//! Cov(x_{t+1}, x_t | all) = P_{t+1|T} J_tᵀ
//! ```
//! M-step, from the smoothed moments: the expected process noise of each step
//! ```text
//! S_t = e eᵀ + F P_t|T Fᵀ + P_{t+1|T} − C F ᵀ − F Cᵀ,   e = x_{t+1|T} − F x_t|T,
//! C = Cov(x_{t+1}, x_t | all)
//! ```
//! and of each measurement `E[(z − Hx)(z − Hx)ᵀ] = (z − H x_t|T)(…)ᵀ + H P_t|T Hᵀ`. A full
//! `Q` or `R` is their mean ([`LinearGaussian`], pykalman's estimate); a pipeline's
//! structured noise `Q_t = q Q₁(dt_t)` and per-sensor variances take the maximum-likelihood
//! scalars (the `railfuse-tune` crate's `em` module).

use nalgebra::{SMatrix, SVector};

use super::rts::smoother_gain;
use super::{sqrt_psd, symmetric};

/// A state-space model the E-step can run: its epochs, their transitions, and how each
/// epoch's measurements update the predicted estimate.
pub trait EmModel<const N: usize> {
    fn epochs(&self) -> usize;
    /// `F` from epoch `t − 1` to epoch `t` (`t ≥ 1`).
    fn transition(&self, t: usize) -> SMatrix<f64, N, N>;
    /// `Q` from epoch `t − 1` to epoch `t` (`t ≥ 1`).
    fn process_noise(&self, t: usize) -> SMatrix<f64, N, N>;
    /// Updates the predicted estimate of epoch `t` with its measurements; returns their
    /// log-likelihood.
    fn update(&self, t: usize, x: &mut SVector<f64, N>, p: &mut SMatrix<f64, N, N>) -> f64;
}

/// The smoothed moments of every epoch.
#[derive(Debug, Clone)]
pub struct Smoothed<const N: usize> {
    pub means: Vec<SVector<f64, N>>,
    pub covariances: Vec<SMatrix<f64, N, N>>,
    /// `Cov(x_t, x_{t−1} | all)` for `t ≥ 1` (index 0 unused, zero).
    pub lag_one: Vec<SMatrix<f64, N, N>>,
    /// Log-likelihood of the measurements under the model.
    pub log_likelihood: f64,
}

/// The E-step: filter forward from `(x0, p0)` (the prior of epoch 0, no transition before
/// it, as pykalman), smooth back.
pub fn smooth<const N: usize>(
    model: &impl EmModel<N>,
    x0: SVector<f64, N>,
    p0: SMatrix<f64, N, N>,
) -> Smoothed<N> {
    let n = model.epochs();
    let mut filtered = Vec::with_capacity(n);
    let mut predicted = Vec::with_capacity(n);
    let mut log_likelihood = 0.0;
    let (mut x, mut p) = (x0, p0);
    for t in 0..n {
        if t > 0 {
            let f = model.transition(t);
            x = f * x;
            p = symmetric(f * p * f.transpose() + model.process_noise(t));
        }
        predicted.push((x, p));
        log_likelihood += model.update(t, &mut x, &mut p);
        filtered.push((x, p));
    }
    let mut means = vec![SVector::zeros(); n];
    let mut covariances = vec![SMatrix::zeros(); n];
    let mut lag_one = vec![SMatrix::zeros(); n];
    if n == 0 {
        return Smoothed {
            means,
            covariances,
            lag_one,
            log_likelihood,
        };
    }
    (means[n - 1], covariances[n - 1]) = filtered[n - 1];
    for t in (0..n - 1).rev() {
        let (xf, pf) = filtered[t];
        let (xp, pp) = predicted[t + 1];
        // A singular prediction (no process noise, no prior) leaves epoch t as filtered.
        let j = smoother_gain(&pf, &model.transition(t + 1), &pp).unwrap_or_else(SMatrix::zeros);
        means[t] = xf + j * (means[t + 1] - xp);
        covariances[t] = symmetric(pf + j * (covariances[t + 1] - pp) * j.transpose());
        lag_one[t + 1] = covariances[t + 1] * j.transpose();
    }
    Smoothed {
        means,
        covariances,
        lag_one,
        log_likelihood,
    }
}

impl<const N: usize> Smoothed<N> {
    /// `E[w wᵀ]` of the step into epoch `t` (`t ≥ 1`) under transition `f`.
    pub fn process_moment(&self, t: usize, f: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
        let e = self.means[t] - f * self.means[t - 1];
        let c = self.lag_one[t] * f.transpose();
        e * e.transpose() + f * self.covariances[t - 1] * f.transpose() + self.covariances[t]
            - c
            - c.transpose()
    }
}

/// A time-invariant linear-Gaussian model with `M`-dimensional measurements at every epoch:
/// the model of pykalman's `KalmanFilter`.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGaussian<const N: usize, const M: usize> {
    pub transition: SMatrix<f64, N, N>,
    pub observation: SMatrix<f64, M, N>,
    pub process_noise: SMatrix<f64, N, N>,
    pub measurement_noise: SMatrix<f64, M, M>,
    pub initial_mean: SVector<f64, N>,
    pub initial_covariance: SMatrix<f64, N, N>,
}

/// The model and its measurements, as the E-step sees them.
struct WithMeasurements<'a, const N: usize, const M: usize> {
    model: &'a LinearGaussian<N, M>,
    z: &'a [SVector<f64, M>],
}

impl<const N: usize, const M: usize> EmModel<N> for WithMeasurements<'_, N, M> {
    fn epochs(&self) -> usize {
        self.z.len()
    }
    fn transition(&self, _: usize) -> SMatrix<f64, N, N> {
        self.model.transition
    }
    fn process_noise(&self, _: usize) -> SMatrix<f64, N, N> {
        self.model.process_noise
    }
    fn update(&self, t: usize, x: &mut SVector<f64, N>, p: &mut SMatrix<f64, N, N>) -> f64 {
        let (h, r) = (&self.model.observation, &self.model.measurement_noise);
        let nu = self.z[t] - h * *x;
        let s = symmetric(h * *p * h.transpose() + r);
        let Some(chol) = s.cholesky() else {
            return f64::NAN;
        };
        let s_inv = chol.inverse();
        let k = *p * h.transpose() * s_inv;
        *x += k * nu;
        // Joseph form.
        let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
        *p = symmetric(i_kh * *p * i_kh.transpose() + k * r * k.transpose());
        let log_det: f64 = chol.l().diagonal().iter().map(|d| 2.0 * d.ln()).sum();
        -0.5 * (M as f64 * std::f64::consts::TAU.ln() + log_det + (nu.transpose() * s_inv * nu)[0])
    }
}

impl<const N: usize, const M: usize> LinearGaussian<N, M> {
    /// One EM iteration: the E-step under the current model, then the full `Q` and/or `R`
    /// that maximise the expected likelihood. Returns the log-likelihood of the E-step.
    pub fn em_step(&mut self, z: &[SVector<f64, M>], estimate_q: bool, estimate_r: bool) -> f64 {
        let s = smooth(
            &WithMeasurements { model: self, z },
            self.initial_mean,
            self.initial_covariance,
        );
        let n = z.len();
        if estimate_q && n > 1 {
            let f = self.transition;
            let sum: SMatrix<f64, N, N> = (1..n).map(|t| s.process_moment(t, &f)).sum();
            self.process_noise = symmetric(sum / (n - 1) as f64);
        }
        if estimate_r && n > 0 {
            let h = self.observation;
            let sum: SMatrix<f64, M, M> = (0..n)
                .map(|t| {
                    let e = z[t] - h * s.means[t];
                    e * e.transpose() + h * s.covariances[t] * h.transpose()
                })
                .sum();
            self.measurement_noise = symmetric(sum / n as f64);
        }
        s.log_likelihood
    }

    /// `n` measurements of a run drawn from the model (seeded), starting from state `x`.
    pub fn sample(&self, n: usize, seed: u64, mut x: SVector<f64, N>) -> Vec<SVector<f64, M>> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        // A rank-deficient Q (a jerk held over each step) has no Cholesky factor.
        let (lq, lr) = (
            sqrt_psd(&self.process_noise),
            sqrt_psd(&self.measurement_noise),
        );
        (0..n)
            .map(|_| {
                let w = SVector::<f64, N>::from_fn(|_, _| StandardNormal.sample(&mut rng));
                let v = SVector::<f64, M>::from_fn(|_, _| StandardNormal.sample(&mut rng));
                x = self.transition * x + lq * w;
                self.observation * x + lr * v
            })
            .collect()
    }

    /// `iterations` EM steps; the log-likelihood before each.
    pub fn em(
        &mut self,
        z: &[SVector<f64, M>],
        iterations: usize,
        estimate_q: bool,
        estimate_r: bool,
    ) -> Vec<f64> {
        (0..iterations)
            .map(|_| self.em_step(z, estimate_q, estimate_r))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ConstantAcceleration, ProcessNoise, TransitionModel};

    /// Constant acceleration with white jerk, dt = 0.1 s, position and speed measured.
    fn ca(q: f64, r: [f64; 2]) -> LinearGaussian<3, 2> {
        let m = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(q),
        };
        LinearGaussian {
            transition: m.transition(0.1),
            observation: SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
            process_noise: m.process_noise(0.1),
            measurement_noise: SMatrix::<f64, 2, 2>::new(r[0], 0.0, 0.0, r[1]),
            initial_mean: SVector::zeros(),
            initial_covariance: SMatrix::identity(),
        }
    }

    #[test]
    fn em_raises_the_likelihood_and_recovers_the_measurement_noise() {
        let truth = ca(0.5, [0.04, 0.01]);
        let z = truth.sample(20_000, 1, SVector::<f64, 3>::new(0.0, 10.0, 0.0));
        let mut m = ca(5.0, [1.0, 1.0]);
        let ll = m.em(&z, 60, true, true);
        assert!(
            ll.windows(2).all(|w| w[1] >= w[0] - 1e-6),
            "EM never lowers the likelihood"
        );
        let r = m.measurement_noise;
        assert!((r[(0, 0)] / 0.04 - 1.0).abs() < 0.1, "{r}");
        assert!((r[(1, 1)] / 0.01 - 1.0).abs() < 0.1, "{r}");
        assert!(r[(0, 1)].abs() < 0.003, "{r}");
        // The process noise is estimated as a full matrix; its jerk direction carries it.
        let q = m.process_noise;
        assert!(
            (q[(2, 2)] / truth.process_noise[(2, 2)] - 1.0).abs() < 0.25,
            "{q}"
        );
    }
}
