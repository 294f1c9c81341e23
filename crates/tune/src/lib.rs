//! Offline tuning of a pipeline's noise values: choose the process-noise intensity, sensor
//! variances, sensor-state σ and τ and gate thresholds named in `[pipeline.tune]` (or on the
//! command line), within their bounds, to minimise over all the logs together
//!
//! - with a reference (ground truth, an RTK GNSS channel, another pipeline's or smoothed
//!   states): `w_s · RMSE(chainage) + w_v · RMSE(speed)`, errors pooled over the logs;
//! - without one: the negative log-likelihood of the innovations,
//!   `½ Σ (ln 2πS + ν²/S)` over every measurement that reached the gate (rejected ones too,
//!   so a tighter gate cannot buy a better score by discarding data).
//!
//! Each log is decoded once ([`recording::Recording`]); every evaluation replays all of them
//! from memory, the logs in parallel, and parallel searches evaluate their candidates in
//! parallel too (rayon). The tuned file is the configuration file with only the tuned numbers
//! changed ([`params::TunableConfig`]).

mod em;
pub mod error;
pub mod params;
pub mod recording;
pub mod search;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

pub use crate::error::{Error, Result};
use railfuse_eval::outages::Withhold;
use railfuse_refuse::config::{
    ObjectiveKind, OptimiserKind, ParamBounds, PipelinesFile, Scale, TuneConfig,
};
use railfuse_refuse::spec::{PipelineSpec, Pipelines};
use railfuse_refuse::Error as RefuseError;

use params::{Param, ParamPath, TunableConfig};
use recording::{Metrics, Recording, Score};
use search::{Ending, Evaluations, SearchProgress, SearchSettings, TraceRow};

/// Whether this build has Bayesian optimisation (the `bayesian` feature).
pub const BAYESIAN: bool = cfg!(feature = "bayesian");

/// Evaluations a search may make when nothing says otherwise (a grid makes all its points).
pub const DEFAULT_BUDGET: usize = 200;

/// What to tune, on what, and how; the command line's choices override the table's.
#[derive(Default)]
pub struct TuneRequest {
    pub config: PathBuf,
    pub pipeline: String,
    pub logs: Vec<PathBuf>,
    pub reference: Option<String>,
    /// `PATH=MIN..MAX[,log|,linear][,steps=N]` from the command line, beside (and over) the
    /// table's.
    pub params: Vec<String>,
    pub objective: Option<ObjectiveKind>,
    pub optimiser: Option<OptimiserKind>,
    pub max_evaluations: Option<usize>,
    pub seed: Option<u64>,
    /// A sensor withheld from the pipeline in outages (over the pipeline's `[pipeline.eval]`):
    /// tuned by cross-validation against what was withheld.
    pub withhold: Option<Withhold>,
    /// How logs of other tools' formats are read (a logger CSV's mapping).
    pub formats: railfuse_catalog::formats::FormatOptions,
}

/// The objective: what is minimised.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Objective {
    pub kind: ObjectiveKind,
    pub position_weight: f64,
    pub speed_weight: f64,
}

impl Objective {
    /// The value of a pooled score; infinite when it cannot be scored (no matched states, no
    /// innovations, a state or innovation that is not a number).
    pub fn value(&self, s: &Score) -> f64 {
        if s.non_finite > 0 {
            return f64::INFINITY;
        }
        let v = match self.kind {
            ObjectiveKind::Rmse => {
                let p = s.position.summary().map(|x| x.rmse);
                let v = s.speed.summary().map(|x| x.rmse);
                match (p, v) {
                    (Some(p), Some(v)) => self.position_weight * p + self.speed_weight * v,
                    // A reference without speed (a NavSatFix): position alone.
                    (Some(p), None) => self.position_weight * p,
                    _ => f64::INFINITY,
                }
            }
            // Fixes withheld from the pipeline: their likelihood as it predicted them.
            ObjectiveKind::Nll if s.heldout_fixes > 0 => s.heldout_nll,
            ObjectiveKind::Nll => match s.innovations {
                0 => f64::INFINITY,
                _ => s.nll,
            },
        };
        if v.is_nan() {
            f64::INFINITY
        } else {
            v
        }
    }
}

