//! Every command tried as a new user would: the README's examples and their obvious
//! variations. Wrong input is one clear line and a non-zero exit, never a silent 0; help
//! lists what the parser takes; no command leaves an output that looks complete after failing.

mod common;

use std::path::Path;

use common::*;

/// The one line a failed command printed, after checking it failed.
fn fails(args: &[&str]) -> String {
    let o = railfuse(args);
    let err = stderr(&o);
    assert!(!o.status.success(), "{args:?} exited 0: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{args:?}: {err}");
    assert!(!err.contains("panicked") && !err.contains("RUST_BACKTRACE"), "{err}");
    lines[0].to_owned()
}

fn exists(p: &Path) -> bool {
    p.exists()
}

#[test]
fn every_reading_command_reports_a_damaged_log_as_info_does_and_leaves_no_output() {
    let d = tempfile::tempdir().unwrap();
    let log = sample("short-run.mcap");
    let bytes = std::fs::read(&log).unwrap();
    // Cut short (a recording cut off) and a chunk with a flipped byte (its CRC fails).
    let cut = d.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let flipped = d.path().join("flipped.mcap");
    let mut b = bytes.clone();
    let mid = b.len() / 2;
    b[mid] ^= 0xff;
    std::fs::write(&flipped, &b).unwrap();
    let config = sample("kalman.toml");
    for damaged in [&cut, &flipped] {
        let (fused, rrd, tuned) = (
            d.path().join("o.mcap"),
            d.path().join("o.rrd"),
            d.path().join("t.toml"),
        );
        for args in [
            vec!["info", s(damaged)],
            vec!["refuse", s(damaged), "-c", s(&config), "-o", s(&fused)],
            vec!["eval", s(damaged)],
            vec!["viz", s(damaged), "--save", s(&rrd)],
            vec![
                "tune",
                s(damaged),
                "-c",
                s(&config),
                "--pipeline",
                "kalman",
                "--params",
                "motion.jerk_psd=0.01..1",
                "--max-evals",
                "2",
                "-o",
                s(&tuned),
            ],
        ] {
            let line = fails(&args);
            assert!(
                line.contains("damaged at byte") && line.contains("railfuse recover"),
                "{args:?}: {line}"
            );
        }
        for out in ["o.mcap", "o.mcap.partial", "o.rrd", "o.rrd.partial", "t.toml"] {
            assert!(!exists(&d.path().join(out)), "{out} left after {damaged:?}");
        }
    }
}
