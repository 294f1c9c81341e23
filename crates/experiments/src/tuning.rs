//! What `railfuse tune` recovers and what it buys:
//!
//! - **recovery**: on seed000 runs, whose true noise values the preset states (jerk variance
//!   0.001 m²/s⁶, loop and radar variances 0.01), each method tunes the three values from a
//!   start 10x off, by maximum likelihood (EM, and each optimiser minimising the innovations'
//!   negative log-likelihood, no reference); the relative error of what it finds, per seed;
//! - **held out**: the default pipeline (samples/kalman.toml) tuned against the truth on some
//!   default-scenario runs, then scored, untuned and tuned, on runs it never saw.

use std::path::{Path, PathBuf};
use std::time::Instant;

use railfuse_record::{simulate, Scenario};
use railfuse_refuse::config::{ObjectiveKind, OptimiserKind};
use railfuse_tune::recording::Metrics;
use railfuse_tune::{ParamReport, TuneRequest, Tuner};
use serde::Serialize;

use crate::{Error, Result};

/// The seed000 preset's noise values (crates/record/src/simulator/seed000.rs).
pub const SEED000_TRUTH: [(&str, f64); 3] = [
    ("motion.jerk_variance", 0.001),
    ("sensor[/loop/position].variance", 0.01),
    ("sensor[/radar/speed].variance", 0.01),
];

/// The recovery runs' length: ten times the source's 100 s, for estimates worth comparing.
pub const RECOVERY_DURATION_S: f64 = 1000.0;

/// The methods compared, and the evaluations each may make (Bayesian optimisation when this
/// build has it).
pub fn methods() -> Vec<(OptimiserKind, &'static str, usize)> {
    let mut m = vec![
        (OptimiserKind::Em, "EM", 200),
        (OptimiserKind::Grid, "grid (9 points a value)", 729),
        (OptimiserKind::NelderMead, "Nelder–Mead", 200),
        (OptimiserKind::Pso, "particle swarm", 200),
    ];
    if railfuse_tune::BAYESIAN {
        m.push((OptimiserKind::Bayesian, "Bayesian (EGO)", 60));
    }
    m
}

#[derive(Debug, Clone, Serialize)]
pub struct RecoveryRow {
    pub method: String,
    /// Per value, per seed: found / true − 1.
    pub relative_errors: Vec<Vec<f64>>,
    pub evaluations: f64,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct HeldOut {
    pub train_seeds: Vec<u64>,
    pub test_seeds: Vec<u64>,
    pub duration_s: f64,
    pub params: Vec<ParamReport>,
    pub train_before: Metrics,
    pub train_after: Metrics,
    pub test_before: Metrics,
    pub test_after: Metrics,
    pub evaluations: usize,
    pub seconds: f64,
    /// The same pipeline tuned on the same runs without the truth: against the RTK
    /// receiver's fixes, which the pipeline never fuses (withheld for the whole run).
    pub without_truth: WithoutTruth,
}

/// Tuning against the withheld RTK receiver instead of the truth, scored on the held-out runs
/// against the truth.
#[derive(Debug, Clone, Serialize)]
pub struct WithoutTruth {
    pub reference: String,
    pub objective_basis: String,
    pub params: Vec<ParamReport>,
    pub test_after: Metrics,
    pub evaluations: usize,
    pub seconds: f64,
    /// Per held-out seed: position RMSE against the truth, untuned, tuned against the truth,
    /// tuned against the RTK fixes.
    pub per_seed: Vec<(u64, f64, f64, f64)>,
}

impl WithoutTruth {
    /// Tuned against the RTK fixes, the held-out position RMSE over that of tuning against
    /// the truth, minus one.
    pub fn against_truth_tuned(&self, truth_tuned: &Metrics) -> Option<f64> {
        Some(self.test_after.position_rmse_m? / truth_tuned.position_rmse_m? - 1.0)
    }