/// One candidate evaluated on every log.
#[derive(Debug, Clone)]
pub struct Evaluation {
    pub objective: f64,
    pub logs: Vec<Score>,
    pub pooled: Score,
}

/// A tuning run ready to search: the configuration, its parameters and the decoded logs.
pub struct Tuner {
    config: TunableConfig,
    pub params: Vec<Param>,
    /// No parameters were named: `params` are the pipeline's noise values.
    pub noise_values: bool,
    pub recordings: Vec<Recording>,
    pub objective: Objective,
    pub reference: Option<String>,
    /// The sensor withheld from the pipeline, if any.
    pub withhold: Option<Withhold>,
    pub optimiser: OptimiserKind,
    pub budget: usize,
    pub seed: u64,
    invalid: AtomicU64,
    first_invalid: Mutex<Option<String>>,
    /// The EM problem, when the optimiser is EM.
    em: Option<em::PipelineEm>,
}

/// A tuned value, before and after.
#[derive(Debug, Clone, Serialize)]
pub struct ParamReport {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub scale: params::ScaleName,
    pub before: f64,
    pub after: f64,
    /// It ended within 0.1 % of the range of a bound: the bound, not the data, may have
    /// chosen it.
    pub on_bound: bool,
}

/// One log's figures before and after.
#[derive(Debug, Clone, Serialize)]
pub struct LogReport {
    pub path: PathBuf,
    pub sensor_messages: usize,
    pub before: Metrics,
    pub after: Metrics,
}

#[derive(Debug, Clone, Serialize)]
pub struct TuneReport {
    pub config: PathBuf,
    pub pipeline: String,
    pub objective: Objective,
    /// What the objective measures, in words (against what, over which samples).
    pub objective_basis: String,
    pub reference: Option<String>,
    pub optimiser: OptimiserKind,
    pub objective_before: f64,
    pub objective_after: f64,
    pub params: Vec<ParamReport>,
    /// All logs pooled.
    pub before: Metrics,
    pub after: Metrics,
    pub logs: Vec<LogReport>,
    pub evaluations: usize,
    /// When the search started, ns since the Unix epoch (the trace's times count from it).
    pub started_unix_ns: u64,
    pub ending: Ending,
    pub search_s: f64,
    pub evaluations_per_s: f64,
    pub threads: usize,
    /// EM: the log-likelihood of each iteration's E-step (it never falls).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub em_log_likelihood: Option<Vec<f64>>,
    /// Candidates the configuration refused (a value its validation rejects): scored as
    /// infinitely bad.
    pub invalid_candidates: u64,
    pub first_invalid: Option<String>,
}

/// What a tuning run gives.
pub struct TuneOutcome {
    pub report: TuneReport,
    pub trace: Vec<TraceRow>,
    /// The configuration file with the tuned values written in, comments kept.
    pub tuned_toml: String,
}

/// What is minimised: the request's objective, else the table's, else RMSE with a reference
/// and the innovations' likelihood without; with the table's weights.
fn objective(
    req: &TuneRequest,
    table: &TuneConfig,
    has_reference: bool,
) -> Result<Objective, String> {
    let kind = match (req.objective.or(table.objective), has_reference) {
        (Some(ObjectiveKind::Rmse), false) => {
            return Err(
                "the rmse objective needs a reference: --reference TOPIC or reference \
                        in [pipeline.tune]"
                    .into(),
            )
        }
        (Some(k), _) => k,
        (None, true) => ObjectiveKind::Rmse,
        (None, false) => ObjectiveKind::Nll,
    };
    let objective = Objective {
        kind,
        position_weight: table.position_weight.unwrap_or(1.0),
        speed_weight: table.speed_weight.unwrap_or(1.0),
    };
    if !(objective.position_weight >= 0.0 && objective.speed_weight >= 0.0)
        || objective.position_weight + objective.speed_weight <= 0.0
    {
        return Err("the weights must be ≥ 0 and not both 0".into());
    }
    Ok(objective)
}

