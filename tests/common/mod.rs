//! Helpers shared by the end-to-end tests: run the real `railfuse` binary and the real
//! third-party clients.

#![allow(dead_code)]

pub mod live;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn railfuse(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args(args)
        .output()
        .expect("the railfuse binary runs")
}

pub fn ok(args: &[&str]) -> Output {
    let out = railfuse(args);
    assert!(
        out.status.success(),
        "railfuse {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub fn sample(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("samples")
        .join(name)
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// A third-party client installed by tests/run. Missing clients fail the test (they are part
/// of the suite), with the command that installs them.
pub fn client(var: &str, venv_name: &str) -> PathBuf {
    if let Ok(p) = std::env::var(var) {
        return PathBuf::from(p);
    }
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(".venv-interop/bin")
        .join(venv_name);
    assert!(
        p.exists(),
        "{var} is not set and {} is missing: run the tests with `tests/run`, which installs it",
        p.display()
    );
    p
}

pub fn python(script: &str, args: &[&str]) -> Output {
    let py = client("RAILFUSE_PYTHON", "python");
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/interop")
        .join(script);
    Command::new(py)
        .arg(script)
        .args(args)
        .output()
        .expect("python runs")
}

pub fn rerun(args: &[&str]) -> Output {
    Command::new(client("RAILFUSE_RERUN", "rerun"))
        .env("RERUN_ANALYTICS", "0")
        .args(args)
        .output()
        .expect("rerun runs")
}

/// Every message on `topic` of a log, decoded, in file order.
pub fn messages<M: railfuse_catalog::messages::ChannelMessage>(path: &Path, topic: &str) -> Vec<M> {
    let mut out = Vec::new();
    let mut r = railfuse_catalog::log::LogReader::open(path).unwrap();
    while let Some(rec) = r.next() {
        if let railfuse_catalog::log::LogRecord::Message(m) = rec.unwrap() {
            if m.channel.topic == topic {
                out.push(m.decode(path).unwrap());
            }
        }
    }
    out
}

/// The truth sample nearest at or after `t` (truth runs at 100 Hz), the last one past the end.
pub fn truth_at(
    truth: &[railfuse_catalog::messages::GroundTruth],
    t: u64,
) -> &railfuse_catalog::messages::GroundTruth {
    let i = truth
        .partition_point(|g| g.stamp_ns < t)
        .min(truth.len() - 1);
    &truth[i]
}
