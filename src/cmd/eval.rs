use anyhow::Result;
use railfuse_catalog::foreign::ForeignChannels;
use railfuse_catalog::reference_track::MAX_GAP_PERIODS;
use railfuse_catalog::run::Run;
use railfuse_catalog::topics;
use railfuse_eval::accuracy::{ConsistencySummary, ErrorSummary};
use railfuse_eval::fix_match::{FixMatchReport, MAX_STATE_GAP_NS};
use railfuse_eval::safety::SafetyEval;
use std::sync::Arc;

use railfuse_catalog::log::{read_metadata, ChannelInfo};
use railfuse_eval::outages::Withheld;
use railfuse_eval::{evaluate, reference_kind, EvalReport, FixQuality, Reference};

use super::run_input::{RunArgs, WithholdArgs};
use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// A fused log (the output of `railfuse refuse`), or every file of a fused run.
    #[command(flatten)]
    pub run: RunArgs,
    /// The reference: the ground-truth channel, another pipeline's state
    /// (`/fused/<name>/state`) or a GNSS fix channel (an RTK receiver). Without it, the
    /// ground truth (`/truth`) where the log has one, else NIS and counts only.
    #[arg(long)]
    pub reference: Option<String>,
    /// Which fixes of a GNSS reference count: auto (RTK fixed where it has any, else all),
    /// all, or fix types (rtk_fixed, rtk_float, dgps, single; commas between several).
    #[arg(long, value_name = "QUALITY", default_value = "auto")]
    pub reference_quality: FixQuality,
    #[command(flatten)]
    pub withhold: WithholdArgs,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let run = a.run.open()?;
    let outages = given_outages(&run, &a)?;
    // A run fused with a sensor withheld is scored against it unless told otherwise.
    let reference = Reference {
        topic: a
            .reference
            .clone()
            .or(a.withhold.withhold.clone())
            .or_else(|| withheld_topic(&run))
            .unwrap_or(topics::GROUND_TRUTH.to_owned()),
        quality: a.reference_quality,
    };
    if a.reference.is_some() || a.withhold.withhold.is_some() {
        check_reference_in_log(&run, &reference.topic)?;
    }
    let report = evaluate(&run, &reference, outages.as_ref())?;
    if report.pipelines.is_empty() {
        anyhow::bail!(
            "{}: no fused pipelines to evaluate: re-fuse it first (railfuse refuse {} -c CONFIG -o OUT)",
            run.display(),
            run.name().display()
        );
    }
    check_reference_used(&run, a.reference.as_deref(), &report)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_eval(&report);
    }
    Ok(())
}

/// `--withhold TOPIC --outages SPEC` placed in the run's span (log time), checked first.
fn given_outages(run: &Run, a: &Args) -> Result<Option<Withheld>> {
    let Some(w) = a.withhold.request() else {
        return Ok(None);
    };
    check_channel_in_log(run, &w.topic, "to score as withheld")?;
    let span = run.reader()?.summary().and_then(|s| s.message_span_ns);
    w.place(span)
        .map(Some)
        .map_err(|e| anyhow::anyhow!("{}: {e}", run.display()))
}

/// The sensor a fused run's pipelines were not shown (its `railfuse.withheld` record).
fn withheld_topic(run: &Run) -> Option<String> {
    run.parts().iter().find_map(|p| {
        read_metadata(&p.path, topics::metadata::WITHHELD)
            .ok()
            .flatten()?
            .remove("topic")
    })
}

/// A reference named on the command line is in the log and can be a reference (ground truth,
/// a fused state, GNSS fixes of any make): said before any work, where the run's summaries
/// list its channels.
pub fn check_reference_in_log(input: &Run, topic: &str) -> Result<()> {
    let Some(c) = check_channel_in_log(input, topic, "to take as the reference")? else {
        return Ok(());
    };
    let read_as = ForeignChannels::default()
        .channel(c.clone(), None)
        .unwrap_or_else(|_| c.clone());
    if reference_kind(read_as.schema_name()).is_none() {
        anyhow::bail!(
            "{}: {topic} ({}) cannot be a reference: a reference is ground truth, a fused \
             state or a GNSS fix channel (GnssFix, NavSatFix, LocationFix)",
            input.display(),
            c.schema_name()
        );
    }
    Ok(())
}