    /// Seeds on which it beats the untuned pipeline, of all.
    pub fn beats_untuned(&self) -> (usize, usize) {
        let n = self.per_seed.iter().filter(|s| s.3 < s.1).count();
        (n, self.per_seed.len())
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct TuningResults {
    pub seeds: u64,
    pub recovery: Vec<RecoveryRow>,
    pub held_out: HeldOut,
}

/// samples/seed000.toml's `kf_no_balise` with its noise 10x off.
const SEED000_START: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
motion = { model = "constant_acceleration", jerk_variance = 0.01 }
reorder_window_s = 0.0
initial = { speed_mps = 20.0, speed_std_mps = 1.0, acceleration_mps2 = 1.0, acceleration_std_mps2 = 0.1 }

[[pipeline.sensor]]
topic = "/loop/position"
variance = 0.1

[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.1

[pipeline.tune.params]
"motion.jerk_variance" = { min = 1e-5, max = 1.0, steps = 9 }
"sensor[/loop/position].variance" = { min = 1e-4, max = 1.0, steps = 9 }
"sensor[/radar/speed].variance" = { min = 1e-4, max = 1.0, steps = 9 }
"#;

/// The default pipeline's noise values and their bounds for the held-out experiment.
const DEFAULT_PARAMS: [&str; 4] = [
    "motion.jerk_psd=0.001..10",
    "sensor[/radar/speed].variance=1e-4..1",
    "sensor[/odometer/1].variance=1e-4..1",
    "sensor[/odometer/2].variance=1e-4..1",
];

fn simulate_to(dir: &Path, scenario: &str, seed: u64, duration_s: f64) -> Result<PathBuf> {
    let preset =
        Scenario::preset(scenario).ok_or_else(|| Error::UnknownScenario(scenario.to_owned()))?;
    let path = dir.join(format!("tune-{scenario}-seed{seed}-{duration_s}s.mcap"));
    simulate(&preset, seed, Some(duration_s), &[], &path)?;
    Ok(path)
}

/// Steps [`run_all`] reports through `progress`.
pub fn runs(seeds: u64) -> u64 {
    seeds * methods().len() as u64 + 1
}

/// Runs both experiments over seeds 1 … `seeds` (held out: trained on them, tested on the
/// next `seeds`).
pub fn run_all(
    dir: &Path,
    seeds: u64,
    default_pipelines: &str,
    progress: &dyn Fn(u64),
) -> Result<TuningResults> {
    let mut done = 0;
    let config = dir.join("tune-seed000-start.toml");
    std::fs::write(&config, SEED000_START).map_err(|source| Error::Io {
        path: config.clone(),
        source,
    })?;
    let methods = methods();
    let mut recovery: Vec<RecoveryRow> = methods
        .iter()
        .map(|(_, name, _)| RecoveryRow {
            method: (*name).to_owned(),
            relative_errors: vec![Vec::new(); SEED000_TRUTH.len()],
            evaluations: 0.0,
            seconds: 0.0,
        })
        .collect();
    for seed in 1..=seeds {
        let log = simulate_to(dir, "seed000", seed, RECOVERY_DURATION_S)?;
        for ((optimiser, _, budget), row) in methods.iter().zip(&mut recovery) {
            let started = Instant::now();
            let tuner = Tuner::open(&TuneRequest {
                config: config.clone(),
                pipeline: "kf".into(),
                logs: vec![log.clone()],
                objective: Some(ObjectiveKind::Nll),
                optimiser: Some(*optimiser),
                max_evaluations: Some(*budget),
                seed: Some(seed),
                ..Default::default()
            })?;
            let outcome = tuner.run(None, None)?;
            row.seconds += started.elapsed().as_secs_f64() / seeds as f64;
            row.evaluations += outcome.report.evaluations as f64 / seeds as f64;
            for (k, (name, truth)) in SEED000_TRUTH.iter().enumerate() {
                let found = outcome
                    .report
                    .params
                    .iter()
                    .find(|p| p.name == *name)
                    .map_or(f64::NAN, |p| p.after);
                row.relative_errors[k].push(found / truth - 1.0);
            }
            done += 1;
            progress(done);
        }
        std::fs::remove_file(&log).ok();
    }
    let held_out = held_out(dir, seeds, default_pipelines)?;
    progress(done + 1);
    Ok(TuningResults {
        seeds,
        recovery,
        held_out,
    })
}

/// Tune the default pipeline on seeds 1 … n against the truth, score on n+1 … 2n.
fn held_out(dir: &Path, seeds: u64, default_pipelines: &str) -> Result<HeldOut> {
    const DURATION_S: f64 = 600.0;
    let config = dir.join("tune-default.toml");
    std::fs::write(&config, default_pipelines).map_err(|source| Error::Io {
        path: config.clone(),
        source,
    })?;
    let train_seeds: Vec<u64> = (1..=seeds).collect();
    let test_seeds: Vec<u64> = (seeds + 1..=2 * seeds).collect();
    let logs = |s: &[u64]| -> Result<Vec<PathBuf>> {
        s.iter()
            .map(|&seed| simulate_to(dir, "default", seed, DURATION_S))
            .collect()
    };
    let (train, test) = (logs(&train_seeds)?, logs(&test_seeds)?);
    let request = |logs: Vec<PathBuf>| TuneRequest {
        config: config.clone(),
        pipeline: "kalman".into(),
        logs,
        reference: Some(railfuse_catalog::topics::GROUND_TRUTH.into()),
        params: DEFAULT_PARAMS.iter().map(|s| s.to_string()).collect(),
        optimiser: Some(OptimiserKind::NelderMead),
        max_evaluations: Some(200),
        ..Default::default()
    };
    let started = Instant::now();
    let tuner = Tuner::open(&request(train.clone()))?;
    let outcome = tuner.run(None, None)?;
    let seconds = started.elapsed().as_secs_f64();
    let tuned: Vec<f64> = outcome.report.params.iter().map(|p| p.after).collect();
    // Without the truth: the same search against the RTK receiver's fixes (RTK fixed ones),
    // which samples/kalman.toml does not fuse.
    let started = Instant::now();
    let rtk = Tuner::open(&TuneRequest {
        reference: Some(railfuse_catalog::topics::GNSS_FIX.into()),
        ..request(train.clone())
    })?
    .run(None, None)?;
    let rtk_seconds = started.elapsed().as_secs_f64();
    let rtk_tuned: Vec<f64> = rtk.report.params.iter().map(|p| p.after).collect();
    let tester = Tuner::open(&request(test.clone()))?;
    let (before, after) = (tester.evaluate(&tester.start())?, tester.evaluate(&tuned)?);
    let rtk_after = tester.evaluate(&rtk_tuned)?;
    let rmse =
        |s: &railfuse_tune::recording::Score| s.metrics().position_rmse_m.unwrap_or(f64::NAN);
    let per_seed = test_seeds
        .iter()
        .enumerate()
        .map(|(i, &seed)| {
            let at = |e: &railfuse_tune::Evaluation| rmse(&e.logs[i]);
            (seed, at(&before), at(&after), at(&rtk_after))
        })
        .collect();
    for log in train.iter().chain(&test) {
        std::fs::remove_file(log).ok();
    }
    Ok(HeldOut {
        train_seeds,
        test_seeds,
        duration_s: DURATION_S,
        params: outcome.report.params.clone(),
        train_before: outcome.report.before.clone(),
        train_after: outcome.report.after.clone(),
        test_before: before.pooled.metrics(),
        test_after: after.pooled.metrics(),
        evaluations: outcome.report.evaluations,
        seconds,
        without_truth: WithoutTruth {
            reference: railfuse_catalog::topics::GNSS_FIX.into(),
            objective_basis: rtk.report.objective_basis.clone(),
            params: rtk.report.params.clone(),
            test_after: rtk_after.pooled.metrics(),
            evaluations: rtk.report.evaluations,
            seconds: rtk_seconds,
            per_seed,
        },
    })
}
