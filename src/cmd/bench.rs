//! `railfuse bench`: file-to-file throughput and memory of `railfuse refuse`, timed as a user
//! runs it (the whole command in a child process, accuracy table included), beside a peer: the
//! same job in Python with the official `mcap` reader and writer and filterpy
//! (`bench/peer_refuse.py`), on the same file. Measured on real files, not a timed test.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use super::measure::{find_python, mib_of, refuse_run_child, Measured};
use railfuse_experiments::sources::SEED001_PIPELINES;

use super::DEFAULT_PIPELINES;

const PEER: &str = include_str!("../../bench/peer_refuse.py");

#[derive(clap::Args)]
// One measurement a run: a second mode flag is refused, not silently dropped.
#[command(group(clap::ArgGroup::new("mode").args(["record", "can", "viz", "tune", "em", "safety", "gnss_ins", "eddy_current", "runs", "mdf4"])))]
pub struct Args {
    /// Durations (s) of the simulated default-scenario logs to measure with samples/kalman.toml;
    /// memory should not grow with them.
    #[arg(long, value_delimiter = ',', default_value = "600,3600")]
    pub durations: Vec<f64>,
    /// Also measure a seed001 run (source 001's maglev) with samples/seed001.toml.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub seed001: bool,
    /// Python with `mcap` and `filterpy` for the peer (default: $RAILFUSE_PYTHON, then the
    /// test venv `.venv-interop/bin/python` that `tests/run` installs).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Folder for the benchmark files.
    #[arg(long, default_value = "target/bench")]
    pub dir: PathBuf,
    /// Runs of refuse per log; the median time and the highest peak memory are reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Measure the recorder instead: UDP ingest rate and CPU/memory at a field load held for
    /// this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub record: Option<f64>,
    /// Measure the recorder on the vehicle's CAN bus instead: `--can-rate` frames a second
    /// through an SLCAN adapter (a pty pair), then through a socketcand server (loopback),
    /// each held this many seconds, decoded with the vehicle's DBC: frames lost, drops
    /// counted, CPU and resident memory over the run.
    #[arg(long, value_name = "SECONDS")]
    pub can: Option<f64>,
    /// With --can: frames a second (1 Mbit/s classic CAN at full load is about 8 000).
    #[arg(long, default_value_t = 50_000.0)]
    pub can_rate: f64,
    /// Measure `railfuse viz` instead: time, peak memory and recording size for the
    /// default scenario re-fused with the demo's two pipelines (samples/kalman.toml and
    /// samples/sensor-states.toml), at the default decimation and at full rate.
    #[arg(long, value_name = "SECONDS")]
    pub viz: Option<f64>,
    /// With --record: play the field load this many times faster (10 for an hour of field
    /// data in six minutes, to see whether memory grows with the amount recorded).
    #[arg(long, default_value_t = 1.0)]
    pub record_speedup: f64,
    /// Measure tuning instead: decoding a default-scenario log of this many seconds once, and
    /// evaluations per second of the default pipeline on it, on one core and on every core.
    #[arg(long, value_name = "SECONDS")]
    pub tune: Option<f64>,
    /// Measure MDF 4 reading instead: these bus logs (files or folders) read to CAN frames by
    /// railfuse and by asammdf, and converted into a run's MCAP part.
    #[arg(long, value_name = "FILE|DIR", num_args = 1..)]
    pub mdf4: Vec<PathBuf>,
    /// Measure EM instead: railfuse's against pykalman's `KalmanFilter.em` on the same
    /// constant-acceleration data (10 000 steps, 20 iterations, Q and R estimated).
    #[arg(long)]
    pub em: bool,
    /// With --em: steps of the run.
    #[arg(long, default_value_t = 10_000)]
    pub em_steps: usize,
    /// With --em: EM iterations.
    #[arg(long, default_value_t = 20)]
    pub em_iterations: usize,
    /// With --em: print JSON.
    #[arg(long, requires = "em")]
    pub json: bool,
    /// Measure source 002's ekf_safety instead: epochs per second of samples/seed002.toml's
    /// two pipelines on a seed002 run of this many seconds (the whole refuse command).
    #[arg(long, value_name = "SECONDS")]
    pub safety: Option<f64>,
    /// Measure source 003's gnss_ins with PU-RLS instead: samples/seed003.toml's `pu_rls`
    /// alone on a default run (200 Hz IMU) of this many seconds, against real time.
    #[arg(long, value_name = "SECONDS")]
    pub gnss_ins: Option<f64>,
    /// Measure source 004's eddy_current instead: samples/seed004.toml's `warped_kf` alone
    /// on a default run (two sensors at 10 kHz) of this many seconds, against real time.
    #[arg(long, value_name = "SECONDS")]
    pub eddy_current: Option<f64>,
    /// Measure runs of many files instead: a default run of this many seconds re-fused whole,
    /// as 20 parts, and as three recorders' files with --align gnss (time and peak memory).
    #[arg(long, value_name = "SECONDS")]
    pub runs: Option<f64>,
    /// Measure `railfuse track` instead: default runs of this many seconds (seeds 1–3),
    /// fitted one, two and three at a time (time, peak memory, fixes a second).
    #[arg(long, value_name = "SECONDS")]
    pub track: Option<f64>,
}

