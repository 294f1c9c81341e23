//! The bootstrap particle filter: particles drawn through the motion model (the transition
//! prior as importance density), weighted by the measurement likelihood, resampled when the
//! effective sample size
//!
//! ```text
//! N_eff = 1 / Σ wᵢ²
//! ```
//!
//! falls below a share of the particle count, and roughened after resampling against sample
//! impoverishment (Gordon, Salmond & Smith 1993): each component j gets Gaussian jitter of
//! standard deviation `K · E_j · N^(−1/d)`, `E_j` the particles' spread in that component.
//! Weights are kept as logarithms during the update so that a very precise measurement (a
//! balise) cannot underflow them all to zero. Seeded: the same seed gives the same run.

mod resampling;

pub use resampling::Resampling;

use nalgebra::{RowSVector, SMatrix, SVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::sqrt_psd;
use super::{symmetric, EstimatorDiagnostics, Innovation, LocalFilter, StateAndCovariance};
use crate::model::TransitionModel;

/// A particle filter's settings: the `[pipeline.particle]` table as written.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct ParticleSettings {
    pub particles: usize,
    pub resampling: Resampling,
    /// Resample when N_eff < threshold · N.
    pub ess_threshold: f64,
    /// Roughening constant K after resampling (0 turns roughening off).
    pub roughening: f64,
    pub seed: u64,
    /// A measurement whose NIS against the cloud (its mean and spread) exceeds this has
    /// missed the cloud: weighting would leave all the weight on the nearest particle and the
    /// cloud collapsed for good. Instead the cloud is drawn afresh from the Kalman update of
    /// its Gaussian (a re-seed). Default 25 (5σ, PX4's position gate); 0: never (the
    /// sources' bootstrap filter).
    pub reseed_nis: f64,
    /// A measurement far more precise than the cloud, landing in its tail inside the NIS
    /// gate, leaves its weight on a handful of particles: when N_eff falls below this share of
    /// N, the posterior has too few particles to stand for it, roughening (scaled by their
    /// spread) cannot widen them again, and the cloud stays collapsed and overconfident. It
    /// is re-seeded the same way. Default 0.01 (fewer than 10 of 1 000 particles); 0: never.
    pub reseed_ess: f64,
}

impl Default for ParticleSettings {
    fn default() -> Self {
        Self {
            particles: 1000,
            resampling: Resampling::Systematic,
            ess_threshold: 0.5,
            roughening: 0.1,
            seed: 1,
            reseed_nis: 25.0,
            reseed_ess: 0.01,
        }
    }
}

impl ParticleSettings {
    /// Checks every value; the message names the offending key.
    pub fn check(&self) -> Result<(), String> {
        if self.particles == 0 {
            return Err("particle.particles must be at least 1".into());
        }
        if !(self.ess_threshold > 0.0 && self.ess_threshold <= 1.0) {
            return Err(format!(
                "particle.ess_threshold must be in (0, 1], not {}",
                self.ess_threshold
            ));
        }
        if !(self.roughening.is_finite() && self.roughening >= 0.0) {
            return Err(format!(
                "particle.roughening must be ≥ 0, not {}",
                self.roughening
            ));
        }
        if !(self.reseed_nis.is_finite() && self.reseed_nis >= 0.0) {
            return Err(format!(
                "particle.reseed_nis must be ≥ 0, not {}",
                self.reseed_nis
            ));
        }
        if !(self.reseed_ess >= 0.0 && self.reseed_ess < 1.0) {
            return Err(format!(
                "particle.reseed_ess must be in [0, 1), not {}",
                self.reseed_ess
            ));
        }
        Ok(())
    }

    /// The same settings on random stream `offset` (each local filter of a federated
    /// pipeline has its own).
    pub fn stream(self, offset: u64) -> Self {
        Self {
            seed: self.seed.wrapping_add(offset),
            ..self
        }
    }
}