/// The optimiser (Nelder–Mead unless asked) and its evaluation budget (a grid's: every point).
fn search_plan(
    req: &TuneRequest,
    table: &TuneConfig,
    grid_points: usize,
) -> Result<(OptimiserKind, usize), String> {
    let optimiser = req
        .optimiser
        .or(table.optimiser)
        .unwrap_or(OptimiserKind::NelderMead);
    if optimiser == OptimiserKind::Bayesian && !BAYESIAN {
        return Err(search::WITHOUT_BAYESIAN.into());
    }
    let budget = req
        .max_evaluations
        .or(table.max_evaluations)
        .unwrap_or(match optimiser {
            OptimiserKind::Grid => grid_points,
            _ => DEFAULT_BUDGET,
        });
    if budget == 0 {
        return Err("max_evaluations must be at least 1".into());
    }
    Ok((optimiser, budget))
}

/// The pipeline the request names, as the configuration specifies it.
fn pipeline_named(pipelines: &Pipelines, req: &TuneRequest) -> Result<PipelineSpec> {
    pipelines
        .pipeline
        .iter()
        .find(|p| p.name == req.pipeline)
        .cloned()
        .ok_or_else(|| {
            let names: Vec<&str> = pipelines.names().collect();
            Error::Request {
                path: req.config.clone(),
                pipeline: req.pipeline.clone(),
                message: format!("no [[pipeline]] of that name (it has {})", names.join(", ")),
            }
        })
}

/// The parameters and their bounds: `[pipeline.tune.params]`, each overridden or added to
/// by a `--params NAME=LO..HI[:STEPS]` argument.
fn param_bounds(
    table: &TuneConfig,
    args: &[String],
) -> std::result::Result<Vec<(String, ParamBounds)>, String> {
    let mut bounds: Vec<(String, ParamBounds)> = table.params.clone().into_iter().collect();
    for arg in args {
        let (name, b) = parse_param_arg(arg)?;
        match bounds.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = b,
            None => bounds.push((name, b)),
        }
    }
    Ok(bounds)
}

impl Tuner {
    /// Reads the configuration, resolves the parameters and decodes every log (in parallel).
    pub fn open(req: &TuneRequest) -> Result<Self> {
        let (file, text) = PipelinesFile::load(&req.config)?;
        drop(file);
        let pipelines = Pipelines::parse(&text, &req.config)?;
        let spec = pipeline_named(&pipelines, req)?;
        let fail = |message: String| Error::Request {
            path: req.config.clone(),
            pipeline: req.pipeline.clone(),
            message,
        };
        let table = spec.tune().cloned().unwrap_or_default();
        let mut bounds = param_bounds(&table, &req.params).map_err(fail)?;
        let mut config = TunableConfig::new(&text, &req.config, &req.pipeline)?;
        // Nothing named: the pipeline's noise values, as a first tune wants.
        let noise_values = bounds.is_empty();
        if noise_values {
            let topics: Vec<&str> = spec.sensors.iter().map(|s| s.topic.as_str()).collect();
            bounds = config.noise_values(&topics);
        }
        if bounds.is_empty() {
            return Err(fail(
                "nothing to tune: no --params, no [pipeline.tune.params], and no noise value \
                 given as a number (\"message\" variances are each message's own)"
                    .into(),
            ));
        }
        let mut params = Vec::new();
        for (name, b) in &bounds {
            let path: ParamPath = name.parse().map_err(fail)?;
            params.push(config.param(&path, b)?);
        }
        let withhold = req.withhold.clone().or(spec.withhold.clone());
        // Cross-validation: scored against what was withheld, unless told otherwise.
        let reference = req
            .reference
            .clone()
            .or(table.reference.clone())
            .or(withhold.as_ref().map(|w| w.topic.clone()));
        let objective = objective(req, &table, reference.is_some()).map_err(fail)?;
        if req.logs.is_empty() {
            return Err(fail("no logs to tune on".into()));
        }
        let grid_points: usize = params.iter().map(|p| p.steps).product();
        let (optimiser, budget) = search_plan(req, &table, grid_points).map_err(fail)?;
        let recordings = req
            .logs
            .par_iter()
            .map(|log| {
                let track = pipelines.track.as_ref();
                let (reference, withhold) = (reference.as_deref(), withhold.as_ref());
                Recording::load(log, &req.formats, &spec, reference, track, withhold)
            })
            .collect::<Result<Vec<_>>>()?;
        let em = match optimiser {
            OptimiserKind::Em => {
                Some(em::PipelineEm::new(&spec, &params, &recordings).map_err(fail)?)
            }
            _ => None,
        };
        Ok(Self {
            em,
            config,
            params,
            noise_values,
            recordings,
            objective,
            reference,
            withhold,
            optimiser,
            budget,
            seed: req.seed.or(table.seed).unwrap_or(1),
            invalid: AtomicU64::new(0),
            first_invalid: Mutex::new(None),
        })
    }

