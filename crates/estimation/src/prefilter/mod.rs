//! Pre-filters (source 003): one scalar channel (a GNSS coordinate, a velocity component, an
//! IMU axis) smoothed before it reaches the fusion filter, with the variance it leaves the
//! pre-filter with.
//!
//! - [`rls`]: RLS with a forgetting factor, on a local quadratic in time ([`rls::LocalTrend`]);
//! - [`forgetting`]: the model of λ driven by the recent errors (adaptive RLS);
//! - [`pso`]: the particle swarm, and [`pu_rls`]: PU-RLS, whose λ model the swarm re-tunes at
//!   every step;
//! - [`unscented`]: the unscented transform of a nonlinear observation (speed and course to
//!   east/north velocity).
//!
//! A pre-filtered channel is correlated in time, which the fusion filter, assuming white
//! measurement noise, does not know: the variance passed on is the pre-filter's own, so the
//! fusion takes the smoothed value for what it is worth at one sample, not for the several
//! samples it averages.

pub mod forgetting;
pub mod pso;
pub mod pu_rls;
pub mod rls;
pub mod unscented;

use forgetting::{ErrorLevel, ForgettingModel};
use pu_rls::{PuRls, PuRlsSettings};
use rls::LocalTrend;

/// A channel's pre-filter, as configured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(
    feature = "serde",
    serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)
)]
pub enum PreFilterSettings {
    /// The samples as they are.
    #[default]
    None,
    /// RLS with a fixed forgetting factor.
    Rls {
        /// The forgetting factor λ, in (0, 1].
        lambda: f64,
        /// The start covariance's scale δ (P₀ = I/δ).
        #[cfg_attr(feature = "serde", serde(default = "default_delta"))]
        delta: f64,
    },
    /// RLS with λ from the recent errors ([`forgetting`]), fixed parameters.
    AdaptiveRls(AdaptiveRlsSettings),
    /// PU-RLS ([`pu_rls`]).
    PuRls(PuRlsSettings),
}

#[cfg(feature = "serde")]
fn default_delta() -> f64 {
    1e-2
}

/// Adaptive RLS: the forgetting model's parameters, `r̄`'s memory (samples) and `δ`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct AdaptiveRlsSettings {
    pub floor: f64,
    pub ceiling: f64,
    pub rho: f64,
    pub memory: f64,
    pub delta: f64,
}

impl Default for AdaptiveRlsSettings {
    /// PU-RLS's starting point, so that the two differ only in the swarm.
    fn default() -> Self {
        let p = PuRlsSettings::default();
        Self {
            floor: p.floor,
            ceiling: p.ceiling,
            rho: p.rho,
            memory: p.memory,
            delta: p.delta,
        }
    }
}

impl AdaptiveRlsSettings {
    pub fn model(&self) -> ForgettingModel {
        ForgettingModel {
            floor: self.floor,
            ceiling: self.ceiling,
            rho: self.rho,
        }
    }
}

impl PreFilterSettings {
    /// The settings' problems, in words (λ outside (0, 1], a swarm of none, …).
    pub fn check(&self) -> Result<(), String> {
        let unit = |what: &str, x: f64| match x > 0.0 && x <= 1.0 {
            true => Ok(()),
            false => Err(format!("{what} = {x}: a forgetting factor is in (0, 1]")),
        };
        let positive = |what: &str, x: f64| match x > 0.0 && x.is_finite() {
            true => Ok(()),
            false => Err(format!("{what} = {x}: must be positive")),
        };
        match *self {
            PreFilterSettings::None => Ok(()),
            PreFilterSettings::Rls { lambda, delta } => {
                unit("lambda", lambda)?;
                positive("delta", delta)
            }
            PreFilterSettings::AdaptiveRls(a) => {
                unit("floor", a.floor)?;
                unit("ceiling", a.ceiling)?;
                if a.floor > a.ceiling {
                    return Err(format!("floor {} above ceiling {}", a.floor, a.ceiling));
                }
                if !(a.rho >= 0.0) {
                    return Err(format!("rho = {}: must be at least 0", a.rho));
                }
                positive("memory", a.memory)?;
                positive("delta", a.delta)
            }
            PreFilterSettings::PuRls(s) => {
                unit("ceiling", s.ceiling)?;
                unit("floor_min", s.floor_min)?;
                if !(s.floor_min..=s.ceiling).contains(&s.floor) {
                    return Err(format!(
                        "floor {} outside [floor_min {}, ceiling {}]",
                        s.floor, s.floor_min, s.ceiling
                    ));
                }
                if !(0.0..=s.rho_max).contains(&s.rho) {
                    return Err(format!("rho {} outside [0, rho_max {}]", s.rho, s.rho_max));
                }
                if s.window == 0 || s.swarm == 0 {
                    return Err("window and swarm must be at least 1".into());
                }
                positive("memory", s.memory)?;
                positive("delta", s.delta)
            }
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            PreFilterSettings::None => "none",
            PreFilterSettings::Rls { .. } => "rls",
            PreFilterSettings::AdaptiveRls { .. } => "adaptive_rls",
            PreFilterSettings::PuRls(_) => "pu_rls",
        }
    }
}

/// One filtered sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filtered {
    pub value: f64,
    pub variance: f64,
    /// The forgetting factor the sample was filtered with (None without RLS).
    pub lambda: Option<f64>,
}