pub fn run(a: Args) -> Result<()> {
    if let Some(secs) = a.record {
        return super::bench_record::run(&a.dir, secs, a.record_speedup);
    }
    if let Some(secs) = a.can {
        return super::bench_can::run(&a.dir, secs, a.can_rate);
    }
    if let Some(secs) = a.tune {
        return super::bench_tune::run(&a.dir, secs, a.repeat);
    }
    if !a.mdf4.is_empty() {
        let python = a.python.clone().or_else(find_python);
        return super::bench_mdf::run(&a.mdf4, python, &a.dir, a.repeat);
    }
    if a.em {
        let python = a.python.clone().or_else(find_python);
        return super::bench_em::run(python, &a.dir, a.em_steps, a.em_iterations, a.json);
    }
    if let Some(secs) = a.viz {
        return super::bench_viz::run(&a.dir, secs, a.repeat);
    }
    if let Some(secs) = a.safety {
        return safety(&a.dir, secs, a.repeat);
    }
    if let Some(secs) = a.gnss_ins {
        return gnss_ins(&a.dir, secs, a.repeat);
    }
    if let Some(secs) = a.eddy_current {
        return eddy_current(&a.dir, secs, a.repeat);
    }
    if let Some(secs) = a.runs {
        return super::bench_runs::run(&a.dir, secs, a.repeat);
    }
    if let Some(secs) = a.track {
        return super::bench_track::run(&a.dir, secs, a.repeat);
    }
    refuse_table(&a)
}

/// The refuse table: the default log at each duration with samples/kalman.toml (and seed001
/// with its four pipelines), railfuse beside the Python peer.
fn refuse_table(a: &Args) -> Result<()> {
    std::fs::create_dir_all(&a.dir)
        .with_context(|| format!("{}: cannot create", a.dir.display()))?;
    let kalman = a.dir.join("kalman.toml");
    std::fs::write(&kalman, DEFAULT_PIPELINES)?;
    let seed001 = a.dir.join("seed001.toml");
    std::fs::write(&seed001, SEED001_PIPELINES)?;
    let peer = a.dir.join("peer_refuse.py");
    std::fs::write(&peer, PEER)?;
    let python = a.python.clone().or_else(find_python);
    println!(
        "{:<28} {:>9} {:>6} {:>9} {:>13} {:>10} {:>8} {:>11} {:>7}",
        "log, pipelines",
        "messages",
        "MiB",
        "refuse s",
        "refuse msg/s",
        "peak RSS",
        "peer s",
        "peer msg/s",
        "ratio"
    );
    let mut runs: Vec<(String, &str, Option<f64>, &Path)> = a
        .durations
        .iter()
        .map(|&d| {
            (
                format!("default {d:.0} s, kalman"),
                "default",
                Some(d),
                kalman.as_path(),
            )
        })
        .collect();
    if a.seed001 {
        runs.push((
            "seed001, seed001.toml".into(),
            "seed001",
            None,
            seed001.as_path(),
        ));
    }
    let bar = crate::progress::Progress::steps("bench", runs.len() as u64);
    for (done, (label, scenario, duration, config)) in runs.into_iter().enumerate() {
        bar.set(done as u64);
        let peer = python.as_deref().zip(Some(peer.as_path()));
        refuse_row(a, &label, scenario, duration, config, peer)?;
    }
    if python.is_none() {
        println!(
            "peer: not run: no Python with mcap and filterpy (run tests/run once, or --python)"
        );
    }
    Ok(())
}