    /// Each log's figures before and after.
    fn log_reports(&self, before: &Evaluation, after: &Evaluation) -> Vec<LogReport> {
        self.recordings
            .iter()
            .zip(before.logs.iter().zip(&after.logs))
            .map(|(r, (b, a))| LogReport {
                path: r.path.clone(),
                sensor_messages: r.messages(),
                before: b.metrics(),
                after: a.metrics(),
            })
            .collect()
    }

    /// What the objective measures, in words.
    pub fn objective_basis(&self) -> String {
        let withheld = self
            .withhold
            .as_ref()
            .filter(|w| Some(&w.topic) == self.reference.as_ref());
        let outages = |w: &Withhold| match &w.outages {
            Some(o) => format!("in the outages {}", o.text),
            None => "over the whole run".to_owned(),
        };
        match (self.objective.kind, withheld, &self.reference) {
            (ObjectiveKind::Rmse, Some(w), _) => format!(
                "position and speed RMSE against the fixes of {} withheld from the pipeline {} \
                 (cross-validation)",
                w.topic,
                outages(w)
            ),
            (ObjectiveKind::Nll, Some(w), _) => format!(
                "negative log-likelihood of the fixes of {} withheld from the pipeline {}, as \
                 its states predicted them (held out)",
                w.topic,
                outages(w)
            ),
            (ObjectiveKind::Rmse, None, Some(r)) => format!("position and speed RMSE against {r}"),
            _ => "negative log-likelihood of the innovations of every fused measurement".into(),
        }
    }

