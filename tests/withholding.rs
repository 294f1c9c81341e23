//! The withholding protocol: `refuse --withhold /gnss/fix --outages SPEC` hides the receiver
//! from the pipelines inside the outages, records them, and scores against what it hid; the
//! same from `[pipeline.eval]`; `eval` reads the windows back from the fused log. Bad
//! requests fail in one line before any work.

mod common;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{FusedDiagnostics, GnssFix};
use railfuse_catalog::topics;

/// (stamp → log time) of every GNSS fix of `log`.
fn fix_log_times(log: &Path) -> HashMap<u64, u64> {
    let mut out = HashMap::new();
    let mut r = LogReader::open(log).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec.unwrap() {
            if m.channel.topic == "/gnss/fix" {
                let f: GnssFix = m.decode(log).unwrap();
                out.insert(f.stamp_ns, m.log_time_ns);
            }
        }
    }
    out
}

/// Every `railfuse.withheld` record of `log`, by pipeline.
fn withheld_records(log: &Path) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    let mut r = LogReader::open(log).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Metadata { name, metadata } = rec.unwrap() {
            if name == topics::metadata::WITHHELD {
                out.insert(metadata["pipeline"].clone(), metadata);
            }
        }
    }
    out
}

fn windows(record: &BTreeMap<String, String>) -> Vec<(u64, u64)> {
    record["windows_log_time_ns"]
        .split(',')
        .map(|w| {
            let (a, b) = w.split_once('-').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect()
}

/// The position RMSE outside the withheld windows, from the whole run's and the windows'.
fn rmse_outside(p: &serde_json::Value) -> f64 {
    let whole = &p["position_error_m"];
    let inside = p["windows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["label"] == "withheld /gnss/fix")
        .expect("the outages are a marked window")["position_error_m"]
        .clone();
    let sq = |e: &serde_json::Value| {
        e["samples"].as_f64().unwrap() * e["rmse"].as_f64().unwrap().powi(2)
    };
    let n = whole["samples"].as_f64().unwrap() - inside["samples"].as_f64().unwrap();
    ((sq(whole) - sq(&inside)) / n).sqrt()
}

#[test]
fn the_receiver_is_hidden_inside_each_outage_and_the_pipeline_is_scored_against_it() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("s1.mcap");
    simulate(
        &["--scenario", "seed001", "--seed", "1", "--duration", "600"],
        &raw,
    );
    let cfg = sample("seed001.toml");
    let fused = d.path().join("s1.withheld.mcap");
    let out = ok_json(&[
        "refuse",
        s(&raw),
        "-c",
        s(&cfg),
        "-o",
        s(&fused),
        "--withhold",
        "/gnss/fix",
        "--outages",
        "standard",
        "--json",
    ]);
    // Recorded for every pipeline that fuses the receiver: 30 s from 60 s, 60 s from 240 s,
    // 120 s from 420 s (the run's first message is t0).
    let records = withheld_records(&fused);
    assert_eq!(
        records.keys().collect::<Vec<_>>(),
        ["fkf", "fkf_cal", "kf", "kf_cal"]
    );
    let w = windows(&records["kf"]);
    let first = *fix_log_times(&raw).values().min().unwrap();
    let t0 = {
        let mut r = LogReader::open(&raw).unwrap();
        let mut t0 = u64::MAX;
        while let Some(rec) = r.next() {
            if let LogRecord::Message(m) = rec.unwrap() {
                t0 = t0.min(m.log_time_ns);
            }
        }
        t0
    };
    assert!(first >= t0);
    let rel: Vec<(f64, f64)> = w
        .iter()
        .map(|(a, b)| ((a - t0) as f64 / 1e9, (b - a) as f64 / 1e9))
        .collect();
    assert_eq!(rel, [(60.0, 30.0), (240.0, 60.0), (420.0, 120.0)]);
    // The pipeline's input inside an outage holds no fix of the receiver: no diagnostics
    // record of a fix logged inside one, and fixes outside them are fused as before.
    let logged = fix_log_times(&raw);
    let inside = |t: u64| w.iter().any(|&(a, b)| (a..b).contains(&t));
    let diagnostics: Vec<FusedDiagnostics> = messages(&fused, "/fused/kf/diagnostics");
    let gnss: Vec<u64> = diagnostics
        .iter()
        .filter(|d| d.source == "/gnss/fix")
        .map(|d| logged[&d.stamp_ns])
        .collect();
    assert!(gnss.len() > 2000, "{} fixes fused", gnss.len());
    assert!(
        gnss.iter().all(|&t| !inside(t)),
        "a fix inside an outage reached the filter"
    );
    let hidden = logged.values().filter(|&&t| inside(t)).count() as u64;
    assert_eq!(out["refuse"]["withheld"]["kf"], hidden, "{}", out["refuse"]);
    // Scored against the withheld fixes (the reference unless told otherwise): at the end of
    // each outage the filter has coasted, and its error there is larger than outside them.
    assert_eq!(out["eval"]["reference"], "/gnss/fix");
    let kf = pipeline_eval(&out["eval"], "kf");
    let outside = rmse_outside(&kf);
    let each = kf["outages"]["each"].as_array().unwrap();
    assert_eq!(each.len(), 3);
    for o in each {
        let end = o["end_error_m"].as_f64().unwrap().abs();
        assert!(
            end > outside,
            "end of the outage at {} s: {end} m, outside the outages {outside} m",
            o["start_s"]
        );
        assert!(o["drift_percent"].as_f64().unwrap() > 0.0, "{o}");
    }
    let by_length: Vec<f64> = kf["outages"]["by_length"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["length_s"].as_f64().unwrap())
        .collect();
    assert_eq!(by_length, [30.0, 60.0, 120.0]);
    // `eval` of the written log finds the windows in it and gives the same table.
    let again = ok_json(&["eval", s(&fused), "--json"]);
    assert_eq!(again["reference"], "/gnss/fix");
    assert_eq!(pipeline_eval(&again, "kf")["outages"], kf["outages"]);
    let table = String::from_utf8(ok(&["eval", s(&fused)]).stdout).unwrap();
    assert!(
        table.contains("outages of /gnss/fix (errors along the track over the outages")
            && table.contains("in withheld /gnss/fix"),
        "{table}"
    );

    // The same from the configuration's [pipeline.eval]: the same fused states.
    let text = std::fs::read_to_string(&cfg).unwrap().replace(
        "name = \"kf\"\n",
        "name = \"kf\"\neval = { withhold = \"/gnss/fix\", outages = \"standard\" }\n",
    );
    let own = d.path().join("own.toml");
    std::fs::write(&own, text).unwrap();
    let by_config = d.path().join("by-config.mcap");
    let o = ok_json(&[
        "refuse",
        s(&raw),
        "-c",
        s(&own),
        "-o",
        s(&by_config),
        "--json",
    ]);
    assert_eq!(o["eval"]["reference"], "/gnss/fix");
    assert_eq!(
        o["refuse"]["withheld"].as_object().unwrap().len(),
        1,
        "only kf"
    );
    let states = |p: &Path| -> Vec<railfuse_catalog::messages::FusedState> {
        messages(p, "/fused/kf/state")
    };
    assert_eq!(states(&by_config), states(&fused));

    // The same outages scored on a log fused with the receiver everywhere (eval --withhold
    // on a log fused elsewhere): the pipeline saw those fixes, so its errors there are
    // smaller than when they were hidden from it; hiding is what makes the figure.
    let plain = d.path().join("plain.mcap");
    ok(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&plain)]);
    let seen = ok_json(&[
        "eval",
        s(&plain),
        "--withhold",
        "/gnss/fix",
        "--outages",
        "standard",
        "--json",
    ]);
    let seen_kf = pipeline_eval(&seen, "kf");
    let end_rms = |p: &serde_json::Value| -> f64 {
        let ends: Vec<f64> = p["outages"]["each"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o["end_error_m"].as_f64().unwrap())
            .collect();
        (ends.iter().map(|e| e * e).sum::<f64>() / ends.len() as f64).sqrt()
    };
    assert_eq!(seen_kf["outages"]["each"].as_array().unwrap().len(), 3);
    assert!(
        end_rms(&seen_kf) < end_rms(&kf),
        "seen {} m, withheld {} m",
        end_rms(&seen_kf),
        end_rms(&kf)
    );

    // Withheld for the whole run: no fix reaches the filter at all.
    let all = d.path().join("all.mcap");
    ok(&[
        "refuse",
        s(&raw),
        "-c",
        s(&cfg),
        "-o",
        s(&all),
        "--withhold",
        "/gnss/fix",
    ]);
    let diagnostics: Vec<FusedDiagnostics> = messages(&all, "/fused/kf/diagnostics");
    assert!(diagnostics.iter().all(|d| d.source != "/gnss/fix"));
}

