//! `railfuse bench --viz SECONDS`: how long `railfuse viz` takes to turn a re-fused run into a
//! Rerun recording, its peak memory and the recording's size, at the default decimation and
//! at full rate. Each run is the whole command in a child process, as a user waits for it.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Result};

pub fn run(dir: &Path, duration_s: f64, repeat: u32) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    let (raw, fused, config) = (
        dir.join(format!("viz-{duration_s:.0}.mcap")),
        dir.join(format!("viz-{duration_s:.0}.fused.mcap")),
        dir.join("viz-pipelines.toml"),
    );
    let preset = railfuse_record::Scenario::preset("default").expect("a built-in preset");
    let sim = railfuse_record::simulate(&preset, 1, Some(duration_s), &[], &raw)?;
    let (text, pipelines) = railfuse_experiments::long_runs::side_by_side()?;
    std::fs::write(&config, text)?;
    let (report, _) = railfuse_refuse::replay::refuse(&railfuse_refuse::replay::RefuseOptions {
        run: &railfuse_catalog::run::Run::file(&raw),
        output: &fused,
        config: &pipelines,
        config_source: config.display().to_string(),
        reference: &railfuse_eval::Reference::topic(railfuse_catalog::topics::GROUND_TRUTH),
        withhold: None,
        progress: None,
        observer: None,
    })?;
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    println!(
        "default {duration_s:.0} s run: {} raw + {} fused messages, {:.1} MiB, pipelines kalman and kalman_cal",
        sim.messages,
        report.fused_messages,
        mib(std::fs::metadata(&fused)?.len())
    );
    println!(
        "{:<22} {:>8} {:>12} {:>10} {:>14} {:>9}",
        "viz", "wall s", "peak RSS MiB", "rows", "recording MB", "bin s"
    );
    for (label, extra) in [
        ("default decimation", None),
        ("--full-rate", Some("--full-rate")),
    ] {
        let rrd = dir.join(format!("viz-{duration_s:.0}{}.rrd", extra.unwrap_or("")));
        let mut runs = (0..repeat.max(1))
            .map(|_| viz_child(&fused, &rrd, extra))
            .collect::<Result<Vec<_>>>()?;
        runs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (wall_s, v) = &runs[runs.len() / 2];
        let peak = runs
            .iter()
            .filter_map(|(_, v)| v["run"]["peak_rss_kib"].as_u64())
            .max();
        println!(
            "{:<22} {:>8.2} {:>12} {:>10} {:>14.1} {:>9}",
            label,
            wall_s,
            super::measure::mib_of(peak),
            v["rows"],
            v["recording_bytes"].as_u64().unwrap_or(0) as f64 / 1e6,
            v["bin_s"]
                .as_f64()
                .map_or("full".into(), |b| format!("{b:.2}")),
        );
    }
    Ok(())
}

/// `railfuse viz --save` in a child process: its wall time and JSON report.
fn viz_child(fused: &Path, rrd: &Path, extra: Option<&str>) -> Result<(f64, serde_json::Value)> {
    let started = Instant::now();
    let out = Command::new(std::env::current_exe()?)
        .args(["viz", "--json", "--save"])
        .arg(rrd)
        .arg(fused)
        .args(extra)
        .output()?;
    let wall_s = started.elapsed().as_secs_f64();
    if !out.status.success() {
        bail!("viz failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    Ok((wall_s, serde_json::from_slice(&out.stdout)?))
}
