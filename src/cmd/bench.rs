//! `railfuse bench`: throughput and memory figures, measured on real files (not a timed test).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use super::refuse::RunStats;
use super::DEFAULT_PIPELINES;

#[derive(clap::Args)]
pub struct Args {
    /// Durations (s) of the simulated logs to measure; memory should not grow with them.
    #[arg(long, value_delimiter = ',', default_value = "600,3600")]
    pub durations: Vec<f64>,
    /// Folder for the benchmark files.
    #[arg(long, default_value = "target/bench")]
    pub dir: PathBuf,
    /// Measure the recorder instead: UDP ingest rate and CPU/memory at a field load held for
    /// this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub record: Option<f64>,
    /// With --record: play the field load this many times faster (10 for an hour of field
    /// data in six minutes, to see whether memory grows with the amount recorded).
    #[arg(long, default_value_t = 1.0)]
    pub record_speedup: f64,
}

pub fn run(a: Args) -> Result<()> {
    if let Some(secs) = a.record {
        return super::bench_record::run(&a.dir, secs, a.record_speedup);
    }
    std::fs::create_dir_all(&a.dir)
        .with_context(|| format!("{}: cannot create", a.dir.display()))?;
    let config = a.dir.join("kalman.toml");
    std::fs::write(&config, DEFAULT_PIPELINES)?;
    let exe = std::env::current_exe()?;
    println!(
        "{:>10} {:>10} {:>10} {:>14} {:>14} {:>14} {:>12}",
        "run s", "messages", "MiB", "simulate msg/s", "refuse msg/s", "refuse MB/s", "refuse RSS"
    );
    for d in a.durations {
        let raw = a.dir.join(format!("bench-{d:.0}s.mcap"));
        let fused = a.dir.join(format!("bench-{d:.0}s.fused.mcap"));
        let started = Instant::now();
        let sim = railfuse_record::simulate(
            &railfuse_record::Scenario::preset("default").expect("preset"),
            1,
            Some(d),
            &[],
            &raw,
        )?;
        let sim_rate = sim.messages as f64 / started.elapsed().as_secs_f64();
        // Refuse in a child process, so its peak memory is its own.
        let out = Command::new(&exe)
            .args(["refuse", "--json", "-c"])
            .arg(&config)
            .arg("-o")
            .arg(&fused)
            .arg(&raw)
            .output()?;
        if !out.status.success() {
            bail!("refuse failed: {}", String::from_utf8_lossy(&out.stderr));
        }
        let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
        let stats: RunStats = serde_json::from_value(v["run"].clone())?;
        let bytes = std::fs::metadata(&raw)?.len() as f64;
        println!(
            "{:>10.0} {:>10} {:>10.1} {:>14.0} {:>14.0} {:>14.1} {:>9} KiB",
            d,
            sim.messages,
            bytes / (1 << 20) as f64,
            sim_rate,
            stats.input_messages_per_s,
            bytes / stats.elapsed_s / 1e6,
            stats.peak_rss_kib.map_or("-".into(), |k| k.to_string())
        );
    }
    Ok(())
}
