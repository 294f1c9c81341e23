//! What a run costs, as the commands and benchmarks report it: wall time and throughput, this
//! process's peak memory, and the Python a benchmark compares against.

use std::path::PathBuf;

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
