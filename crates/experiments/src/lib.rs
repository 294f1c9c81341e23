//! The experiments of the source documents, re-run: each source's scenario simulated over
//! many seeds, re-fused with the source's pipelines, and scored against the truth. What it
//! owns:
//!
//! - [`run`]: simulate, re-fuse and evaluate one run (one scenario, seed, set of faults);
//! - [`Envelope`]: the worst case over seeds of one pipeline's figures;
//! - [`sources`]: the experiments of sources 000 and 001 and their typed results, each
//!   source's claim beside railfuse's figure of the same kind;
//! - [`long_runs`]: the default pipelines' covariance honesty over one-hour runs;
//! - [`sharing`]: what sources 000 and 001's α and β change, and under which fusion rule;
//! - [`safety`]: source 002's safety checks: availability, containment and flagged faults;
//! - [`eddy_current`]: source 004's eddy-current speed and distance by speed band, beside its
//!   goals;
//! - [`gnss_ins`]: source 003's GNSS/INS pipelines scored in the plane beside its figures;
//! - [`tuning`]: what `railfuse tune` recovers of known noise values, and what tuning buys on
//!   runs it never saw.
//!
//! Printing the results (Markdown, JSON) is the CLI's job.

pub mod eddy_current;
pub mod gnss_ins;
pub mod long_runs;
pub mod safety;
pub mod sharing;
pub mod sources;
pub mod tuning;

use std::borrow::Cow;
use std::path::Path;

