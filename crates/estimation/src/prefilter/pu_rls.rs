//! PU-RLS (source 003, section 1.2): RLS whose forgetting factor a particle swarm adapts at
//! every step, over the model of λ in [`super::forgetting`].
//!
//! Each particle is a parameter pair `θ = (ρ, λ_floor)` of the model (the ceiling is fixed).
//! Its fitness is how well the pre-filter would have predicted the latest `window` samples
//! had it run with `θ`: the sum of squared a-priori errors over each sample's reported
//! variance, `Σ eᵢ² / σᵢ²`, replayed from the filter's state at the start of the window. The swarm takes one
//! generation per sample ([`super::pso`]); the sample is then filtered with `λ = λ_θ(r̄)` of
//! the swarm's best `θ`.
//!
//! Choices the source leaves open, and why:
//! - what the swarm searches: the model's two parameters rather than λ itself, so that λ
//!   still reacts within a sample to an error burst (through `r̄`) while the swarm follows the
//!   slower question of how strongly it should react;
//! - window 50 samples (5 s of 10 Hz GNSS): a longer memory shows in the fitness only as a
//!   slightly smaller prediction error (about 10 % between λ = 0.95 and 0.995), which 12
//!   samples cannot resolve (their spread is 40 %): there the swarm kept λ near 0.95 on a
//!   steady cruise. At 100 samples it followed a brake application too slowly. 50 did best
//!   on the changing test signal (`prefilter::tests`);
//! - swarm of 6: the fitness has two parameters and moves slowly; more particles cost time at
//!   200 Hz without finding better `θ` (see the benchmark);
//! - search box `ρ ∈ [0, 20]`, `λ_floor ∈ [0.5, ceiling]`: at `ρ = 20` a doubling of the
//!   error's expected size already takes λ to its floor; a floor below 0.5 remembers less than
//!   two samples.

use std::collections::VecDeque;

use super::forgetting::{ErrorLevel, ForgettingModel};
use super::pso::Swarm;
use super::rls::{LocalTrend, TrendStep};

/// PU-RLS's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct PuRlsSettings {
    /// The model's fixed ceiling: the longest memory (`1 / (1 − λ)` samples).
    pub ceiling: f64,
    /// Where the swarm starts: the adaptive RLS defaults.
    pub rho: f64,
    pub floor: f64,
    /// Samples in `r̄`'s exponential mean.
    pub memory: f64,
    /// Samples the fitness replays.
    pub window: usize,
    pub swarm: usize,
    pub rho_max: f64,
    pub floor_min: f64,
    /// RLS's `δ` (`P₀ = δ⁻¹ I`).
    pub delta: f64,
    /// Seed of the swarm's random numbers (mixed with the channel's).
    pub seed: u64,
}

impl Default for PuRlsSettings {
    fn default() -> Self {
        Self {
            ceiling: 0.995,
            rho: 0.5,
            floor: 0.9,
            memory: 10.0,
            window: 50,
            swarm: 6,
            rho_max: 20.0,
            floor_min: 0.5,
            delta: 1e-2,
            seed: 0,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Sample {
    t_ns: u64,
    d: f64,
    variance: f64,
    lambda: f64,
}

/// The filter's state at some sample: the trend and the error level driving λ.
#[derive(Debug, Clone, Copy)]
struct State {
    trend: LocalTrend,
    level: ErrorLevel,
}

impl State {
    fn step(&mut self, s: &Sample, lambda: f64) -> TrendStep {
        let step = self.trend.update(s.t_ns, s.d, s.variance, lambda);
        self.level.push(step.error, step.error_variance);
        step
    }
}

#[derive(Debug, Clone)]
pub struct PuRls {
    settings: PuRlsSettings,
    live: State,
    /// The state just before the window's first sample.
    checkpoint: State,
    window: VecDeque<Sample>,
    swarm: Swarm<2>,
}

impl PuRls {
    /// `seed` tells apart the channels of one pipeline.
    pub fn new(settings: PuRlsSettings, seed: u64) -> Self {
        let start = State {
            trend: LocalTrend::new(settings.delta),
            level: ErrorLevel::new(settings.memory),
        };
        let s = settings;
        Self {
            settings,
            live: start,
            checkpoint: start,
            window: VecDeque::with_capacity(s.window + 1),
            swarm: Swarm::new(
                s.swarm,
                [0.0, s.floor_min],
                [s.rho_max, s.ceiling],
                [s.rho, s.floor],
                s.seed ^ seed,
            ),
        }
    }

    fn model(&self, theta: &[f64; 2]) -> ForgettingModel {
        ForgettingModel {
            rho: theta[0],
            floor: theta[1],
            ceiling: self.settings.ceiling,
        }
    }

    /// The model the swarm currently holds best.
    pub fn current_model(&self) -> ForgettingModel {
        self.model(&self.swarm.best())
    }

    /// Filters one sample; returns the step and the λ it was filtered with.
    pub fn step(&mut self, t_ns: u64, d: f64, variance: f64) -> (TrendStep, f64) {
        let sample = Sample {
            t_ns,
            d,
            variance,
            lambda: f64::NAN,
        };
        self.window.push_back(sample);
        if self.window.len() > self.settings.window {
            let oldest = self.window.pop_front().expect("a full window");
            self.checkpoint.step(&oldest, oldest.lambda);
        }
        let (checkpoint, window) = (self.checkpoint, &self.window);
        let ceiling = self.settings.ceiling;
        self.swarm.generation(|theta| {
            let model = ForgettingModel {
                rho: theta[0],
                floor: theta[1],
                ceiling,
            };
            let mut replay = checkpoint;
            window
                .iter()
                .map(|s| {
                    let step = replay.step(s, model.lambda(replay.level.mean));
                    // Against the sample's own variance: the fit's uncertainty must not excuse
                    // its errors (a short memory would buy itself a larger `E[e²]`).
                    step.error * step.error / s.variance
                })
                .sum()
        });
        let lambda = self.current_model().lambda(self.live.level.mean);
        self.window.back_mut().expect("just pushed").lambda = lambda;
        (self.live.step(&sample, lambda), lambda)
    }
}