#[derive(Debug, Clone)]
pub struct ParticleFilter<const N: usize> {
    settings: ParticleSettings,
    particles: Vec<SVector<f64, N>>,
    /// Normalised weights.
    weights: Vec<f64>,
    rng: ChaCha8Rng,
    last_ess: f64,
    last_resampled: bool,
    scratch: Vec<usize>,
    /// The weights before an update, kept to re-seed from if it collapses the cloud.
    prior_weights: Vec<f64>,
}

impl<const N: usize> ParticleFilter<N> {
    /// Draws the particles from the Gaussian prior `initial`.
    pub fn new(settings: ParticleSettings, initial: &StateAndCovariance<N>) -> Self {
        let mut pf = Self {
            particles: Vec::with_capacity(settings.particles),
            weights: Vec::with_capacity(settings.particles),
            rng: ChaCha8Rng::seed_from_u64(settings.seed),
            last_ess: settings.particles as f64,
            last_resampled: false,
            scratch: Vec::new(),
            prior_weights: Vec::new(),
            settings,
        };
        pf.reset(initial);
        pf
    }

    pub fn particles(&self) -> &[SVector<f64, N>] {
        &self.particles
    }

    pub fn effective_sample_size(&self) -> f64 {
        1.0 / self.weights.iter().map(|w| w * w).sum::<f64>()
    }

    fn gaussian(&mut self) -> SVector<f64, N> {
        SVector::from_fn(|_, _| StandardNormal.sample(&mut self.rng))
    }

    /// `H p` of every particle.
    fn projected(&self, h: &RowSVector<f64, N>) -> Vec<f64> {
        self.particles.iter().map(|p| (h * p)[0]).collect()
    }

    /// The innovation against the cloud's weighted mean and spread of `H p` (`hx`).
    fn innovation_of(&self, hx: &[f64], r: f64, z: f64) -> Innovation {
        let mean: f64 = hx.iter().zip(&self.weights).map(|(x, w)| w * x).sum();
        let var: f64 = hx
            .iter()
            .zip(&self.weights)
            .map(|(x, w)| w * (x - mean).powi(2))
            .sum();
        Innovation::new(z - mean, var + r)
    }

    /// The cloud drawn afresh from the Kalman update of its Gaussian by `z` (a re-seed).
    fn reseed(&mut self, h: &RowSVector<f64, N>, r: f64, z: f64) -> bool {
        let mut g = super::KalmanFilter {
            estimate: self.estimate(),
        };
        if !LocalFilter::update(&mut g, h, r, z) {
            return false;
        }
        let e = g.estimate();
        self.reset(&e);
        self.last_ess = self.particles.len() as f64;
        self.last_resampled = true;
        true
    }

    fn resample(&mut self) {
        let mut idx = std::mem::take(&mut self.scratch);
        self.settings
            .resampling
            .resample(&self.weights, &mut self.rng, &mut idx);
        let survivors: Vec<SVector<f64, N>> = idx.iter().map(|&i| self.particles[i]).collect();
        self.particles = survivors;
        self.scratch = idx;
        let n = self.particles.len();
        self.weights.iter_mut().for_each(|w| *w = 1.0 / n as f64);
        if self.settings.roughening > 0.0 {
            let mut lo = SVector::<f64, N>::repeat(f64::INFINITY);
            let mut hi = SVector::<f64, N>::repeat(f64::NEG_INFINITY);
            for p in &self.particles {
                lo = lo.inf(p);
                hi = hi.sup(p);
            }
            let sigma = (hi - lo) * self.settings.roughening * (n as f64).powf(-1.0 / N as f64);
            for i in 0..n {
                let jitter = self.gaussian().component_mul(&sigma);
                self.particles[i] += jitter;
            }
        }
    }
}

