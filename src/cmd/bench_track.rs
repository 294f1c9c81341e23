//! `railfuse bench --track`: what fitting a line costs. Default runs (seeds 1–3) of the given
//! length, fitted one, two and three at a time, each the whole `track` command in a child
//! process: wall time, peak memory, fixes used.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use railfuse_record::{simulate, Scenario};

use super::measure::mib_of;

/// One `track` of `runs` in a child: wall time, peak RSS (KiB) and the fixes it used.
fn track_child(runs: &[PathBuf], out: &Path) -> Result<(f64, Option<u64>, u64)> {
    let started = Instant::now();
    let o = Command::new(std::env::current_exe()?)
        .arg("track")
        .args(runs)
        .arg("-o")
        .arg(out)
        .args(["--json", "-q"])
        .output()?;
    let wall_s = started.elapsed().as_secs_f64();
    if !o.status.success() {
        bail!("track failed: {}", String::from_utf8_lossy(&o.stderr));
    }
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)?;
    Ok((
        wall_s,
        v["peak_rss_kib"].as_u64(),
        v["fixes_used"].as_u64().unwrap_or(0),
    ))
}

fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

pub fn run(dir: &Path, secs: f64, repeat: u32) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let preset = Scenario::preset("default").expect("a built-in preset");
    let runs: Vec<PathBuf> = (1..=3u64)
        .map(|seed| {
            let p = dir.join(format!("track-{secs:.0}s-seed{seed}.mcap"));
            simulate(&preset, seed, Some(secs), &[], &p).map(|_| p)
        })
        .collect::<Result<_, _>>()?;
    let out = dir.join("track.geojson");
    println!(
        "{:>5} {:>9} {:>9} {:>10} {:>12}",
        "runs", "fixes", "track s", "peak RSS", "fixes/s"
    );
    for n in 1..=runs.len() {
        let (mut walls, mut rss, mut fixes) = (Vec::new(), Vec::new(), 0);
        for _ in 0..repeat.max(1) {
            let (w, r, f) = track_child(&runs[..n], &out)?;
            walls.push(w);
            rss.extend(r.map(|k| k as f64));
            fixes = f;
        }
        let wall = median(walls);
        let peak = (!rss.is_empty()).then(|| median(rss) as u64);
        println!(
            "{n:>5} {fixes:>9} {wall:>9.2} {:>10} {:>12.0}",
            mib_of(peak),
            fixes as f64 / wall
        );
    }
    Ok(())
}
