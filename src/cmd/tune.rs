//! `railfuse tune`: choose a pipeline's noise values over one or many logs.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{Context, Result};
use railfuse_refuse::config::{value_names, ObjectiveKind, OptimiserKind};
use railfuse_tune::recording::Metrics;
use railfuse_tune::search::SearchProgress;
use railfuse_tune::{
    write_trace_csv, write_trace_mcap, TuneOutcome, TuneReport, TuneRequest, Tuner,
};

use super::run_input::WithholdArgs;
use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The runs to tune on, each a file, a directory of its parts or a ROS 2 bag (raw or
    /// fused): the objective is pooled over all of them.
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// The pipeline configuration (TOML) holding the pipeline.
    #[arg(short, long)]
    pub config: PathBuf,
    #[command(flatten)]
    pub formats: super::run_input::FormatArgs,
    /// The pipeline to tune.
    #[arg(long)]
    pub pipeline: String,
    /// Reference topic (ground truth, an RTK GNSS channel, another pipeline's state or
    /// smoothed states); without one (and none in [pipeline.tune]) the innovations'
    /// likelihood is minimised.
    #[arg(long)]
    pub reference: Option<String>,
    /// A value to tune, `PATH=MIN..MAX[,log|,linear][,steps=N]`, e.g.
    /// `motion.jerk_psd=0.001..10` or `sensor[/radar/speed].variance=1e-4..1` (repeat it; these
    /// add to and override [pipeline.tune.params]).
    #[arg(long = "params", value_name = "PATH=MIN..MAX")]
    pub params: Vec<String>,
    #[arg(long, value_parser = parse_enum::<ObjectiveKind>, help = format!(
        "What to minimise: {} (rmse against the reference; nll the innovations' negative \
         log-likelihood)", value_names(ObjectiveKind::ALL).join(", ")))]
    pub objective: Option<ObjectiveKind>,
    #[arg(long, value_parser = parse_enum::<OptimiserKind>, help = format!(
        "The search: {} (nelder_mead the default; - and _ alike, here and in the TOML)",
        value_names(OptimiserKind::ALL).join(", ")))]
    pub optimiser: Option<OptimiserKind>,
    /// The most evaluations (replays of every log); default 200, a grid's point count.
    #[arg(long, value_parser = at_least_one)]
    pub max_evals: Option<usize>,
    /// Seed of the particle swarm.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: every core).
    #[arg(long, value_parser = at_least_one)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub withhold: WithholdArgs,
    /// The tuned configuration: the input file with only the tuned values changed.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The convergence trace as CSV (default: OUTPUT with `.trace.csv`).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// The convergence trace as an MCAP log for `railfuse viz` (default: OUTPUT with
    /// `.trace.mcap`).
    #[arg(long)]
    pub trace_mcap: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// A count that must be at least 1 (threads, evaluations).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

/// A config enum from its snake_case name (`nelder-mead` as well as `nelder_mead`).
fn parse_enum<T: serde::de::DeserializeOwned>(s: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(s.replace('-', "_")))
        .map_err(|e| e.to_string())
}

pub fn run(a: Args) -> Result<()> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = a.threads {
        pool = pool.num_threads(n);
    }
    pool.build()
        .context("tune: starting the worker threads")?
        .install(|| tune(&a))
}

fn tune(a: &Args) -> Result<()> {
    // Every output can be written before the search runs, and none is written until all are.
    for path in [a.output.clone(), trace_csv_path(a), trace_mcap_path(a)] {
        super::check_writable(&path)?;
    }
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // The second Ctrl-C ends at once; the first ends the search with the best so far.
        signal_hook::flag::register_conditional_shutdown(signal, 1, stop.clone())?;
        signal_hook::flag::register(signal, stop.clone())?;
    }
    let request = TuneRequest {
        config: a.config.clone(),
        pipeline: a.pipeline.clone(),
        logs: a.logs.clone(),
        reference: a.reference.clone(),
        params: a.params.clone(),
        objective: a.objective,
        optimiser: a.optimiser,
        max_evaluations: a.max_evals,
        seed: a.seed,
        withhold: a.withhold.request(),
        formats: a.formats.options()?,
    };
    let loading = crate::progress::Progress::steps("decoding logs", a.logs.len() as u64);
    let tuner = Tuner::open(&request)?;
    loading.finish();
    for warning in tuner.recordings.iter().flat_map(|r| &r.missing_sensors) {
        eprintln!("warning: {warning}");
    }
    if tuner.noise_values {
        let names: Vec<String> = tuner.params.iter().map(|p| p.path.to_string()).collect();
        crate::say!(
            "no --params: tuning the pipeline's noise values over 1/100 … 100 × each: {}",
            names.join(", ")
        );
    }
    let bar = crate::progress::Progress::steps("tune", tuner.budget as u64);
    let progress = |p: SearchProgress| {
        let rate = p.evaluations as f64 / p.elapsed_s.max(1e-9);
        bar.set_with(
            p.evaluations as u64,
            &format!("tune: best {:.6}, {rate:.1} evaluations/s", p.best),
        );
    };
    let outcome = tuner.run(Some(&stop), Some(&progress))?;
    bar.finish();
    write_outputs(a, &tuner, &outcome)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&outcome.report)?);
    } else {
        print_report(a, &outcome);
    }
    Ok(())
}

