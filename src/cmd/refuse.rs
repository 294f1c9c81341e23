use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use railfuse_catalog::topics;
use railfuse_eval::outages::Withhold;
use railfuse_eval::{EvalReport, FixQuality, Reference};
use railfuse_refuse::registry::Registry;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use railfuse_refuse::default_config::default_config;
use railfuse_refuse::replay::{refuse, Observer, RefuseOptions, RefuseReport};
use railfuse_refuse::spec::Pipelines;

use super::eval::print_eval;
use super::measure::{peak_rss_kib, RunStats};
use super::run_input::{RunArgs, SplitArgs, WithholdArgs};
use railfuse_catalog::run::Run;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub run: RunArgs,
    /// Pipeline configuration (TOML); see samples/kalman.toml. Without one, a default
    /// pipeline is picked from what the log's topics decode to, and which topics it used and
    /// why it left the others out is printed.
    #[arg(short, long)]
    pub config: Option<PathBuf>,
    /// The track (GeoJSON line or CSV of latitude/longitude) for the default pipeline, on
    /// which GNSS fixes give chainage, when the log has none. A configuration names its own
    /// at its top (`track = "line.geojson"`).
    #[arg(long, conflicts_with = "config")]
    pub track: Option<PathBuf>,
    /// Write the default pipeline's configuration here, to edit and pass with --config.
    #[arg(long, conflicts_with = "config", value_name = "FILE")]
    pub save_config: Option<PathBuf>,
    /// The train (a TOML file's `[vehicle]` table, as `railfuse calibrate` writes it): wins
    /// over the configuration's `[vehicle]` and the log's `/vehicle`.
    #[arg(long, value_name = "FILE")]
    pub vehicle: Option<PathBuf>,
    /// The probability that each pipeline's safe front end interval (`/fused/<name>/train`,
    /// the min and max safe front end) holds the true front end: wins over the
    /// configuration's `confidence` (default 0.9999, ±3.89 σ).
    #[arg(long, value_name = "P")]
    pub confidence: Option<f64>,
    /// The output MCAP log: every input record plus the fused channels. May be the input
    /// itself: it is replaced only once the new file is complete.
    #[arg(short, long, required_unless_present = "config_schema")]
    pub output: Option<PathBuf>,
    /// The output in parts (OUTPUT-001.mcap, …), as `merge` writes them.
    #[command(flatten)]
    pub split: SplitArgs,
    /// Reference trajectory for the accuracy table (ground truth, another pipeline's state or
    /// a GNSS fix channel). Without it, the ground truth (`/truth`) where the log has one.
    #[arg(long)]
    pub reference: Option<String>,
    /// Which fixes of a GNSS reference count: auto (RTK fixed where it has any, else all),
    /// all, or fix types (rtk_fixed, rtk_float, dgps, single; commas between several).
    #[arg(long, value_name = "QUALITY", default_value = "auto")]
    pub reference_quality: FixQuality,
    #[command(flatten)]
    pub withhold: WithholdArgs,
    /// Print the report as JSON (with wall time, throughput and peak memory).
    #[arg(long)]
    pub json: bool,
    /// Stream the fused channels, and what the pipelines read, to a Rerun viewer while
    /// re-fusing: `spawn` starts one, or give a viewer URL (rerun+http://127.0.0.1:9876/proxy).
    /// A viewer that goes away is reported once; the re-fusion goes on.
    #[arg(long, value_name = "spawn|URL")]
    pub viz: Option<String>,
    /// Print the JSON schema of the configuration file and exit: an editor that reads JSON
    /// schemas for TOML (Taplo, Even Better TOML) then completes and checks a configuration.
    #[arg(long, exclusive = true)]
    pub config_schema: bool,
}