    /// The file's own values.
    pub fn start(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.start).collect()
    }

    /// The pipeline with `values`.
    pub fn spec_with(&self, values: &[f64]) -> Result<PipelineSpec> {
        self.config.spec_with(&self.params, values)
    }

    /// Replays every log with `values` (the logs in parallel) and scores them.
    pub fn evaluate(&self, values: &[f64]) -> Result<Evaluation> {
        let spec = self.spec_with(values)?;
        let logs = self
            .recordings
            .par_iter()
            .map(|r| r.replay(&spec))
            .collect::<Result<Vec<_>>>()?;
        let mut pooled = Score::default();
        logs.iter().for_each(|s| pooled.merge(s));
        Ok(Evaluation {
            objective: self.objective.value(&pooled),
            logs,
            pooled,
        })
    }

    /// The objective at `values`; a candidate the configuration refuses scores infinity.
    fn objective_at(&self, values: &[f64]) -> Result<f64> {
        match self.evaluate(values) {
            Ok(e) => Ok(e.objective),
            Err(
                e @ Error::Refuse(
                    RefuseError::ConfigInvalid { .. } | RefuseError::ConfigSyntax { .. },
                ),
            ) => {
                self.invalid.fetch_add(1, Ordering::Relaxed);
                self.first_invalid
                    .lock()
                    .expect("lock")
                    .get_or_insert_with(|| e.to_string());
                Ok(f64::INFINITY)
            }
            Err(e) => Err(e),
        }
    }

    /// Searches, then writes the best values into the configuration text.
    pub fn run(
        &self,
        stop: Option<&AtomicBool>,
        progress: Option<&(dyn Fn(SearchProgress) + Sync)>,
    ) -> Result<TuneOutcome> {
        let started_unix_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        let start = self.start();
        let before = self.evaluate(&start)?;
        let values_of = |u: &[f64]| -> Vec<f64> {
            self.params
                .iter()
                .zip(u)
                .map(|(p, &u)| p.from_unit(u))
                .collect()
        };
        let objective = |values: &[f64]| self.objective_at(values);
        let book = Evaluations::new(&values_of, &objective, self.budget, stop, progress);
        book.record(start.clone(), before.objective);
        let settings = SearchSettings {
            optimiser: self.optimiser,
            steps: self.params.iter().map(|p| p.steps).collect(),
            start: self.params.iter().map(|p| p.to_unit(p.start)).collect(),
            seed: self.seed,
        };
        let started = Instant::now();
        let (ending, em_answer, em_log_likelihood) = match &self.em {
            // EM's answer is its last iterate (the likelihood's maximum), whatever the objective
            // says of the iterates on the way.
            Some(em) => {
                let (ending, values, ll) = self.run_em(em, &start, &book)?;
                (ending, Some(values), Some(ll))
            }
            None => (search::search(&settings, &book)?, None, None),
        };
        let search_s = started.elapsed().as_secs_f64();
        let (trace, best) = book.finish();
        let best = em_answer.unwrap_or_else(|| best.map_or(start.clone(), |b| b.values));
        let after = self.evaluate(&best)?;
        let tuned_toml = self.tuned_text(&best)?;
        let evaluations = trace.len();
        let report = TuneReport {
            config: self.config.path.clone(),
            pipeline: self.config.pipeline.clone(),
            objective: self.objective,
            objective_basis: self.objective_basis(),
            reference: self.reference.clone(),
            optimiser: self.optimiser,
            objective_before: before.objective,
            objective_after: after.objective,
            params: self.param_reports(&best),
            before: before.pooled.metrics(),
            after: after.pooled.metrics(),
            logs: self.log_reports(&before, &after),
            evaluations,
            started_unix_ns,
            ending,
            search_s,
            evaluations_per_s: (evaluations.saturating_sub(1)) as f64 / search_s.max(1e-9),
            threads: rayon::current_num_threads(),
            em_log_likelihood,
            invalid_candidates: self.invalid.load(Ordering::Relaxed),
            first_invalid: self.first_invalid.lock().expect("lock").clone(),
        };
        Ok(TuneOutcome {
            report,
            trace,
            tuned_toml,
        })
    }

    /// EM on the pipeline's own model, each iterate booked as an evaluation: how it ended, its
    /// answer (rounded to the parameters' steps) and its log-likelihood at each iteration.
    fn run_em(
        &self,
        em: &em::PipelineEm,
        start: &[f64],
        book: &Evaluations<'_>,
    ) -> Result<(Ending, Vec<f64>, Vec<f64>)> {
        let units = |v: &[f64]| -> Vec<f64> {
            self.params
                .iter()
                .zip(v)
                .map(|(p, &v)| p.to_unit(v))
                .collect()
        };
        let mut ending = Ending::Converged;
        let (values, ll) = em.run(&self.params, start, self.budget - 1, |v| {
            book.batch(&[units(v)]).map(|_| ()).inspect_err(|e| {
                ending = match e {
                    Error::Interrupted => Ending::Interrupted,
                    _ => Ending::Budget,
                }
            })
        })?;
        let rounded = self
            .params
            .iter()
            .zip(&values)
            .map(|(p, &v)| p.round(v))
            .collect();
        Ok((ending, rounded, ll))
    }

    /// Each parameter's bounds, start and tuned value.
    fn param_reports(&self, best: &[f64]) -> Vec<ParamReport> {
        self.params
            .iter()
            .zip(best)
            .map(|(p, &after)| ParamReport {
                name: p.path.to_string(),
                min: p.min,
                max: p.max,
                scale: p.scale,
                before: p.start,
                after,
                on_bound: p.on_bound(after),
            })
            .collect()
    }

    /// The configuration text with `values` written in, comments kept.
    pub fn tuned_text(&self, values: &[f64]) -> Result<String> {
        let mut c = self.config.clone();
        c.set(&self.params, values)?;
        Ok(c.text())
    }
}

