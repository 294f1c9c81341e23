//! `railfuse bench --runs`: what reading a run of many files costs. One default run re-fused
//! as one file (chunks copied), as the same file through the run reader (record by record),
//! as 20 parts of it (read part after part, chunks copied), as the 20 parts through the run
//! reader (the k-way merge), and as three recorders' files on their own clocks with
//! `--align gnss` (the clock estimate's extra pass included), and beside the one file the same
//! run in the flat point-train world (`--scenario flat`: what the railway in three dimensions
//! and the train's geometry cost): wall time and peak memory of each, each the whole `refuse`
//! command in a child process.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use railfuse_catalog::log::{SplitRule, WriterOptions};
use railfuse_catalog::run::Run;
use railfuse_record::{simulate, simulate_recorders, Scenario, SimRecorder};

use super::measure::{mib_of, refuse_run_child, Measured};
use super::DEFAULT_PIPELINES;

const PARTS: u64 = 20;

/// The benchmark's logs: one run of `secs` s, the same as 20 parts, and as three recorders.
struct Logs {
    sim: railfuse_record::SimulationReport,
    whole: PathBuf,
    parts: PathBuf,
    three: Vec<PathBuf>,
    /// The same run flattened, a point train.
    flat: PathBuf,
}

fn write_logs(dir: &Path, secs: f64) -> Result<Logs> {
    let preset = Scenario::preset("default").expect("a built-in preset");
    let whole = dir.join(format!("runs-{secs:.0}s.mcap"));
    let sim = simulate(&preset, 1, Some(secs), &[], &whole)?;
    let flat = dir.join(format!("runs-{secs:.0}s-flat.mcap"));
    let flat_preset = Scenario::preset("flat").expect("a built-in preset");
    simulate(&flat_preset, 1, Some(secs), &[], &flat)?;
    let parts = dir.join(format!("runs-{secs:.0}s-parts"));
    let _ = std::fs::remove_dir_all(&parts);
    std::fs::create_dir_all(&parts)?;
    let every_ns = (sim.duration_s * 1e9 / PARTS as f64).ceil() as u64;
    railfuse_catalog::run::merge(
        &Run::file(&whole),
        &parts.join("run.mcap"),
        SplitRule {
            every_ns: Some(every_ns),
            ..Default::default()
        },
        &WriterOptions::default(),
    )?;
    let three = dir.join(format!("runs-{secs:.0}s-three"));
    let _ = std::fs::remove_dir_all(&three);
    let recorders: Vec<SimRecorder> = ["box", "rack=+0.35,+20ppm", "radar=-1.2,-15ppm"]
        .iter()
        .map(|r| r.parse().map_err(anyhow::Error::msg))
        .collect::<Result<_>>()?;
    let written = simulate_recorders(&preset, 1, Some(secs), &[], &recorders, &three)?;
    Ok(Logs {
        sim,
        whole,
        parts,
        three: written.files.iter().map(PathBuf::from).collect(),
        flat,
    })
}

/// Each case's median wall time and median peak RSS (KiB) over `repeat` rounds, round after
/// round over all cases, so that the machine's drift (other load, heat) falls on every case
/// alike rather than on whichever ran last.
fn measure<'a>(
    cases: &[(&'a str, &[&Path], &[&str])],
    repeat: u32,
    config: &Path,
    fused: &Path,
) -> Result<Vec<(&'a str, (f64, Option<u64>))>> {
    let mut all: Vec<Vec<Measured>> = cases.iter().map(|_| Vec::new()).collect();
    for _ in 0..repeat.max(1) {
        for ((_, inputs, options), runs) in cases.iter().zip(&mut all) {
            runs.push(refuse_run_child(inputs, options, config, fused)?);
        }
    }
    Ok(cases
        .iter()
        .zip(all)
        .map(|((label, ..), mut runs)| {
            // Medians of both: one run's peak RSS moves by a chunk buffer or two with where
            // the allocator and the read-ahead happen to stand when it peaks.
            let mut peaks: Vec<u64> = runs.iter().filter_map(|m| m.peak_rss_kib).collect();
            peaks.sort_unstable();
            runs.sort_by(|x, y| x.wall_s.total_cmp(&y.wall_s));
            let median_peak = peaks.get(peaks.len() / 2).copied();
            (*label, (runs[runs.len() / 2].wall_s, median_peak))
        })
        .collect())
}

pub fn run(dir: &Path, secs: f64, repeat: u32) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let config = dir.join("kalman.toml");
    std::fs::write(&config, DEFAULT_PIPELINES)?;
    let Logs {
        sim,
        whole,
        parts,
        three: three_files,
        flat,
    } = write_logs(dir, secs)?;
    let fused = dir.join("runs.fused.mcap");
    let three: Vec<&Path> = three_files.iter().map(PathBuf::as_path).collect();
    // Publish time is the log time in a simulated run: the same order, read record by
    // record through the run reader.
    let cases: [(&str, &[&Path], &[&str]); 6] = [
        ("one file (chunks copied)", &[&whole], &[]),
        (
            "one file, through the run reader",
            &[&whole],
            &["--time", "publish"],
        ),
        ("20 parts (read part after part)", &[&parts], &[]),
        (
            "20 parts, through the run reader",
            &[&parts],
            &["--time", "publish"],
        ),
        ("3 recorders, --align gnss", &three, &["--align", "gnss"]),
        ("one file, flat and a point train", &[&flat], &[]),
    ];
    let rows = measure(&cases, repeat, &config, &fused)?;
    println!(
        "default {:.0} s, {} messages, kalman; refuse: medians of {} rounds over all inputs",
        sim.duration_s,
        sim.messages,
        repeat.max(1)
    );
    println!("{:<36} {:>9} {:>13}", "input", "refuse s", "peak RSS MiB");
    for (label, (wall, peak)) in &rows {
        println!("{label:<36} {wall:>9.3} {:>13}", mib_of(*peak));
    }
    let pct = |a: f64, b: f64| (a / b - 1.0) * 100.0;
    let kib = |row: &(f64, Option<u64>)| row.1.map_or(f64::NAN, |k| k as f64);
    for (what, row, base) in [
        (
            "the railway in three dimensions against the flat point-train world",
            rows[0].1,
            rows[5].1,
        ),
        ("20 parts against one file", rows[2].1, rows[0].1),
        (
            "the k-way merge of 20 parts against one file, both through the run reader",
            rows[3].1,
            rows[1].1,
        ),
    ] {
        println!(
            "{what}: time {:+.1} %, peak RSS {:+.1} %",
            pct(row.0, base.0),
            pct(kib(&row), kib(&base)),
        );
    }
    Ok(())
}
