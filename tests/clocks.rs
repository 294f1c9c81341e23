//! Several recorders on their own clocks read as one run: each recorder's offset and drift
//! recovered from the GNSS time it logged (within 1 ms and 1 ppm of the simulator's), and the
//! run re-fused with `--align gnss` as accurately as the same run written by one recorder.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::run::ClockMap;

/// The simulator's truth about a recorder's clock, from its file's run metadata.
fn true_clock(file: &Path) -> ClockMap {
    let mut r = LogReader::open(file).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Metadata { name, metadata } = rec.unwrap() {
            if name == "railfuse.run" {
                let get = |k: &str| metadata[k].clone();
                return ClockMap {
                    offset_ns: get("recorder_clock_offset_ns").parse().unwrap(),
                    drift_ppm: get("recorder_clock_drift_ppm").parse().unwrap(),
                    origin_ns: get("recorder_clock_origin_ns").parse().unwrap(),
                };
            }
        }
    }
    panic!("{}: no run metadata", file.display())
}

const RECORDERS: [&str; 3] = ["box", "rack=+0.35,+20ppm", "radar=-1.2,-15ppm"];

/// The run simulated by three recorders into `d`/three; their files.
fn three_recorders(d: &Path, seed: &str) -> Vec<PathBuf> {
    let dir = d.join("three");
    let mut args = vec!["simulate", "--duration", "300", "--seed", seed];
    for r in RECORDERS {
        args.extend(["--recorder", r]);
    }
    args.extend(["-o", s(&dir)]);
    ok(&args);
    ["box", "rack", "radar"]
        .iter()
        .map(|n| dir.join(format!("{n}.mcap")))
        .collect()
}

#[test]
fn each_recorder_s_offset_and_drift_are_recovered_within_1_ms_and_1_ppm() {
    let d = tempfile::tempdir().unwrap();
    let files = three_recorders(d.path(), "3");
    let mut args = vec!["info", "--json"];
    args.extend(files.iter().map(|f| s(f)));
    let info = ok_json(&args);
    let estimates = info["clocks"]["estimates"].as_array().unwrap();
    assert_eq!(estimates.len(), 3, "{}", info["clocks"]);
    for (file, e) in files.iter().zip(estimates) {
        let e = &e["Ok"];
        assert_eq!(e["source"], "time_reference", "{e}");
        let est: ClockMap = ClockMap {
            offset_ns: e["clock"]["offset_ns"].as_i64().unwrap(),
            drift_ppm: e["clock"]["drift_ppm"].as_f64().unwrap(),
            origin_ns: e["clock"]["origin_ns"].as_u64().unwrap(),
        };
        let truth = true_clock(file);
        // Over the whole run: the GNSS time each assigns to the recorder's clock readings.
        for after_s in [0u64, 100, 200, 300] {
            let local = truth.origin_ns + after_s * 1_000_000_000;
            let error_ns = est.correct(local) as f64 - truth.correct(local) as f64;
            assert!(
                error_ns.abs() < 1e6,
                "{}: {error_ns} ns off at {after_s} s",
                file.display()
            );
        }
        let drift_error = est.drift_ppm - truth.drift_ppm;
        assert!(
            drift_error.abs() < 1.0,
            "{}: drift {drift_error} ppm off",
            file.display()
        );
        eprintln!(
            "{}: offset {} ns (true {}), drift {:.3} ppm (true {:.3})",
            file.display(),
            est.offset_ns,
            truth.offset_ns,
            est.drift_ppm,
            truth.drift_ppm
        );
    }
}

#[test]
fn three_recorders_aligned_by_gnss_refuse_as_accurately_as_one() {
    let d = tempfile::tempdir().unwrap();
    let one = d.path().join("one.mcap");
    simulate(&["--duration", "300", "--seed", "4"], &one);
    let files = three_recorders(d.path(), "4");
    let rmse = |report: &serde_json::Value| {
        pipeline_eval(report, "kalman")["position_error_m"]["rmse"]
            .as_f64()
            .unwrap()
    };
    let single = rmse(&refuse_json(
        &one,
        "kalman.toml",
        &d.path().join("one.fused.mcap"),
    ));
    let refuse_three = |align: &str, out: &str| {
        let mut args = vec!["refuse"];
        args.extend(files.iter().map(|f| s(f)));
        let out = d.path().join(out);
        let config = sample("kalman.toml");
        args.extend(["-c", s(&config), "--align", align, "-o", s(&out), "--json"]);
        let report: serde_json::Value = serde_json::from_slice(&ok(&args).stdout).unwrap();
        rmse(&report)
    };
    let aligned = refuse_three("gnss", "aligned.fused.mcap");
    let unaligned = refuse_three("none", "unaligned.fused.mcap");
    // The same from the configuration's [run] table (a bare file name names the run's file).
    let config = d.path().join("kalman-run.toml");
    let text = std::fs::read_to_string(sample("kalman.toml")).unwrap()
        + "\n[run]\nalign = \"gnss\"\nclock_offsets = [\"radar.mcap=-1.2,-15ppm\"]\n";
    std::fs::write(&config, text).unwrap();
    let mut args = vec!["refuse"];
    args.extend(files.iter().map(|f| s(f)));
    let out = d.path().join("configured.fused.mcap");
    args.extend(["-c", s(&config), "-o", s(&out), "--json"]);
    let configured = rmse(&serde_json::from_slice(&ok(&args).stdout).unwrap());
    assert!(
        (configured - aligned).abs() <= 0.02 * single,
        "{configured} against {aligned}"
    );
    eprintln!("position RMSE: one recorder {single:.4} m, three aligned {aligned:.4} m, three on their own clocks {unaligned:.4} m");
    assert!(
        (aligned - single).abs() <= 0.02 * single,
        "aligned {aligned} m against one recorder's {single} m"
    );
    // The offsets matter: on their own clocks the same files fuse far worse.
    assert!(unaligned > 3.0 * single, "unaligned {unaligned} m");
}

#[test]
fn a_folder_of_several_recorders_files_read_as_one_input_is_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let files = three_recorders(d.path(), "5");
    let dir = files[0].parent().unwrap();
    let out = railfuse(&["info", s(dir), "--align", "gnss"]);
    let e = stderr(&out);
    assert!(!out.status.success());
    assert!(
        e.contains("on another clock than") && e.contains("an input of its own"),
        "{e}"
    );
    assert_eq!(e.trim().lines().count(), 1, "{e}");
}

#[test]
fn align_gnss_on_a_run_without_gnss_time_says_so() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("seed000.mcap");
    simulate(&["--scenario", "seed000", "--duration", "20"], &log);
    let out = railfuse(&["info", s(&log), "--align", "gnss"]);
    let e = stderr(&out);
    assert!(!out.status.success());
    assert!(e.contains("no input carries GNSS time"), "{e}");
}