/// `PATH=MIN..MAX[,log|,linear][,steps=N]` (the `--params` syntax).
pub fn parse_param_arg(arg: &str) -> std::result::Result<(String, ParamBounds), String> {
    let bad = |why: &str| {
        format!("--params '{arg}': {why} (expected PATH=MIN..MAX[,log|,linear][,steps=N])")
    };
    let (path, rest) = arg.split_once('=').ok_or_else(|| bad("no '='"))?;
    let mut parts = rest.split(',');
    let range = parts.next().unwrap_or_default();
    let (min, max) = range.split_once("..").ok_or_else(|| bad("no MIN..MAX"))?;
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .map_err(|_| bad(&format!("'{s}' is not a number")))
    };
    let mut b = ParamBounds {
        min: number(min)?,
        max: number(max)?,
        scale: None,
        steps: None,
    };
    for option in parts {
        match option.trim() {
            "log" => b.scale = Some(Scale::Log),
            "linear" => b.scale = Some(Scale::Linear),
            s => match s.strip_prefix("steps=").map(str::parse::<usize>) {
                Some(Ok(n)) => b.steps = Some(n),
                _ => return Err(bad(&format!("unknown option '{s}'"))),
            },
        }
    }
    Ok((path.trim().to_owned(), b))
}

/// The trace as CSV: evaluation, elapsed time, objective, best so far, then each parameter.
pub fn write_trace_csv(
    out: impl std::io::Write,
    params: &[Param],
    trace: &[TraceRow],
) -> csv::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let mut header = vec![
        "evaluation".to_owned(),
        "elapsed_s".into(),
        "objective".into(),
        "best".into(),
    ];
    header.extend(params.iter().map(|p| p.path.to_string()));
    w.write_record(&header)?;
    for r in trace {
        let mut row = vec![
            r.evaluation.to_string(),
            format!("{:.6}", r.elapsed_s),
            r.objective.to_string(),
            r.best.to_string(),
        ];
        row.extend(r.values.iter().map(f64::to_string));
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}

/// The trace as an MCAP log `viz` shows: one `railfuse.TuneEvaluation` per evaluation on
/// `/tune/<pipeline>/trace`, stamped by when it was entered, and the report as metadata.
pub fn write_trace_mcap(
    path: &std::path::Path,
    report: &TuneReport,
    trace: &[TraceRow],
) -> Result<()> {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::{TuneEvaluation, TunedValue};
    let finite = |x: f64| x.is_finite().then_some(x);
    let mut w = LogWriter::create(path)?;
    let channel =
        w.add_channel::<TuneEvaluation>(&railfuse_catalog::topics::tune_trace(&report.pipeline))?;
    let mut last = 0;
    for r in trace {
        // A batch is entered at one instant: 1 µs apart keeps its evaluations in order.
        let stamp_ns = (report.started_unix_ns + (r.elapsed_s * 1e9) as u64).max(last + 1000);
        last = stamp_ns;
        let m = TuneEvaluation {
            stamp_ns,
            evaluation: r.evaluation as u64,
            objective: finite(r.objective),
            best: finite(r.best),
            values: report
                .params
                .iter()
                .zip(&r.values)
                .map(|(p, &value)| TunedValue {
                    name: p.name.clone(),
                    value,
                })
                .collect(),
        };
        w.write(channel, stamp_ns, &m)?;
    }
    let json = serde_json::to_string(report).expect("a report serialises");
    w.write_metadata(
        "railfuse.tune",
        std::collections::BTreeMap::from([
            ("pipeline".to_owned(), report.pipeline.clone()),
            ("report".to_owned(), json),
        ]),
    )?;
    w.finish()?;
    Ok(())
}
