//! What a run costs, as the commands and benchmarks report it: wall time and throughput, this
//! process's peak memory, and the Python a benchmark compares against.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Result};

/// A command's wall time, throughput and peak memory (`refuse --json`, the benchmarks).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RunStats {
    pub elapsed_s: f64,
    pub input_messages_per_s: f64,
    /// Peak resident memory of this process (VmHWM), KiB; None where /proc is missing.
    pub peak_rss_kib: Option<u64>,
}

/// Peak resident set size of this process, from /proc/self/status.
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// A resident size in KiB (as /proc gives it) written in MiB, as the README reports memory.
pub fn mib_of(kib: Option<u64>) -> String {
    kib.map_or("-".into(), |k| format!("{:.1}", k as f64 / 1024.0))
}

/// The Python with the peers' packages: $RAILFUSE_PYTHON, else the test venv's.
pub fn find_python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("RAILFUSE_PYTHON") {
        return Some(PathBuf::from(p));
    }
    let venv = PathBuf::from(".venv-interop/bin/python");
    venv.exists().then_some(venv)
}

/// One measured `refuse` run.
pub struct Measured {
    pub wall_s: f64,
    pub peak_rss_kib: Option<u64>,
    /// Epochs of each pipeline with safety checks.
    pub safety_epochs: Vec<u64>,
}

/// `railfuse refuse` of a run (its inputs, with more options) in a child process, timed
/// from spawn to exit, so its peak memory is its own and the time is what a user waits.
pub fn refuse_run_child(
    inputs: &[&Path],
    options: &[&str],
    config: &Path,
    fused: &Path,
) -> Result<Measured> {
    let exe = std::env::current_exe()?;
    let started = Instant::now();
    let out = Command::new(&exe)
        .args(["refuse", "--json", "-q", "-c"])
        .arg(config)
        .arg("-o")
        .arg(fused)
        .args(options)
        .args(inputs)
        .output()?;
    let wall_s = started.elapsed().as_secs_f64();
    if !out.status.success() {
        bail!("refuse failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    let stats: RunStats = serde_json::from_value(v["run"].clone())?;
    let safety_epochs = v["eval"]["pipelines"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| p["safety"]["epochs"].as_u64())
        .collect();
    Ok(Measured {
        wall_s,
        peak_rss_kib: stats.peak_rss_kib,
        safety_epochs,
    })
}