fn trace_csv_path(a: &Args) -> PathBuf {
    a.trace
        .clone()
        .unwrap_or_else(|| a.output.with_extension("trace.csv"))
}

fn write_outputs(a: &Args, tuner: &Tuner, outcome: &TuneOutcome) -> Result<()> {
    std::fs::write(&a.output, &outcome.tuned_toml)
        .with_context(|| format!("{}: writing the tuned configuration", a.output.display()))?;
    let trace = trace_csv_path(a);
    let file = std::fs::File::create(&trace)
        .with_context(|| format!("{}: writing the trace", trace.display()))?;
    write_trace_csv(std::io::BufWriter::new(file), &tuner.params, &outcome.trace)
        .with_context(|| format!("{}: writing the trace", trace.display()))?;
    write_trace_mcap(&trace_mcap_path(a), &outcome.report, &outcome.trace)?;
    Ok(())
}

fn trace_mcap_path(a: &Args) -> PathBuf {
    a.trace_mcap
        .clone()
        .unwrap_or_else(|| a.output.with_extension("trace.mcap"))
}

fn print_report(a: &Args, o: &TuneOutcome) {
    let r = &o.report;
    let objective = match r.objective.kind {
        ObjectiveKind::Rmse => format!(
            "{} x position RMSE + {} x speed RMSE: {}",
            r.objective.position_weight, r.objective.speed_weight, r.objective_basis
        ),
        ObjectiveKind::Nll => r.objective_basis.clone(),
    };
    println!(
        "tuned pipeline '{}' of {} over {} log(s): {objective}",
        r.pipeline,
        r.config.display(),
        r.logs.len()
    );
    println!(
        "{:?} search: {} evaluations in {:.2} s ({:.1}/s on {} threads), {:?}; objective {:.6} -> {:.6}",
        r.optimiser,
        r.evaluations,
        r.search_s,
        r.evaluations_per_s,
        r.threads,
        r.ending,
        r.objective_before,
        r.objective_after
    );
    print!("{}", params_table(r));
    print!("{}", logs_table(r));
    if r.invalid_candidates > 0 {
        println!(
            "{} candidates were refused by the configuration's checks (scored as infinitely bad); the first: {}",
            r.invalid_candidates,
            r.first_invalid.as_deref().unwrap_or("-")
        );
    }
    let trace = a
        .trace
        .clone()
        .unwrap_or_else(|| a.output.with_extension("trace.csv"));
    println!(
        "wrote {} and the trace {} and {} (railfuse viz shows it)",
        a.output.display(),
        trace.display(),
        trace_mcap_path(a).display()
    );
}

/// Each tuned value: its bounds, scale, start and result.
fn params_table(r: &TuneReport) -> Table {
    let mut t = Table::new(&[
        "parameter",
        "min",
        "max",
        "scale",
        "before",
        "after",
        "on a bound",
    ]);
    for p in &r.params {
        t.row(vec![
            p.name.clone(),
            p.min.to_string(),
            p.max.to_string(),
            format!("{:?}", p.scale).to_lowercase(),
            p.before.to_string(),
            p.after.to_string(),
            if p.on_bound { "yes" } else { "" }.to_owned(),
        ]);
    }
    t
}

/// Each log's figures before and after (and all logs pooled, when there are several).
fn logs_table(r: &TuneReport) -> Table {
    let mut t = Table::new(&[
        "log",
        "",
        "pos RMSE m",
        "pos max m",
        "speed RMSE m/s",
        "NEES in 95%",
        "NIS in 95%",
        "NIS mean",
        "NLL",
        "gated",
    ]);
    let row = |t: &mut Table, name: String, when: &str, m: &Metrics| {
        let f = |x: Option<f64>, d: usize| x.map_or("-".to_owned(), |x| format!("{x:.d$}"));
        let pct = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{:.1}%", 100.0 * x));
        t.row(vec![
            name,
            when.to_owned(),
            f(m.position_rmse_m, 3),
            f(m.position_max_m, 3),
            f(m.speed_rmse_mps, 4),
            pct(m.nees_inside_95),
            pct(m.nis_inside_95),
            f(m.nis_mean, 2),
            f(m.nll, 1),
            m.gated.to_string(),
        ]);
    };
    for l in &r.logs {
        let name = l.path.display().to_string();
        row(&mut t, name, "before", &l.before);
        row(&mut t, String::new(), "after", &l.after);
    }
    if r.logs.len() > 1 {
        row(&mut t, "all logs".into(), "before", &r.before);
        row(&mut t, String::new(), "after", &r.after);
    }
    t
}