pub fn run(a: Args) -> Result<()> {
    if a.config_schema {
        let schema = railfuse_refuse::config_reference::schema(&Registry::standard());
        println!("{}", serde_json::to_string_pretty(&schema)?);
        return Ok(());
    }
    let Some(output) = a.output.as_deref() else {
        anyhow::bail!("refuse needs an input log and -o OUTPUT");
    };
    let loaded = match &a.config {
        Some(path) => Some((Pipelines::load(path)?, path.display().to_string())),
        None => None,
    };
    let run = match &loaded {
        Some((c, _)) => a.run.open_with(&c.clock_offsets, c.align)?,
        None => a.run.open()?,
    };
    let input = &run;
    let rule = a.split.rule(input)?;
    // A split output is written whole first, then cut into its parts.
    let whole = match rule.splits() {
        true => output.with_extension("whole.mcap.partial"),
        false => output.to_owned(),
    };
    let (mut config, source) = match loaded {
        Some(loaded) => loaded,
        None => default_pipeline(input, a.track.as_deref(), a.save_config.as_deref())?,
    };
    if let Some(vehicle) = &a.vehicle {
        let unread = config.set_vehicle_from(vehicle)?;
        leave_aside(vehicle, &unread, input)?;
    }
    if config.vehicle.is_none() {
        place_from_tf(&mut config, input)?;
    }
    if let Some(c) = a.confidence {
        config.confidence = railfuse_refuse::spec::check_confidence(c)
            .map_err(|e| anyhow::anyhow!("--confidence {e}"))?;
    }
    let (reference, withhold) = scoring(&a, &config, input)?;
    let live = match &a.viz {
        Some(target) => Some(LiveView::open(target)?),
        None => None,
    };
    let observer = live.as_ref().map(LiveView::observer);
    let (report, eval, stats) = refuse_with(
        input,
        &whole,
        &config,
        source,
        (&reference, withhold.as_ref()),
        observer.as_ref().map(|o| o as Observer<'_>),
    )?;
    drop(observer);
    if let Some(live) = live {
        live.finish();
    }
    let parts = match rule.splits() {
        true => Some(split_output(&whole, output, rule)?),
        false => None,
    };
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({ "refuse": report, "eval": eval, "run": stats, "parts": parts })
            )?
        );
    } else {
        print_eval(&eval);
        print_counts(&report);
    }
    // The fused log is written; the table the user asked for could not be made.
    super::eval::check_reference_used(input, a.reference.as_deref(), &eval)
}

