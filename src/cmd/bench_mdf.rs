//! `railfuse bench --mdf4`: MDF 4 bus logs read to CAN frames by railfuse and by asammdf,
//! the same files, in one run: frames, seconds (median of the passes) and frames a second;
//! and railfuse's whole conversion into a run's MCAP part.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use railfuse_catalog::formats::{self, FormatOptions, Storage};
use railfuse_mdf::bus::BusFrames;

const SCRIPT: &str = include_str!("../../bench/peer_mdf4.py");

/// The files of the inputs (a folder: its .MF4 files, in name order).
fn files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for i in inputs {
        if i.is_dir() {
            let mut f: Vec<PathBuf> = std::fs::read_dir(i)
                .with_context(|| format!("{}: cannot read", i.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| Storage::of_name(p) == Some(Storage::Mdf4))
                .collect();
            f.sort();
            out.extend(f);
        } else {
            out.push(i.clone());
        }
    }
    if out.is_empty() {
        bail!("--mdf4: no .MF4 file in {inputs:?}");
    }
    Ok(out)
}

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// railfuse's passes: the frames, and the median seconds to read them and to convert them.
fn railfuse_passes(files: &[PathBuf], dir: &Path, repeat: u32) -> Result<(u64, f64, f64)> {
    let (mut frames, mut read_s, mut convert_s) = (0u64, Vec::new(), Vec::new());
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        frames = 0;
        for f in files {
            let mut r = BusFrames::open(f).map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
            frames += r.by_ref().count() as u64;
        }
        read_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for f in files {
            let out = dir.join("bench-mdf4.mcap");
            formats::convert(
                Storage::Mdf4,
                f,
                &out,
                &FormatOptions::default(),
                &Default::default(),
            )?;
        }
        convert_s.push(t.elapsed().as_secs_f64());
    }
    Ok((frames, median(read_s), median(convert_s)))
}

pub fn run(inputs: &[PathBuf], python: Option<PathBuf>, dir: &Path, repeat: u32) -> Result<()> {
    let files = files(inputs)?;
    let bytes: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).map_or(0, |m| m.len()))
        .sum();
    let (frames, ours, convert) = railfuse_passes(&files, dir, repeat)?;
    println!(
        "{} files, {:.1} MiB, {frames} CAN frames; median of {} passes",
        files.len(),
        bytes as f64 / (1 << 20) as f64,
        repeat.max(1)
    );
    println!("{:<42} {:>9} {:>13}", "reader", "seconds", "frames/s");
    println!(
        "{:<42} {:>9.3} {:>13.0}",
        "railfuse (frames)",
        ours,
        frames as f64 / ours
    );
    println!(
        "{:<42} {:>9.3} {:>13.0}",
        "railfuse (frames into a run's MCAP part)",
        convert,
        frames as f64 / convert
    );
    let Some(python) = python else {
        println!("asammdf: not run (no Python: set RAILFUSE_PYTHON or run tests/run once)");
        return Ok(());
    };
    let script = dir.join("peer_mdf4.py");
    std::fs::write(&script, SCRIPT)?;
    let out = Command::new(&python)
        .arg(&script)
        .arg(repeat.max(1).to_string())
        .args(&files)
        .output()
        .with_context(|| format!("{}: cannot run", python.display()))?;
    if !out.status.success() {
        bail!("asammdf failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let theirs: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("asammdf's output")?;
    let (s, n) = (
        theirs["seconds"].as_f64().unwrap_or(f64::NAN),
        theirs["frames"].as_u64().unwrap_or(0),
    );
    println!(
        "{:<42} {:>9.3} {:>13.0}",
        "asammdf (MDF + get of CAN_DataFrame members)",
        s,
        n as f64 / s
    );
    if n != frames {
        println!("warning: asammdf counted {n} frames, railfuse {frames}");
    }
    println!("railfuse reads {:.1}x as fast", s / ours);
    Ok(())
}
