//! `railfuse bench --tune SECONDS`: the cost of tuning the default pipeline on one log of that
//! length: decoding it once (time, and the memory the decoded log takes), then evaluations
//! per second (one replay of the log from memory, scored) on one core and on every core.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use railfuse_tune::{TuneRequest, Tuner};
use rayon::prelude::*;

use super::measure::peak_rss_kib;
use super::DEFAULT_PIPELINES;

pub fn run(dir: &Path, duration_s: f64, repeat: u32) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let (raw, config) = (
        dir.join(format!("tune-{duration_s:.0}.mcap")),
        dir.join("tune-kalman.toml"),
    );
    let preset = railfuse_record::Scenario::preset("default").expect("a built-in preset");
    let sim = railfuse_record::simulate(&preset, 1, Some(duration_s), &[], &raw)?;
    std::fs::write(&config, DEFAULT_PIPELINES)?;
    let rss_before = peak_rss_kib();
    let started = Instant::now();
    let tuner = Tuner::open(&TuneRequest {
        config: config.clone(),
        pipeline: "kalman".into(),
        logs: vec![raw.clone()],
        reference: Some(railfuse_catalog::topics::GROUND_TRUTH.into()),
        params: vec![
            "motion.jerk_psd=0.001..10".into(),
            "sensor[/radar/speed].variance=1e-4..1".into(),
        ],
        ..Default::default()
    })?;
    let decode_s = started.elapsed().as_secs_f64();
    let sensor_messages = tuner.recordings[0].messages();
    println!(
        "default {duration_s:.0} s run, {} messages ({} read by samples/kalman.toml): decoded once in {decode_s:.2} s; peak RSS {} MiB (before decoding {} MiB)",
        sim.messages,
        sensor_messages,
        super::measure::mib_of(peak_rss_kib()),
        super::measure::mib_of(rss_before),
    );
    println!(
        "{:<10} {:>12} {:>16} {:>18}",
        "threads", "evaluations", "evaluations/s", "sensor msg/s"
    );
    let start = tuner.start();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut thread_counts = vec![1];
    if cores > 1 {
        thread_counts.push(cores);
    }
    for threads in thread_counts {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let n = (repeat.max(1) as usize) * threads * 2;
        let started = Instant::now();
        // Independent candidates, as a grid or a swarm evaluates them.
        pool.install(|| {
            (0..n)
                .into_par_iter()
                .map(|_| tuner.evaluate(&start).map(|e| e.objective))
                .collect::<railfuse_tune::Result<Vec<f64>>>()
        })?;
        let rate = n as f64 / started.elapsed().as_secs_f64();
        println!(
            "{threads:<10} {n:>12} {rate:>16.2} {:>18.0}",
            rate * sensor_messages as f64
        );
    }
    std::fs::remove_file(&raw).ok();
    Ok(())
}