/// One row of the refuse table: the log simulated, refused `repeat` times (the median run),
/// and the peer on the default scenario.
fn refuse_row(
    a: &Args,
    label: &str,
    scenario: &str,
    duration: Option<f64>,
    config: &Path,
    peer: Option<(&Path, &Path)>,
) -> Result<()> {
    let tag = label.replace([' ', ','], "");
    let raw = a.dir.join(format!("bench-{tag}.mcap"));
    let preset = railfuse_record::Scenario::preset(scenario).expect("a built-in preset");
    let sim = railfuse_record::simulate(&preset, 1, duration, &[], &raw)?;
    let fused = a.dir.join(format!("bench-{tag}.fused.mcap"));
    // The median of several runs: the machine's other load moves single timings.
    let mut all = (0..a.repeat.max(1))
        .map(|_| refuse_child(&raw, config, &fused))
        .collect::<Result<Vec<_>>>()?;
    all.sort_by(|x, y| x.wall_s.total_cmp(&y.wall_s));
    let ours = Measured {
        wall_s: all[all.len() / 2].wall_s,
        peak_rss_kib: all.iter().filter_map(|m| m.peak_rss_kib).max(),
        safety_epochs: Vec::new(),
    };
    let rate = sim.messages as f64 / ours.wall_s;
    // The peer writes the same records (bench/peer_refuse.py says what it leaves out).
    let theirs = match peer {
        Some((py, peer)) => Some(peer_child(py, peer, &raw, config, &a.dir)?),
        None => None,
    };
    let mib = std::fs::metadata(&raw)?.len() as f64 / (1 << 20) as f64;
    let (peer_s, peer_rate, ratio) = match theirs {
        Some(s) => {
            let r = sim.messages as f64 / s;
            (
                format!("{s:.2}"),
                format!("{:.1} k", r / 1e3),
                format!("{:.0}x", rate / r),
            )
        }
        None => ("-".into(), "-".into(), "-".into()),
    };
    println!(
        "{:<28} {:>9} {:>6.1} {:>9.3} {:>11.2} M {:>6} MiB {:>8} {:>11} {:>7}",
        label,
        sim.messages,
        mib,
        ours.wall_s,
        rate / 1e6,
        mib_of(ours.peak_rss_kib),
        peer_s,
        peer_rate,
        ratio
    );
    Ok(())
}

/// A `scenario` run of `secs` s simulated into `dir`, then refused `repeat` times with the
/// pipelines `config` (a file name and its text) in child processes; the runs fastest first.
fn timed_runs(
    dir: &Path,
    scenario: &str,
    secs: f64,
    (name, text): (&str, &str),
    repeat: u32,
) -> Result<(railfuse_record::SimulationReport, Vec<Measured>)> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let config = dir.join(name);
    std::fs::write(&config, text)?;
    let raw = dir.join(format!("bench-{scenario}-{secs:.0}s.mcap"));
    let fused = raw.with_extension("fused.mcap");
    let preset = railfuse_record::Scenario::preset(scenario).expect("a built-in preset");
    let sim = railfuse_record::simulate(&preset, 1, Some(secs), &[], &raw)?;
    let mut all = (0..repeat.max(1))
        .map(|_| refuse_child(&raw, &config, &fused))
        .collect::<Result<Vec<_>>>()?;
    all.sort_by(|x, y| x.wall_s.total_cmp(&y.wall_s));
    Ok((sim, all))
}

/// `railfuse bench --safety`: a seed002 run of `secs` s through samples/seed002.toml, the
/// median of `repeat` refuse runs; epochs (fixes and axle-1 samples) per second per pipeline.
fn safety(dir: &Path, secs: f64, repeat: u32) -> Result<()> {
    let pipelines = railfuse_experiments::safety::SEED002_PIPELINES;
    let (sim, all) = timed_runs(dir, "seed002", secs, ("seed002.toml", pipelines), repeat)?;
    let m = &all[all.len() / 2];
    let epochs: u64 = m.safety_epochs.iter().sum();
    println!(
        "seed002 {:.0} s, {} messages: refuse {:.3} s (median of {}), {} epochs in {} pipelines: \
         {:.0} epochs/s per pipeline, {:.2} M msg/s, peak RSS {} MiB",
        sim.duration_s,
        sim.messages,
        m.wall_s,
        all.len(),
        epochs,
        m.safety_epochs.len(),
        epochs as f64 / m.safety_epochs.len().max(1) as f64 / m.wall_s,
        sim.messages as f64 / m.wall_s / 1e6,
        mib_of(all.iter().filter_map(|m| m.peak_rss_kib).max()),
    );
    Ok(())
}