/// Cuts the fused log `whole` into the parts of `output` by `rule`, then removes it.
fn split_output(
    whole: &Path,
    output: &Path,
    rule: railfuse_catalog::log::SplitRule,
) -> Result<Vec<PathBuf>> {
    let written = railfuse_catalog::run::merge(
        &Run::file(whole),
        output,
        rule,
        &railfuse_catalog::log::WriterOptions::default(),
    );
    let written = match written {
        Ok(r) => r,
        Err(e) => anyhow::bail!("{e} (the whole fused log is kept in {})", whole.display()),
    };
    std::fs::remove_file(whole).map_err(|e| anyhow::anyhow!("{}: {e}", whole.display()))?;
    crate::say!(
        "fused log in {} parts: {}",
        written.outputs.len(),
        written
            .outputs
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(written.outputs)
}

/// For a configuration without `[vehicle]` on a ROS recording with a `/tf_static` and no
/// `/vehicle`: the train the transforms place, each sensor a pipeline reads at its frame,
/// said in one line with what was assumed.
fn place_from_tf(config: &mut Pipelines, input: &Run) -> Result<()> {
    let channels = railfuse_refuse::default_config::channels(input)?;
    let topics = config.read_topics();
    let Some((v, notes)) = railfuse_refuse::default_config::tf_vehicle(input, &channels, &topics)?
    else {
        return Ok(());
    };
    let placed: Vec<String> = v
        .sensors
        .iter()
        .map(|s| format!("{} at {}", s.topic, s.frame_id.as_deref().unwrap_or("?")))
        .collect();
    let notes = notes.iter().map(|n| format!("; {n}")).collect::<String>();
    crate::say!(
        "{}: the train from /tf_static: {} ({:.1} m long){notes}",
        input.name().display(),
        if placed.is_empty() {
            "no sensor a pipeline reads has a frame".to_owned()
        } else {
            placed.join(", ")
        },
        v.length_m
    );
    config.vehicle = Some(v);
    Ok(())
}

/// The sensors a `--vehicle` file places that no pipeline reads: those on a channel of the
/// run are the train's others, left aside in one line; one the run does not have either is a
/// misspelt topic, which would leave the sensor it meant at the front end: refused.
fn leave_aside(vehicle: &Path, unread: &[String], input: &Run) -> Result<()> {
    if unread.is_empty() {
        return Ok(());
    }
    let reader = input.reader()?;
    let channels = reader.summary().and_then(|s| s.channels.as_ref());
    if let Some(channels) = channels {
        if let Some(t) = unread
            .iter()
            .find(|t| !channels.iter().any(|c| &c.topic == *t))
        {
            anyhow::bail!(
                "{}: [vehicle]: sensor '{t}' is on no channel of the run and no pipeline reads it \
                 (a misspelt topic?)",
                vehicle.display()
            );
        }
    }
    eprintln!(
        "{}: {} placed on the train, read by no pipeline of the configuration: left aside",
        vehicle.display(),
        unread.join(", ")
    );
    Ok(())
}

/// The default pipeline of a log given no configuration, with what it used and left out said
/// on stderr (and its configuration written to `save`, when given).
fn default_pipeline(
    input: &Run,
    track: Option<&Path>,
    save: Option<&Path>,
) -> Result<(Pipelines, String)> {
    let default = default_config(input, track)?;
    let path = match save {
        Some(path) => {
            std::fs::write(path, &default.text)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            path.to_owned()
        }
        None => PathBuf::from(format!("{} (default pipeline)", input.display())),
    };
    let config = default.pipelines(&path)?;
    crate::say!(
        "no --config: re-fusing with a default pipeline '{}' (Kalman, constant acceleration){}",
        railfuse_refuse::default_config::NAME,
        match save {
            Some(p) => format!("; its configuration is in {}", p.display()),
            None => "; --save-config FILE writes it to edit".to_owned(),
        }
    );
    for t in &default.used {
        crate::say!("  uses {}: {}", t.topic, t.why);
    }
    for t in &default.left_out {
        crate::say!("  leaves out {}: {}", t.topic, t.why);
    }
    Ok((config, path.display().to_string()))
}

/// A viewer fed as the replay goes (`--viz`).
struct LiveView {
    viz: Mutex<railfuse_viz::LiveViz>,
    failed: AtomicBool,
}

impl LiveView {
    fn open(target: &str) -> Result<Self> {
        let sink = railfuse_viz::Sink::live(target);
        Ok(LiveView {
            viz: Mutex::new(railfuse_viz::LiveViz::open(&sink, &Default::default())?),
            failed: AtomicBool::new(false),
        })
    }

    fn observer(&self) -> impl Fn(&str, &str, u64, &[u8]) + Sync + '_ {
        move |topic, schema, log_time_ns, json| {
            if self.failed.load(Ordering::Relaxed) {
                return;
            }
            let sent = match self.viz.lock() {
                Ok(mut viz) => viz.message(topic, schema, log_time_ns, json),
                Err(_) => return,
            };
            // A viewer that goes away must not stop the re-fusion: say so once.
            if let Err(e) = sent {
                eprintln!("\nviewer: {e}; re-fusing continues without it");
                self.failed.store(true, Ordering::Relaxed);
            }
        }
    }

    fn finish(self) {
        if self.failed.load(Ordering::Relaxed) {
            return;
        }
        if let Ok(mut viz) = self.viz.into_inner() {
            if let Err(e) = viz.finish() {
                eprintln!("viewer: {e}");
            }
        }
    }
}

pub fn refuse_with(
    input: &Run,
    output: &Path,
    config: &Pipelines,
    source: String,
    (reference, withhold): (&Reference, Option<&Withhold>),
    observer: Option<Observer<'_>>,
) -> Result<(RefuseReport, EvalReport, RunStats)> {
    let started = Instant::now();
    let bar = crate::progress::Progress::bytes("refuse", input.total_bytes());
    let progress = |done: u64| bar.set(done);
    let (report, eval) = refuse(&RefuseOptions {
        run: input,
        output,
        config,
        config_source: source,
        reference,
        withhold,
        progress: Some(&progress),
        observer,
    })?;
    bar.finish();
    let elapsed_s = started.elapsed().as_secs_f64();
    let stats = RunStats {
        elapsed_s,
        input_messages_per_s: report.input_messages as f64 / elapsed_s,
        peak_rss_kib: peak_rss_kib(),
    };
    crate::say!(
        "re-fused {} messages of {} in {:.2} s ({:.0} msg/s), wrote {} fused messages -> {}",
        report.input_messages,
        input.display(),
        elapsed_s,
        stats.input_messages_per_s,
        report.fused_messages,
        output.display()
    );
    for line in report
        .undecodable
        .lines()
        .iter()
        .chain(&report.missing_sensors)
    {
        eprintln!("warning: {line}");
    }
    for (reason, n) in &report.skipped {
        eprintln!("note: {n} messages skipped: {reason}");
    }
    if let Some(can) = &report.can {
        print_can(can);
    }
    if report.merge.duplicates_dropped > 0 {
        eprintln!(
            "note: {} messages were in two files of the run (a split boundary): read once",
            report.merge.duplicates_dropped
        );
    }
    if report.out_of_order_messages > 0 {
        eprintln!(
            "note: {} messages are earlier in log time than the one before them in the file",
            report.out_of_order_messages
        );
    }
    Ok((report, eval, stats))
}

