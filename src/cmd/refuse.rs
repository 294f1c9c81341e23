use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use railfuse_catalog::topics;
use railfuse_refuse::config::PipelinesConfig;
use railfuse_refuse::replay::{refuse, RefuseOptions, RefuseReport};

use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The input MCAP log.
    pub input: PathBuf,
    /// Pipeline configuration (TOML); see samples/kalman.toml.
    #[arg(short, long)]
    pub config: PathBuf,
    /// The output MCAP log: every input record plus the fused channels. May be the input
    /// itself: it is replaced only once the new file is complete.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Reference trajectory for the accuracy table (ground truth or another pipeline's state).
    #[arg(long, default_value = topics::GROUND_TRUTH)]
    pub reference: String,
    /// Print the report as JSON (with wall time, throughput and peak memory).
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let config = PipelinesConfig::load(&a.config)?;
    let source = a.config.display().to_string();
    let (report, stats) = refuse_with(&a.input, &a.output, &config, source, &a.reference)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "refuse": report, "run": stats }))?);
    } else {
        print_accuracy(&report);
    }
    Ok(())
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RunStats {
    pub elapsed_s: f64,
    pub input_messages_per_s: f64,
    /// Peak resident memory of this process (VmHWM), KiB; None where /proc is missing.
    pub peak_rss_kib: Option<u64>,
}

pub fn refuse_with(input: &Path, output: &Path, config: &PipelinesConfig, source: String, reference: &str) -> Result<(RefuseReport, RunStats)> {
    let started = Instant::now();
    let report = refuse(&RefuseOptions { input, output, config, config_source: source, reference_topic: reference.to_owned() })?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let stats = RunStats { elapsed_s, input_messages_per_s: report.input_messages as f64 / elapsed_s, peak_rss_kib: peak_rss_kib() };
    eprintln!(
        "re-fused {} messages of {} in {:.2} s ({:.0} msg/s), wrote {} fused messages -> {}",
        report.input_messages,
        input.display(),
        elapsed_s,
        stats.input_messages_per_s,
        report.fused_messages,
        output.display()
    );
    if report.out_of_order_messages > 0 {
        eprintln!("note: {} messages are earlier in log time than the one before them in the file", report.out_of_order_messages);
    }
    Ok((report, stats))
}

/// Peak resident set size of this process, from /proc/self/status.
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The accuracy table, as refuse and demo print it.
pub fn print_accuracy(report: &RefuseReport) {
    match &report.reference {
        Some(r) => {
            println!("accuracy against {r} (errors = fused − reference, at each fused state):")
        }
        None => println!("no reference channel in the input: accuracy not computed (counts only)"),
    }
    let mut t = Table::new(&[
        "pipeline",
        "states",
        "pos RMSE m",
        "pos p95 m",
        "pos max m",
        "speed RMSE m/s",
        "speed p95 m/s",
        "speed max m/s",
        "gated",
        "invalid",
        "late",
    ]);
    let f = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:.3}"));
    for p in &report.pipelines {
        let (pos, spd) = (p.position_error_m.as_ref(), p.speed_error_mps.as_ref());
        t.row(vec![
            p.name.clone(),
            p.fused_states.to_string(),
            f(pos.map(|e| e.rmse)),
            f(pos.map(|e| e.p95_abs)),
            f(pos.map(|e| e.max_abs)),
            f(spd.map(|e| e.rmse)),
            f(spd.map(|e| e.p95_abs)),
            f(spd.map(|e| e.max_abs)),
            p.counts.rejected_gate.to_string(),
            p.counts.rejected_invalid.to_string(),
            p.counts.rejected_late.to_string(),
        ]);
    }
    print!("{t}");
}