/// The channel `topic` of the run, where its summaries list its channels; an error saying
/// what it was wanted for where the run lacks it.
pub fn check_channel_in_log(
    input: &Run,
    topic: &str,
    wanted: &str,
) -> Result<Option<Arc<ChannelInfo>>> {
    let reader = input.reader()?;
    let Some(channels) = reader.summary().and_then(|s| s.channels.as_ref()) else {
        return Ok(None);
    };
    if let Some(c) = channels.iter().find(|c| c.topic == topic) {
        return Ok(Some(c.clone()));
    }
    let have: Vec<&str> = channels.iter().map(|c| c.topic.as_str()).collect();
    anyhow::bail!(
        "{}: no channel {topic} {wanted} (it has {})",
        input.display(),
        have.join(", ")
    )
}

/// A reference named on the command line was one the table could use.
pub fn check_reference_used(input: &Run, named: Option<&str>, report: &EvalReport) -> Result<()> {
    match (named, &report.reference) {
        (Some(topic), None) => anyhow::bail!(
            "{}: reference {topic} is not in the log or gives no samples (a reference is ground \
             truth, a fused state, or GNSS fixes on the log's track map)",
            input.display()
        ),
        _ => Ok(()),
    }
}

/// The accuracy table, as eval, refuse and demo print it: one row per pipeline (and per
/// smoothed channel), then one row per marked window it crossed.
pub fn print_eval(report: &EvalReport) {
    let at_fixes = report.pipelines.iter().any(|p| p.reference_fixes.is_some());
    match &report.reference {
        Some(r) if at_fixes => println!(
            "accuracy against {r} (errors = fused − reference, at each reference fix, the \
             states interpolated to its time):"
        ),
        Some(r) => {
            println!("accuracy against {r} (errors = fused − reference, at each fused state):")
        }
        None => println!("no usable reference channel: errors not computed (NIS and counts only)"),
    }
    print!("{}", accuracy_table(report));
    print_outages(report);
    print_plane(report);
    for p in &report.pipelines {
        if let Some(safety) = &p.safety {
            print_safety(&p.name, safety);
        }
    }
    print_safe_front(report);
    for p in &report.pipelines {
        if let Some(f) = &p.reference_fixes {
            println!("{}: {}", p.name, describe_fix_match(f));
        }
        if let Some(e) = &p.across_track_error_m {
            println!(
                "{}: across the track against the fixes (in the plane): RMSE {:.3} m, p95 \
                 {:.3} m, max {:.3} m",
                p.name, e.rmse, e.p95_abs, e.max_abs
            );
        }
        let (gaps, outside) = (p.states_in_reference_gaps, p.unmatched_states);
        if gaps + outside > 0 {
            println!(
                "{}: {} of {} states not scored: {gaps} inside gaps of the reference (samples \
                 more than {MAX_GAP_PERIODS} of its periods apart), {outside} outside its time \
                 span",
                p.name,
                gaps + outside,
                p.states
            );
        }
    }
}

/// How often each pipeline's safe front end interval held the reference, beside the
/// confidence it claims (fewer: the pipeline is surer of itself than it should be).
fn print_safe_front(report: &EvalReport) {
    for p in &report.pipelines {
        let Some(f) = &p.safe_front else { continue };
        let verdict = match f.share >= f.confidence {
            true => "as claimed",
            false => "less often than claimed: its σ is too small",
        };
        println!(
            "{}: the safe front end interval ({:.2} %) held the reference's front end {:.2} % \
             of {} times, {verdict}",
            p.name,
            100.0 * f.confidence,
            100.0 * f.share,
            f.checked
        );
    }
}

