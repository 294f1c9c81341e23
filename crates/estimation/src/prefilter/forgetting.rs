//! The forgetting factor as a function of how well the fit has been predicting: adaptive RLS
//! runs this model with fixed parameters, PU-RLS lets a particle swarm re-tune them at every
//! step ([`super::pu_rls`]).
//!
//! ```text
//! rᵢ = eᵢ² / E[eᵢ²]                       (1 on average while the fit is right)
//! r̄ₙ = (1 − α) r̄ₙ₋₁ + α rₙ                 (α = 1 / memory)
//! λₙ = λ_floor + (λ_ceiling − λ_floor) · exp(−ρ · max(0, r̄ₙ − 1))
//! ```
//!
//! A stationary stretch keeps `r̄` near 1 and λ at its ceiling (long memory, most noise
//! averaged out); a change the quadratic cannot follow (a brake application, multipath
//! arriving) makes the errors outgrow their expected size and λ falls towards its floor
//! (short memory, little lag). `ρ` is the source's sensitivity gain: how strongly the
//! departure from stationarity shortens the memory.
//!
//! The source drives its model with the recent errors and the signal-to-noise ratio, the
//! previous filtered value taken as the signal and the raw sample as signal plus noise. The
//! power of a coordinate depends on where its origin is, so here the receiver's reported
//! variance stands in for the noise power and the ratio that carries the information is the
//! error against its expected variance, `rᵢ`.

/// `λ(r̄) = floor + (ceiling − floor) · exp(−ρ · max(0, r̄ − 1))`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
pub struct ForgettingModel {
    pub floor: f64,
    pub ceiling: f64,
    pub rho: f64,
}

impl ForgettingModel {
    pub fn lambda(&self, error_level: f64) -> f64 {
        let excess = (error_level - 1.0).max(0.0);
        self.floor + (self.ceiling - self.floor) * (-self.rho * excess).exp()
    }
}

/// `r̄`: the recent normalised squared error, an exponential mean over `memory` samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorLevel {
    pub mean: f64,
    alpha: f64,
}

impl ErrorLevel {
    pub fn new(memory: f64) -> Self {
        Self {
            mean: 1.0,
            alpha: 1.0 / memory.max(1.0),
        }
    }

    pub fn push(&mut self, error: f64, expected_variance: f64) {
        let r = error * error / expected_variance;
        // One absurd sample (a NaN variance, say) must not freeze λ for the rest of the run.
        if r.is_finite() {
            self.mean += self.alpha * (r - self.mean);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambda_is_at_its_ceiling_while_the_fit_predicts_and_falls_when_it_does_not() {
        let m = ForgettingModel {
            floor: 0.8,
            ceiling: 0.99,
            rho: 0.5,
        };
        assert_eq!(m.lambda(0.7), 0.99);
        assert_eq!(m.lambda(1.0), 0.99);
        assert!((m.lambda(3.0) - (0.8 + 0.19 * (-1.0f64).exp())).abs() < 1e-12);
        assert!(m.lambda(100.0) - 0.8 < 1e-9);
        let mut level = ErrorLevel::new(10.0);
        for _ in 0..100 {
            level.push(3.0, 1.0);
        }
        assert!((level.mean - 9.0).abs() < 1e-3, "{}", level.mean);
        level.push(1.0, f64::NAN);
        assert!(level.mean.is_finite());
    }
}