#[test]
fn a_withholding_request_the_run_cannot_meet_fails_in_one_line_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("s1.mcap");
    simulate(
        &["--scenario", "seed001", "--seed", "1", "--duration", "120"],
        &raw,
    );
    let cfg = sample("seed001.toml");
    let out = d.path().join("out.mcap");
    for (args, says) in [
        (
            &["--withhold", "/gnss/fix", "--outages", "300"][..],
            "withhold /gnss/fix: outages '300': no outage fits in the run (120.0 s long",
        ),
        (
            &["--withhold", "/odometer/9"][..],
            "no channel /odometer/9 to withhold",
        ),
        (
            &["--withhold", "/gnss/fix", "--reference", "/imu"][..],
            "/imu (railfuse.Imu) cannot be a reference",
        ),
        (
            &["--withhold", "/gnss/fix", "--outages", "30s:evry=180"][..],
            "'evry=180' is neither every=PERIOD nor from=T",
        ),
        (
            &["--withhold", "/truth"][..],
            "withhold /truth: no pipeline fuses it",
        ),
    ] {
        let o = railfuse(&[&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&out)][..], args].concat());
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(
            err.lines().filter(|l| !l.trim().is_empty()).count() <= 3,
            "{args:?}: one line (clap adds its usage hint): {err}"
        );
        assert!(!out.exists(), "{args:?} wrote an output");
    }
    // A [pipeline.eval] naming a topic the pipeline does not fuse: its line and column.
    let text = std::fs::read_to_string(&cfg).unwrap().replace(
        "name = \"kf\"\n",
        "name = \"kf\"\neval = { withhold = \"/odometer/1\" }\n",
    );
    let bad = d.path().join("bad.toml");
    std::fs::write(&bad, text).unwrap();
    let err = stderr(&railfuse(&[
        "refuse",
        s(&raw),
        "-c",
        s(&bad),
        "-o",
        s(&out),
    ]));
    assert!(
        err.contains("pipeline 'kf': eval.withhold: /odometer/1 is not a sensor of this pipeline"),
        "{err}"
    );
}