/// What matching a pipeline's states to a GNSS reference's fixes gave, in a sentence.
fn describe_fix_match(f: &FixMatchReport) -> String {
    if f.fixes == 0 {
        return format!(
            "no reference fix of quality {} on the track ({} of other quality left out)",
            f.quality, f.other_quality
        );
    }
    if f.matched == 0 && f.in_state_gaps == 0 {
        return format!(
            "none of the {} {} fixes lies inside the span of its states",
            f.fixes, f.quality
        );
    }
    let of = match f.quality.as_str() {
        "all" => "fixes".to_owned(),
        q => format!("{q} fixes"),
    };
    let mut s = format!(
        "{} of {} {of} matched (at most {:.3} s from a state)",
        f.matched, f.fixes, f.largest_dt_s
    );
    if f.in_state_gaps > 0 {
        s += &format!(
            "; {} in gaps of the states (more than {:.0} s apart)",
            f.in_state_gaps,
            MAX_STATE_GAP_NS as f64 / 1e9
        );
    }
    if f.outside_states > 0 {
        s += &format!(
            "; {} before its first state or after its last",
            f.outside_states
        );
    }
    if f.other_quality > 0 {
        s += &format!("; {} fixes of other quality left out", f.other_quality);
    }
    if let Some(why) = &f.no_speed {
        s += &format!("; speed not scored: {why}");
    }
    s
}

/// The whole-run row of each pipeline, its marked windows' rows below it.
fn accuracy_table(report: &EvalReport) -> Table {
    let mut t = Table::new(&[
        "pipeline",
        "filter",
        "states",
        "pos RMSE m",
        "pos p95 m",
        "pos max m",
        "speed RMSE m/s",
        "speed p95 m/s",
        "speed max m/s",
        "NEES in 95%",
        "beyond 3σ",
        "NIS in 95%",
        "gated",
        "resets",
    ]);
    let f = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:.3}"));
    let percent = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{:.1}%", 100.0 * x));
    let share = |c: Option<&ConsistencySummary>| {
        c.map_or("-".to_owned(), |c| format!("{:.1}%", 100.0 * c.inside_95))
    };
    let errors = |pos: Option<&ErrorSummary>, spd: Option<&ErrorSummary>| {
        vec![
            f(pos.map(|e| e.rmse)),
            f(pos.map(|e| e.p95_abs)),
            f(pos.map(|e| e.max_abs)),
            f(spd.map(|e| e.rmse)),
            f(spd.map(|e| e.p95_abs)),
            f(spd.map(|e| e.max_abs)),
        ]
    };
    for p in &report.pipelines {
        let mut row = vec![
            p.name.clone(),
            p.filter.clone().unwrap_or_else(|| "-".into()),
            p.states.to_string(),
        ];
        row.extend(errors(
            p.position_error_m.as_ref(),
            p.speed_error_mps.as_ref(),
        ));
        row.extend([
            share(p.nees.as_ref()),
            percent(p.beyond_3_sigma),
            share(p.nis.as_ref()),
            p.gated.to_string(),
            p.resets_to_fix.to_string(),
        ]);
        t.row(row);
        for w in &p.windows {
            let n = w.position_error_m.as_ref().map_or(0, |e| e.samples);
            let mut row = vec![format!("  in {}", w.label), String::new(), n.to_string()];
            row.extend(errors(
                w.position_error_m.as_ref(),
                w.speed_error_mps.as_ref(),
            ));
            row.extend([
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ]);
            t.row(row);
        }
    }
    t
}