/// `railfuse bench --gnss-ins`: a default run of `secs` s (IMU at 200 Hz, GNSS at 10 Hz)
/// through samples/seed003.toml's `pu_rls` pipeline alone (one core), the whole refuse
/// command timed.
fn gnss_ins(dir: &Path, secs: f64, repeat: u32) -> Result<()> {
    let all = railfuse_experiments::gnss_ins::SEED003_PIPELINES;
    // The sample's pu_rls pipeline, alone.
    let Some(pu_rls) = all
        .split("[[pipeline]]")
        .find(|p| p.contains("name = \"pu_rls\""))
        .map(|p| format!("[[pipeline]]{p}"))
    else {
        bail!("samples/seed003.toml no longer has the pu_rls pipeline");
    };
    let (sim, all) = timed_runs(
        dir,
        "default",
        secs,
        ("seed003-pu_rls.toml", &pu_rls),
        repeat,
    )?;
    let m = &all[all.len() / 2];
    // 200 Hz IMU and 10 Hz GNSS: the epochs the pipeline processes.
    let imu_and_fixes = sim.duration_s * (200.0 + 10.0);
    println!(
        "default {:.0} s, {} messages: gnss_ins pu_rls refuse {:.3} s (median of {}): {:.0}x real \
         time, about {:.0} epochs/s (IMU samples and fixes), peak RSS {} MiB",
        sim.duration_s,
        sim.messages,
        m.wall_s,
        all.len(),
        sim.duration_s / m.wall_s,
        imu_and_fixes / m.wall_s,
        mib_of(all.iter().filter_map(|m| m.peak_rss_kib).max()),
    );
    Ok(())
}

/// `railfuse bench --eddy-current`: a default run of `secs` s (two eddy-current sensors at
/// 10 kHz) through samples/seed004.toml's `warped_kf` pipeline alone (one core), the whole
/// refuse command timed (copying the log's other channels included).
fn eddy_current(dir: &Path, secs: f64, repeat: u32) -> Result<()> {
    let all = railfuse_experiments::eddy_current::SEED004_PIPELINES;
    let start = all.rfind("[[pipeline]]").expect("the sample has pipelines");
    let warped_kf = &all[start..];
    if !warped_kf.contains("name = \"warped_kf\"") {
        bail!("samples/seed004.toml no longer ends with the warped_kf pipeline");
    }
    let (sim, all) = timed_runs(
        dir,
        "default",
        secs,
        ("seed004-warped_kf.toml", warped_kf),
        repeat,
    )?;
    let m = &all[all.len() / 2];
    let samples = sim.duration_s * 2.0 * 10_000.0;
    println!(
        "default {:.0} s, {} messages: eddy_current warped_kf refuse {:.3} s (median of {}): \
         {:.0}x real time, {:.2} M samples/s (two sensors at 10 kHz: 0.02 M/s in real time), \
         peak RSS {} MiB",
        sim.duration_s,
        sim.messages,
        m.wall_s,
        all.len(),
        sim.duration_s / m.wall_s,
        samples / m.wall_s / 1e6,
        mib_of(all.iter().filter_map(|m| m.peak_rss_kib).max()),
    );
    Ok(())
}

/// `railfuse refuse` in a child process, timed from spawn to exit, so its peak memory is its
/// own and the time is what a user waits.
fn refuse_child(raw: &Path, config: &Path, fused: &Path) -> Result<Measured> {
    refuse_run_child(&[raw], &[], config, fused)
}

/// The Python peer on the same file, timed the same way (interpreter start included).
fn peer_child(python: &Path, script: &Path, raw: &Path, config: &Path, dir: &Path) -> Result<f64> {
    let started = Instant::now();
    let out = Command::new(python)
        .arg(script)
        .arg(raw)
        .arg(config)
        .arg(dir.join("bench-peer.fused.mcap"))
        .output()
        .with_context(|| format!("{}: cannot run", python.display()))?;
    let wall_s = started.elapsed().as_secs_f64();
    if !out.status.success() {
        bail!(
            "the Python peer failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(wall_s)
}