impl<const N: usize> LocalFilter<N> for ParticleFilter<N> {
    fn predict(&mut self, model: &dyn TransitionModel<N>, dt: f64, q_scale: f64) {
        let f = model.transition(dt);
        let l = sqrt_psd(&(model.process_noise(dt) * q_scale));
        for i in 0..self.particles.len() {
            let w = l * self.gaussian();
            self.particles[i] = f * self.particles[i] + w;
        }
    }

    fn innovation(&self, h: &RowSVector<f64, N>, r: f64, z: f64) -> Innovation {
        self.innovation_of(&self.projected(h), r, z)
    }

    fn update(&mut self, h: &RowSVector<f64, N>, r: f64, z: f64) -> bool {
        // Each particle projected once: for the re-seed check and for its weight.
        let mut log_lik = self.projected(h);
        if self.settings.reseed_nis > 0.0
            && self.innovation_of(&log_lik, r, z).nis > self.settings.reseed_nis
        {
            return self.reseed(h, r, z);
        }
        if self.settings.reseed_ess > 0.0 {
            self.prior_weights.clone_from(&self.weights);
        }
        for l in &mut log_lik {
            *l = -0.5 * (z - *l).powi(2) / r;
        }
        let max = log_lik.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            return false;
        }
        let mut total = 0.0;
        for (w, l) in self.weights.iter_mut().zip(&log_lik) {
            *w *= (l - max).exp();
            total += *w;
        }
        if !(total > 0.0 && total.is_finite()) {
            // Every particle was too far from z for its prior weight: the measurement is
            // inconsistent with the cloud; keep the cloud and weight by likelihood alone.
            for (w, l) in self.weights.iter_mut().zip(&log_lik) {
                *w = (l - max).exp();
            }
            total = self.weights.iter().sum();
        }
        self.weights.iter_mut().for_each(|w| *w /= total);
        self.last_ess = self.effective_sample_size();
        let n = self.particles.len() as f64;
        if self.last_ess < self.settings.reseed_ess * n {
            std::mem::swap(&mut self.weights, &mut self.prior_weights);
            return self.reseed(h, r, z);
        }
        self.last_resampled =
            self.last_ess < self.settings.ess_threshold * self.particles.len() as f64;
        if self.last_resampled {
            self.resample();
        }
        true
    }

    fn estimate(&self) -> StateAndCovariance<N> {
        let mut mean = SVector::<f64, N>::zeros();
        for (p, w) in self.particles.iter().zip(&self.weights) {
            mean += p * *w;
        }
        let mut cov = SMatrix::<f64, N, N>::zeros();
        for (p, w) in self.particles.iter().zip(&self.weights) {
            let d = p - mean;
            cov += d * d.transpose() * *w;
        }
        StateAndCovariance {
            state: mean,
            covariance: symmetric(cov),
        }
    }

    fn reset(&mut self, to: &StateAndCovariance<N>) {
        let l = sqrt_psd(&to.covariance);
        let n = self.settings.particles;
        self.particles.clear();
        for _ in 0..n {
            let p = to.state + l * self.gaussian();
            self.particles.push(p);
        }
        self.weights = vec![1.0 / n as f64; n];
    }

    fn diagnostics(&self, out: &mut EstimatorDiagnostics) {
        out.effective_sample_size = Some(self.last_ess);
        out.resampled = Some(self.last_resampled);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::KalmanFilter;
    use crate::model::ConstantVelocity;
    use nalgebra::{Matrix2, RowVector2, Vector2};

    fn run(particles: usize, seed: u64) -> (StateAndCovariance<2>, StateAndCovariance<2>) {
        let model = ConstantVelocity {
            acceleration_psd: 0.05,
        };
        let init = StateAndCovariance {
            state: Vector2::new(0.0, 10.0),
            covariance: Matrix2::new(4.0, 0.0, 0.0, 1.0),
        };
        let settings = ParticleSettings {
            particles,
            resampling: Resampling::Systematic,
            ess_threshold: 0.5,
            roughening: 0.0,
            seed,
            reseed_nis: 0.0,
            reseed_ess: 0.0,
        };
        let mut pf = ParticleFilter::new(settings, &init);
        let mut kf = KalmanFilter::new(init.state, init.covariance);
        for k in 1..=40 {
            let dt = 0.5;
            LocalFilter::predict(&mut pf, &model, dt, 1.0);
            kf.predict(&model, dt);
            let t = k as f64 * dt;
            let (h, r, z) = if k % 2 == 0 {
                (
                    RowVector2::new(1.0, 0.0),
                    1.0,
                    10.0 * t + ((k * 37) % 5) as f64 * 0.3 - 0.6,
                )
            } else {
                (
                    RowVector2::new(0.0, 1.0),
                    0.04,
                    10.0 + ((k * 11) % 3) as f64 * 0.1 - 0.1,
                )
            };
            LocalFilter::update(&mut pf, &h, r, z);
            kf.update(&h, r, z);
        }
        (pf.estimate(), kf.estimate)
    }

    /// On a linear-Gaussian problem the particle filter tends to the Kalman filter: with 20 000
    /// particles its mean is within 0.05 σ and its variance within 10 % of the Kalman
    /// filter's, and the error shrinks as the particle count grows.
    #[test]
    fn particle_mean_and_variance_approach_the_kalman_filter_as_particles_grow() {
        let gap = |n: usize| {
            let mut worst_mean = 0.0f64;
            let mut worst_var = 0.0f64;
            for seed in 0..4 {
                let (pf, kf) = run(n, seed);
                for i in 0..2 {
                    let sd = kf.covariance[(i, i)].sqrt();
                    worst_mean = worst_mean.max((pf.state[i] - kf.state[i]).abs() / sd);
                    worst_var =
                        worst_var.max((pf.covariance[(i, i)] / kf.covariance[(i, i)] - 1.0).abs());
                }
            }
            (worst_mean, worst_var)
        };
        let (m_small, v_small) = gap(200);
        let (m_big, v_big) = gap(20_000);
        eprintln!("particle vs Kalman: 200 particles: mean {m_small:.3} σ, variance {v_small:.3}; 20 000: mean {m_big:.4} σ, variance {v_big:.4}");
        assert!(
            m_big < 0.05 && v_big < 0.10,
            "20 000 particles: mean gap {m_big} σ, variance gap {v_big}"
        );
        assert!(
            m_big < m_small && v_big < v_small,
            "no convergence: {m_small}/{v_small} → {m_big}/{v_big}"
        );
    }

    #[test]
    fn square_root_of_rank_one_noise_is_exact() {
        let g = nalgebra::Vector3::new(1.0 / 6.0, 0.5, 1.0);
        let q = g * g.transpose() * 0.001;
        let l = sqrt_psd(&q);
        assert!((l * l.transpose() - q).abs().max() < 1e-15);
        let full = nalgebra::Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let l = sqrt_psd(&full);
        assert!((l * l.transpose() - full).abs().max() < 1e-12);
    }

    #[test]
    fn the_same_seed_gives_the_same_run_and_a_far_measurement_never_makes_nan() {
        assert_eq!(run(500, 3).0, run(500, 3).0);
        let init = StateAndCovariance {
            state: Vector2::new(0.0, 10.0),
            covariance: Matrix2::identity(),
        };
        let settings = ParticleSettings {
            particles: 100,
            resampling: Resampling::Residual,
            ess_threshold: 0.5,
            roughening: 0.2,
            seed: 1,
            reseed_nis: 0.0,
            reseed_ess: 0.0,
        };
        let mut pf = ParticleFilter::new(settings, &init);
        assert!(LocalFilter::update(
            &mut pf,
            &RowVector2::new(1.0, 0.0),
            1e-4,
            1e6
        ));
        assert!(pf.estimate().is_finite());
    }

    /// A precise fix far outside the cloud: weighted as the bootstrap filter does, every
    /// weight goes to the nearest particle and the cloud collapses onto it (far from the fix,
    /// no spread left); re-seeded (`reseed_nis`), the cloud is drawn from the Kalman update
    /// of its Gaussian, and the speed, which the fix does not measure, keeps its spread.
    #[test]
    fn a_fix_that_missed_the_cloud_reseeds_it_instead_of_collapsing_it() {
        let init = StateAndCovariance {
            state: Vector2::new(0.0, 10.0),
            covariance: Matrix2::new(0.01, 0.0, 0.0, 1.0),
        };
        let h = RowVector2::new(1.0, 0.0);
        let after = |reseed_nis: f64| {
            let settings = ParticleSettings {
                particles: 2000,
                reseed_nis,
                reseed_ess: 0.0,
                roughening: 0.0,
                ..ParticleSettings::default()
            };
            let mut pf = ParticleFilter::new(settings, &init);
            assert!(LocalFilter::update(&mut pf, &h, 1e-4, 5.0));
            pf.estimate()
        };
        let (stated, reseeded) = (after(0.0), after(25.0));
        // Collapsed: short of the fix by metres, nothing left of its spread.
        assert!(5.0 - stated.state[0] > 4.0, "{stated:?}");
        assert!(stated.covariance[(1, 1)] < 1e-6, "{stated:?}");
        // Re-seeded: at the Kalman posterior of the cloud's Gaussian and the fix (mean
        // 5 · 0.01 / 0.0101, variance 0.01 · 1e-4 / 0.0101); the speed keeps its spread.
        let (mean, var) = (5.0 * 0.01 / 0.0101, 0.01 * 1e-4 / 0.0101);
        assert!((reseeded.state[0] - mean).abs() < 0.01, "{reseeded:?}");
        assert!(
            (reseeded.covariance[(0, 0)] / var - 1.0).abs() < 0.1,
            "{reseeded:?}"
        );
        assert!((reseeded.covariance[(1, 1)] - 1.0).abs() < 0.1);
    }

    /// A balise σ 0.1 m landing 1.9 m into the tail of a cloud of σ 0.39 m: NIS 22.3, inside
    /// the 5σ gate, so no NIS re-seed. Weighted as the bootstrap filter does, the weight goes
    /// to the few particles nearest the fix, short of it, and the cloud is left overconfident
    /// (seed000_loop_drift seed 27: pf_balise 3.06 m off at σ 0.2 m); with `reseed_ess` the
    /// collapsed weights re-seed it at the Kalman posterior.
    #[test]
    fn a_precise_fix_in_the_clouds_tail_reseeds_it_when_the_weights_collapse() {
        let init = StateAndCovariance {
            state: Vector2::new(0.0, 10.0),
            covariance: Matrix2::new(0.39 * 0.39, 0.0, 0.0, 1.0),
        };
        let h = RowVector2::new(1.0, 0.0);
        let after = |reseed_ess: f64| {
            let settings = ParticleSettings {
                reseed_ess,
                ..ParticleSettings::default()
            };
            let mut pf = ParticleFilter::new(settings, &init);
            assert!(pf.innovation(&h, 0.01, 1.9).nis < 25.0);
            assert!(LocalFilter::update(&mut pf, &h, 0.01, 1.9));
            (pf.estimate(), pf.last_ess)
        };
        let p = 0.39 * 0.39;
        let (mean, var) = (1.9 * p / (p + 0.01), p * 0.01 / (p + 0.01));
        let ((collapsed, _), (reseeded, ess)) = (after(0.0), after(0.01));
        assert!(mean - collapsed.state[0] > 0.3, "{collapsed:?}");
        assert!(collapsed.covariance[(0, 0)] < var / 4.0, "{collapsed:?}");
        assert!((reseeded.state[0] - mean).abs() < 0.02, "{reseeded:?}");
        assert!(
            (reseeded.covariance[(0, 0)] / var - 1.0).abs() < 0.15,
            "{reseeded:?}"
        );
        assert_eq!(ess, 1000.0, "a fresh cloud");
    }
}