/// A channel's pre-filter, running.
#[derive(Debug, Clone)]
pub enum PreFilter {
    None,
    Rls {
        trend: LocalTrend,
        lambda: f64,
    },
    Adaptive {
        trend: LocalTrend,
        model: ForgettingModel,
        level: ErrorLevel,
    },
    PuRls(Box<PuRls>),
}

impl PreFilter {
    /// `seed` tells apart the channels of one pipeline (PU-RLS's swarm).
    pub fn new(settings: &PreFilterSettings, seed: u64) -> Self {
        match *settings {
            PreFilterSettings::None => PreFilter::None,
            PreFilterSettings::Rls { lambda, delta } => PreFilter::Rls {
                trend: LocalTrend::new(delta),
                lambda,
            },
            PreFilterSettings::AdaptiveRls(a) => PreFilter::Adaptive {
                trend: LocalTrend::new(a.delta),
                model: a.model(),
                level: ErrorLevel::new(a.memory),
            },
            PreFilterSettings::PuRls(s) => PreFilter::PuRls(Box::new(PuRls::new(s, seed))),
        }
    }

    /// Filters sample `d` of variance `variance` at `t_ns`.
    pub fn step(&mut self, t_ns: u64, d: f64, variance: f64) -> Filtered {
        let (step, lambda) = match self {
            PreFilter::None => {
                return Filtered {
                    value: d,
                    variance,
                    lambda: None,
                }
            }
            PreFilter::Rls { trend, lambda } => (trend.update(t_ns, d, variance, *lambda), *lambda),
            PreFilter::Adaptive {
                trend,
                model,
                level,
            } => {
                let lambda = model.lambda(level.mean);
                let step = trend.update(t_ns, d, variance, lambda);
                level.push(step.error, step.error_variance);
                (step, lambda)
            }
            PreFilter::PuRls(p) => p.step(t_ns, d, variance),
        };
        Filtered {
            value: step.value,
            variance: step.variance,
            lambda: Some(lambda),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A signal whose statistics change: a quiet cruise, then hard braking with noise bursts
    /// (multipath), then standstill. Returns (t, truth, noisy, variance) at 10 Hz.
    fn changing_signal(seed: u64) -> Vec<(u64, f64, f64, f64)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut out = Vec::new();
        let (mut x, mut v) = (0.0f64, 20.0f64);
        for i in 0..3000u64 {
            let t = i as f64 * 0.1;
            let a = match t {
                t if t < 60.0 => 0.0,
                t if t < 70.0 => -1.2,
                t if t < 120.0 => 0.05 * (t * 0.7).sin(),
                t if t < 135.0 => -0.6,
                _ => 0.0,
            };
            v = (v + a * 0.1).max(0.0);
            x += v * 0.1;
            let sigma = if (150.0..200.0).contains(&t) {
                3.0
            } else {
                0.8
            };
            out.push((
                i * 100_000_000,
                x,
                x + sigma * unit.sample(&mut rng),
                0.8 * 0.8,
            ));
        }
        out
    }

    fn rmse(settings: PreFilterSettings, seed: u64) -> f64 {
        let mut f = PreFilter::new(&settings, 1);
        let data = changing_signal(seed);
        let sq: f64 = data
            .iter()
            .skip(50)
            .map(|&(t, truth, z, r)| (f.step(t, z, r).value - truth).powi(2))
            .sum();
        (sq / (data.len() - 50) as f64).sqrt()
    }

    #[test]
    fn pu_rls_beats_fixed_lambda_rls_on_a_signal_whose_statistics_change() {
        let pu = PreFilterSettings::PuRls(PuRlsSettings::default());
        for seed in [1, 2, 3] {
            let p = rmse(pu, seed);
            for lambda in [0.9, 0.95, 0.98, 0.995] {
                let r = rmse(
                    PreFilterSettings::Rls {
                        lambda,
                        delta: 1e-2,
                    },
                    seed,
                );
                assert!(
                    p < r,
                    "seed {seed}: PU-RLS {p:.3} m vs RLS λ {lambda} {r:.3} m"
                );
            }
            let raw = rmse(PreFilterSettings::None, seed);
            assert!(
                p < 0.6 * raw,
                "seed {seed}: PU-RLS {p:.3} m vs raw {raw:.3} m"
            );
        }
    }

    #[test]
    fn pu_rls_is_reproducible_for_a_seed() {
        let run = |seed| {
            let s = PreFilterSettings::PuRls(PuRlsSettings {
                seed,
                ..Default::default()
            });
            let mut f = PreFilter::new(&s, 0);
            changing_signal(7)
                .iter()
                .map(|&(t, _, z, r)| f.step(t, z, r).value)
                .collect::<Vec<f64>>()
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }

    #[test]
    #[cfg(feature = "serde")]
    fn bad_settings_are_refused_with_the_field() {
        let bad = PreFilterSettings::Rls {
            lambda: 1.2,
            delta: 1e-2,
        };
        assert!(bad.check().unwrap_err().contains("lambda = 1.2"));
        let toml = "kind = \"pu_rls\"\nwindow = 0\n";
        let s: PreFilterSettings = toml::from_str(toml).unwrap();
        assert!(s.check().unwrap_err().contains("window"));
        assert!(toml::from_str::<PreFilterSettings>("kind = \"rls\"\nlamda = 0.9\n").is_err());
    }
}