/// What the sensors made from the CAN bus made, and what of the bus they could not read.
fn print_can(can: &railfuse_catalog::foreign::can::BridgeCounts) {
    let made: Vec<String> = can.made.iter().map(|(t, n)| format!("{t} {n}")).collect();
    eprintln!(
        "made from the CAN bus: {}",
        match made.is_empty() {
            true => "nothing (no frame of a mapped message)".to_owned(),
            false => made.join(", "),
        }
    );
    let counted = [
        ("frames of ids not in the DBC", &can.unknown_ids),
        ("frames shorter than their message", &can.too_short),
        (
            "mapped signals outside their DBC range (left out)",
            &can.out_of_range,
        ),
        (
            "mapped signals not a finite number (left out)",
            &can.not_finite,
        ),
    ];
    for (what, by) in counted.iter().filter(|(_, by)| !by.is_empty()) {
        let total: u64 = by.values().sum();
        let first: Vec<String> = by
            .iter()
            .take(5)
            .map(|(k, n)| format!("{k} ×{n}"))
            .collect();
        eprintln!("note: {total} {what}: {}", first.join(", "));
    }
}

/// What each pipeline did with its measurements (the gate counts are in the accuracy table).
pub fn print_counts(report: &RefuseReport) {
    for p in &report.pipelines {
        let c = &p.counts;
        println!(
            "{}: {} accepted, {} after a gate lockout, {} resets to a fix, {} gated, {} invalid, {} late, {} from failed devices, {} before initialisation",
            p.name,
            c.accepted,
            c.accepted_after_lockout,
            c.resets_to_fix,
            c.rejected_gate,
            c.rejected_invalid,
            c.rejected_late,
            c.rejected_device_fault,
            c.before_initialisation
        );
        if let Some(line) = &p.report {
            println!("{}: {line}", p.name);
        }
    }
}

/// What the run is scored against, and the sensor withheld from the pipelines if any: the
/// command line's, checked against the log before any work. With a sensor withheld (here
/// or in a pipeline's `[pipeline.eval]`) it is the reference unless `--reference` says
/// otherwise.
fn scoring(a: &Args, config: &Pipelines, input: &Run) -> Result<(Reference, Option<Withhold>)> {
    let withhold = a.withhold.request();
    let withheld_topic = withhold.as_ref().map(|w| w.topic.clone()).or_else(|| {
        config
            .pipeline
            .iter()
            .find_map(|p| Some(p.withhold.as_ref()?.topic.clone()))
    });
    let reference = Reference {
        topic: a
            .reference
            .clone()
            .or(withheld_topic)
            .unwrap_or(topics::GROUND_TRUTH.to_owned()),
        quality: a.reference_quality.clone(),
    };
    if let Some(w) = &withhold {
        super::eval::check_channel_in_log(input, &w.topic, "to withhold")?;
    }
    if a.reference.is_some() || reference.topic != topics::GROUND_TRUTH {
        super::eval::check_reference_in_log(input, &reference.topic)?;
    }
    Ok((reference, withhold))
}

/// Re-fuses and prints the accuracy table of the result (demo).
pub fn refuse_and_evaluate(
    input: &Path,
    output: &Path,
    config: &Pipelines,
    source: String,
    reference: &Reference,
) -> Result<(RefuseReport, EvalReport)> {
    let run = Run::file(input);
    let (report, eval, _) = refuse_with(&run, output, config, source, (reference, None), None)?;
    print_eval(&eval);
    Ok((report, eval))
}