use railfuse_catalog::topics;
use railfuse_eval::{PipelineEval, AFTER_FIRST_BALISE};
use railfuse_record::simulator::FaultSpec;
use railfuse_record::{simulate, Scenario};
use railfuse_refuse::replay::{refuse, RefuseOptions};
use railfuse_refuse::spec::Pipelines;
use serde::Serialize;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("unknown scenario '{0}'")]
    UnknownScenario(String),
    #[error(transparent)]
    Scenario(#[from] railfuse_record::error::ScenarioError),
    #[error(transparent)]
    Simulate(#[from] railfuse_catalog::Error),
    #[error(transparent)]
    Refuse(#[from] railfuse_refuse::Error),
    #[error(transparent)]
    Tune(#[from] railfuse_tune::Error),
    #[error(transparent)]
    Calibrate(#[from] railfuse_calibrate::Error),
    #[error("a pipeline variant does not read back: {0}")]
    Toml(toml::de::Error),
    #[error("{}: {source}", path.display())]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// One run, evaluated: every pipeline's figures and the run's length.
#[derive(Debug, Clone)]
pub struct Run {
    pub pipelines: Vec<PipelineEval>,
    pub duration_s: f64,
}

/// Simulates the preset `scenario` with `seed` and `faults` into `dir`, re-fuses the log with
/// `pipelines`, evaluates against the truth, and removes both logs.
pub fn run(
    dir: &Path,
    scenario: &str,
    seed: u64,
    faults: &[FaultSpec],
    pipelines: &Pipelines,
    tag: &str,
) -> Result<Run> {
    let preset =
        Scenario::preset(scenario).ok_or_else(|| Error::UnknownScenario(scenario.to_owned()))?;
    run_scenario(dir, &preset, seed, None, faults, pipelines, tag)
}

/// [`run`] on a scenario given by value (a preset with some parameters changed), for
/// `duration_s` (the preset's whole run when `None`).
pub fn run_scenario(
    dir: &Path,
    scenario: &Scenario,
    seed: u64,
    duration_s: Option<f64>,
    faults: &[FaultSpec],
    pipelines: &Pipelines,
    tag: &str,
) -> Result<Run> {
    scenario.check(duration_s, faults)?;
    let (pipelines, duration_s) = fused_run(
        dir,
        scenario,
        (seed, duration_s, faults),
        (pipelines, Train::AsConfigured),
        tag,
        |_, eval| Ok(eval.pipelines),
    )?;
    Ok(Run {
        pipelines,
        duration_s,
    })
}

/// The train a run is re-fused with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Train {
    /// The configuration's `[vehicle]`, else the log's drawing.
    AsConfigured,
    /// The log's drawing with the IMU's mounting from `railfuse calibrate` on the same run:
    /// how a field engineer re-fuses a run whose train was built to a tolerance of its
    /// drawing (the railway scenarios), since the drawing's degree or two of mounting is
    /// `g` times that in the IMU's forward and lateral acceleration.
    Calibrated,
}

/// Simulates `scenario` with `seed` into `dir`, re-fuses it with `pipelines` and the `train`,
/// hands the fused log to `score`, and removes both logs whatever happened.
pub(crate) fn score_fused_run(
    dir: &Path,
    scenario: &Scenario,
    seed: u64,
    (pipelines, train): (&Pipelines, Train),
    tag: &str,
    score: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    fused_run(
        dir,
        scenario,
        (seed, None, &[]),
        (pipelines, train),
        tag,
        |fused, _| score(fused),
    )
    .map(|_| ())
}

/// One simulated run `(seed, duration, faults)` re-fused: `score` gets the fused log and the
/// refuse run's evaluation; both logs are removed afterwards whatever happened. Also gives
/// the run's simulated length, s.
fn fused_run<T>(
    dir: &Path,
    scenario: &Scenario,
    (seed, duration_s, faults): (u64, Option<f64>, &[FaultSpec]),
    (pipelines, train): (&Pipelines, Train),
    tag: &str,
    score: impl FnOnce(&Path, railfuse_eval::EvalReport) -> Result<T>,
) -> Result<(T, f64)> {
    let name = scenario.name();
    let raw = dir.join(format!("{name}-{tag}-seed{seed}.mcap"));
    let fused = dir.join(format!("{name}-{tag}-seed{seed}.fused.mcap"));
    let sim = simulate(scenario, seed, duration_s, faults, &raw)?;
    let run = railfuse_catalog::run::Run::file(&raw);
    let result = match train {
        Train::AsConfigured => Ok(Cow::Borrowed(pipelines)),
        Train::Calibrated => calibrated(&run).map(|vehicle| {
            let mut config = pipelines.clone();
            config.vehicle = Some(vehicle);
            Cow::Owned(config)
        }),
    }
    .and_then(|config| {
        refuse(&RefuseOptions {
            run: &run,
            output: &fused,
            config: &config,
            config_source: pipelines.path.display().to_string(),
            reference: &railfuse_eval::Reference::topic(topics::GROUND_TRUTH),
            withhold: None,
            progress: None,
            observer: None,
        })
        .map_err(Error::from)
    });
    std::fs::remove_file(&raw).ok();
    let scored = result.and_then(|(_, eval)| score(&fused, eval));
    std::fs::remove_file(&fused).ok();
    Ok((scored?, sim.duration_s))
}

/// The run's drawing with the IMU's mounting calibrated from the run itself, replayed with
/// its default pipeline as `railfuse calibrate RUN` does.
fn calibrated(run: &railfuse_catalog::run::Run) -> Result<railfuse_catalog::messages::Vehicle> {
    let default = railfuse_refuse::default_config::default_config(run, None)?;
    let config = default.pipelines(Path::new("default pipeline"))?;
    let priors = railfuse_calibrate::mounting::MountingPriors::default();
    let c = railfuse_calibrate::calibrate(&[(run.clone(), config)], None, &priors)?;
    Ok(c.vehicle())
}

/// Envelopes over `seeds` runs of each of `names`, `run(seed)` giving one run.
pub(crate) fn envelopes(
    seeds: u64,
    names: &[&str],
    step: &mut dyn FnMut(),
    mut run: impl FnMut(u64) -> Result<Run>,
) -> Result<Vec<Envelope>> {
    let mut env = vec![Envelope::default(); names.len()];
    for seed in 0..seeds {
        let r = run(seed)?;
        for (e, name) in env.iter_mut().zip(names) {
            e.add_named(&r, name);
        }
        step();
    }
    Ok(env)
}

/// Worst case over seeds of one pipeline's figures: signed error extremes, mean RMSE, the
/// lowest output rate and the mean share of states whose NEES lies in its 95 % interval.
#[derive(Debug, Default, Clone, Copy, Serialize)]
pub struct Envelope {
    pub runs: u32,
    pub position_min_m: f64,
    pub position_max_m: f64,
    pub position_rmse_sum_m: f64,
    pub speed_min_mps: f64,
    pub speed_max_mps: f64,
    pub speed_rmse_sum_mps: f64,
    pub min_rate_hz: f64,
    pub nees_inside_sum: f64,
    /// The lowest share of states inside the NEES 95 % interval in any one run.
    pub nees_inside_min: f64,
    /// The largest position RMSE of any one run, m.
    pub position_rmse_max_m: f64,
    /// Largest |position error| after the first balise, m (runs with balises).
    pub after_first_balise_abs_m: Option<f64>,
}

impl Envelope {
    /// Adds one run of pipeline `p` (a run without errors, with no reference, is left out).
    pub fn add(&mut self, p: &PipelineEval, duration_s: f64) {
        let (Some(pos), Some(spd)) = (&p.position_error_m, &p.speed_error_mps) else {
            return;
        };
        let rate = p.states as f64 / duration_s;
        let nees = p.nees.as_ref().map_or(0.0, |n| n.inside_95);
        if self.runs == 0 {
            self.nees_inside_min = nees;
            self.position_min_m = pos.min;
            self.position_max_m = pos.max;
            self.speed_min_mps = spd.min;
            self.speed_max_mps = spd.max;
            self.min_rate_hz = rate;
        }
        self.runs += 1;
        self.position_min_m = self.position_min_m.min(pos.min);
        self.position_max_m = self.position_max_m.max(pos.max);
        self.speed_min_mps = self.speed_min_mps.min(spd.min);
        self.speed_max_mps = self.speed_max_mps.max(spd.max);
        self.position_rmse_sum_m += pos.rmse;
        self.speed_rmse_sum_mps += spd.rmse;
        self.min_rate_hz = self.min_rate_hz.min(rate);
        self.nees_inside_sum += nees;
        self.nees_inside_min = self.nees_inside_min.min(nees);
        self.position_rmse_max_m = self.position_rmse_max_m.max(pos.rmse);
        let after_balise = p
            .windows
            .iter()
            .find(|w| w.label == AFTER_FIRST_BALISE)
            .and_then(|w| w.position_error_m.as_ref())
            .map(|e| e.max_abs);
        if let Some(a) = after_balise {
            self.after_first_balise_abs_m =
                Some(self.after_first_balise_abs_m.map_or(a, |b| b.max(a)));
        }
    }

    /// The run named `name` of `run`, if it was evaluated.
    pub fn add_named(&mut self, run: &Run, name: &str) {
        if let Some(p) = run.pipelines.iter().find(|p| p.name == name) {
            self.add(p, run.duration_s);
        }
    }

    /// Largest |position error|, m.
    pub fn position_abs_m(&self) -> f64 {
        self.position_max_m.max(-self.position_min_m)
    }

    /// Largest |speed error|, m/s.
    pub fn speed_abs_mps(&self) -> f64 {
        self.speed_max_mps.max(-self.speed_min_mps)
    }

    pub fn position_rmse_m(&self) -> f64 {
        self.position_rmse_sum_m / f64::from(self.runs.max(1))
    }

    pub fn speed_rmse_mps(&self) -> f64 {
        self.speed_rmse_sum_mps / f64::from(self.runs.max(1))
    }

    /// Mean share of states whose NEES lies inside its 95 % interval.
    pub fn nees_inside_95(&self) -> f64 {
        self.nees_inside_sum / f64::from(self.runs.max(1))
    }
}
