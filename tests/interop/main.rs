//! Interop: railfuse's outputs checked by clients written by others (the official Python
//! `mcap` reader with `jsonschema`, the `rerun` CLI, filterpy). `tests/run` installs them.

#[path = "../common/mod.rs"]
mod common;

use common::live::free_port;
use common::*;

mod mcap_reader;
mod numerics;
mod python_package;
mod viewer;

/// `railfuse refuse` of the short sample run with a config, and any further arguments.
fn refuse_short_run(config: &std::path::Path, out: &std::path::Path, extra: &[&str]) {
    let run = sample("short-run.mcap");
    let mut args = vec!["refuse", s(&run), "-c", s(config), "-o", s(out)];
    args.extend(extra);
    ok(&args);
}

/// Two figures equal but for the last bits (serde_json reads floats to within an ulp, and sums
/// in another order differ there).
fn close(a: &serde_json::Value, b: &serde_json::Value) {
    let (x, y) = (a.as_f64().unwrap(), b.as_f64().unwrap());
    assert!((x - y).abs() <= 1e-12 * y.abs().max(1e-300), "{x} vs {y}");
}
