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

/// `railfuse simulate ARGS… -o OUT`, which must succeed.
pub fn simulate(args: &[&str], out: &Path) -> Output {
    let mut all = vec!["simulate"];
    all.extend_from_slice(args);
    all.extend(["-o", s(out)]);
    ok(&all)
}

/// `railfuse refuse RAW -c samples/CONFIG -o OUT`, which must succeed.
pub fn refuse(raw: &Path, config: &str, out: &Path) -> Output {
    ok(&["refuse", s(raw), "-c", s(&sample(config)), "-o", s(out)])
}

/// `railfuse ARGS`, which must succeed, with JSON on its standard output (`--json`).
pub fn ok_json(args: &[&str]) -> serde_json::Value {
    let out = ok(args);
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: {e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// `railfuse import --format eth` of one of samples/eth-pbl-railway/ into `log`.
pub fn import_eth(name: &str, log: &Path) {
    let src = sample("eth-pbl-railway").join(name);
    ok(&[
        "import",
        "--format",
        "eth",
        s(&src),
        "-o",
        s(log),
        "--quiet",
    ]);
}

/// `railfuse refuse --json` of `raw` with a sample config: the run's report as JSON.
pub fn refuse_json(raw: &Path, config: &str, out: &Path) -> serde_json::Value {
    let run = ok(&[
        "refuse",
        s(raw),
        "-c",
        s(&sample(config)),
        "-o",
        s(out),
        "--json",
    ]);
    serde_json::from_slice(&run.stdout).unwrap()
}

/// The accuracy of pipeline `name` in a `--json` report of `refuse` (its `eval`) or `eval`.
pub fn pipeline_eval(report: &serde_json::Value, name: &str) -> serde_json::Value {
    let evals = report.get("eval").unwrap_or(report)["pipelines"].as_array();
    evals
        .and_then(|p| p.iter().find(|p| p["name"] == name))
        .unwrap_or_else(|| panic!("no pipeline {name} in {report}"))
        .clone()
}

/// The one error line a failed command printed, after checking it failed.
pub fn fails(args: &[&str]) -> String {
    let o = railfuse(args);
    let err = stderr(&o);
    assert!(!o.status.success(), "{args:?} exited 0: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(lines.len(), 1, "{args:?}: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
        "{err}"
    );
    lines[0].to_owned()
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

/// A Python client script that must succeed; its standard output as JSON.
pub fn python_ok(script: &str, args: &[&str]) -> serde_json::Value {
    let out = python(script, args);
    assert!(
        out.status.success(),
        "{script} {args:?}: {}{}",
        stderr(&out),
        String::from_utf8_lossy(&out.stdout)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{script}: {e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// The `rerun` CLI, which must succeed; what it printed.
pub fn rerun_ok(args: &[&str]) -> String {
    let out = rerun(args);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert!(out.status.success(), "rerun {args:?}: {text}");
    text
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

/// A receiver's NMEA capture (50 RTK fixes, 50 sentences with a wrong checksum, 50 lines of
/// garbage) and a UBX capture (the real frames of an ETH sample with torn frames between).
pub fn captures(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let d = dir;
    let nmea = d.join("rx.nmea");
    let mut text = String::new();
    for k in 0..50 {
        let body = format!(
            "GNRMC,0835{:02}.00,A,4439.30664,N,01055.78382,E,10.0,90.0,201022,,,R,V",
            k % 60
        );
        let gga = format!(
            "GNGGA,0835{:02}.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000",
            k % 60
        );
        for b in [body, gga] {
            let cs = b.bytes().fold(0u8, |a, x| a ^ x);
            text += &format!("${b}*{cs:02X}\r\n");
        }
        text += "$GNGGA,083500.00,4439.3,N,01055.7,E,1,05,1.0,3.0,M,4.0,M,,*00\r\n"; // wrong checksum
        text += "\u{1}\u{2}garbage\r\n";
    }
    std::fs::write(&nmea, &text).unwrap();
    let ubx = d.join("rx.ubx");
    let hexes = std::fs::read_to_string(sample(
        "eth-pbl-railway/20221020_1030_R90117_Modena_SN2_sample.csv",
    ))
    .unwrap();
    let mut bytes = Vec::new();
    for l in hexes.lines().filter(|l| l.contains(",U,")) {
        let h = l.rsplit(',').next().unwrap();
        bytes.extend(
            (0..h.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&h[i..i + 2], 16).unwrap()),
        );
        bytes.extend_from_slice(b"\xb5\x62\x01\x07\x04\x00junk"); // a torn frame with a bad checksum
    }
    std::fs::write(&ubx, &bytes).unwrap();
    (nmea, ubx)
}