/// The withholding protocol's table: per pipeline and outage length, the error along the
/// track at the outages' ends, the largest inside them and the drift per distance run.
fn print_outages(report: &EvalReport) {
    let with: Vec<_> = report
        .pipelines
        .iter()
        .filter_map(|p| Some((p, p.outages.as_ref()?)))
        .collect();
    if with.is_empty() {
        return;
    }
    let topics: std::collections::BTreeSet<&str> = with
        .iter()
        .filter_map(|(p, _)| p.withheld.as_deref())
        .collect();
    println!(
        "outages of {} (errors along the track over the outages: RMS, 95th percentile, \
         maximum):",
        topics.into_iter().collect::<Vec<_>>().join(", ")
    );
    let mut t = Table::new(&[
        "pipeline",
        "outage s",
        "outages",
        "end RMS m",
        "end p95 m",
        "end max m",
        "inside max m",
        "drift RMS %",
        "drift max %",
    ]);
    let f = |e: Option<&ErrorSummary>, pick: fn(&ErrorSummary) -> f64| {
        e.map_or("-".to_owned(), |e| format!("{:.3}", pick(e)))
    };
    for (p, o) in &with {
        for l in &o.by_length {
            t.row(vec![
                p.name.clone(),
                format!("{:.0}", l.length_s),
                l.outages.to_string(),
                f(l.end_error_m.as_ref(), |e| e.rmse),
                f(l.end_error_m.as_ref(), |e| e.p95_abs),
                f(l.end_error_m.as_ref(), |e| e.max_abs),
                f(l.max_abs_error_m.as_ref(), |e| e.max_abs),
                f(l.drift_percent.as_ref(), |e| e.rmse),
                f(l.drift_percent.as_ref(), |e| e.max_abs),
            ]);
        }
    }
    print!("{t}");
    for (p, o) in with {
        for l in o.by_length.iter().filter(|l| l.end_across_m.is_some()) {
            let e = l.end_across_m.expect("filtered");
            println!(
                "{}: across the track at the ends of the {:.0} s outages: RMS {:.3} m, max {:.3} m",
                p.name, l.length_s, e.rmse, e.max_abs
            );
        }
    }
}

/// The 2-D pipelines' errors in the plane against the truth, east and north.
fn print_plane(report: &EvalReport) {
    let planar: Vec<_> = report
        .pipelines
        .iter()
        .filter_map(|p| p.plane.map(|plane| (p, plane)))
        .collect();
    if planar.is_empty() {
        return;
    }
    println!("in the plane (errors = fused − truth, east and north):");
    let mut t = Table::new(&[
        "pipeline",
        "E RMSE m",
        "E max m",
        "N RMSE m",
        "N max m",
        "vE RMSE m/s",
        "vE max m/s",
        "vN RMSE m/s",
        "vN max m/s",
    ]);
    let f = |e: Option<ErrorSummary>, max: bool| {
        e.map_or("-".to_owned(), |e| match max {
            true => format!("{:.3}", e.max_abs),
            false => format!("{:.3}", e.rmse),
        })
    };
    for (p, plane) in planar {
        t.row(vec![
            p.name.clone(),
            f(Some(plane.east_error_m), false),
            f(Some(plane.east_error_m), true),
            f(Some(plane.north_error_m), false),
            f(Some(plane.north_error_m), true),
            f(plane.velocity_east_error_mps, false),
            f(plane.velocity_east_error_mps, true),
            f(plane.velocity_north_error_mps, false),
            f(plane.velocity_north_error_mps, true),
        ]);
    }
    print!("{t}");
}

/// S7 of a pipeline with safety checks: availability, containment, each check's record, and
/// whether each injected fault was caught.
fn print_safety(name: &str, e: &SafetyEval) {
    let c = &e.containment;
    let held = match e.containment_share {
        Some(share) => format!(
            "U_safe held the reference in {} of {} ({:.4} %)",
            c.contained,
            c.checked,
            100.0 * share
        ),
        None => "U_safe not checked (no reference)".to_owned(),
    };
    println!(
        "{name}: safety: {} of {} epochs usable ({:.2} %); {held}",
        e.usable_epochs,
        e.epochs,
        100.0 * e.availability
    );
    let mut t = Table::new(&[
        "  check",
        "failed epochs",
        "first failure",
        "episodes",
        "failed s",
    ]);
    for k in e.checks.iter().filter(|k| k.failed_epochs > 0) {
        t.row(vec![
            format!("  {}", k.check),
            k.failed_epochs.to_string(),
            k.first_failure_epochs.to_string(),
            k.episodes.to_string(),
            format!("{:.1}", k.failed_s),
        ]);
    }
    print!("{t}");
    for f in &e.faults {
        match (f.flagged, f.delay_s, &f.by) {
            (true, Some(d), Some(by)) => {
                println!(
                    "  {} at {:.1} s: flagged after {d:.2} s by {by}",
                    f.label, f.start_s
                )
            }
            _ => println!(
                "  {} at {:.1} s: not flagged while it lasted",
                f.label, f.start_s
            ),
        }
    }
}
