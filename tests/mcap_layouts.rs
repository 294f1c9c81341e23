//! Every valid MCAP layout reads in every command. The official Python writer rewrites one
//! railfuse log in each layout the specification allows (chunks or none, summaries that repeat
//! channels and schemas or not, no summary, no message index, no statistics, compression,
//! metadata and attachments anywhere, log times out of order, a schemaless channel), and info,
//! refuse, eval, viz, tune and recover run on each: the same messages, the same fused result.
//! And a ROS 2 bag as rosbags writes it, in every command.

mod common;

use common::*;
use serde_json::Value;

fn json(out: &std::process::Output) -> Value {
    serde_json::from_slice(&out.stdout).unwrap()
}

/// (states, position RMSE, speed RMSE) of the first pipeline of a fused log.
fn accuracy(fused: &std::path::Path) -> (u64, f64, f64) {
    let e = json(&ok(&["eval", s(fused), "--json"]));
    let p = &e["pipelines"][0];
    (
        p["states"].as_u64().unwrap(),
        p["position_error_m"]["rmse"].as_f64().unwrap(),
        p["speed_error_mps"]["rmse"].as_f64().unwrap(),
    )
}

/// Three evaluations of a tuning of `pipeline`'s jerk on `log`.
fn tune_three(
    log: &std::path::Path,
    config: &std::path::Path,
    pipeline: &str,
    out: &std::path::Path,
) {
    ok(&[
        "tune",
        s(log),
        "-c",
        s(config),
        "--pipeline",
        pipeline,
        "--params",
        "motion.jerk_psd=0.001..10",
        "--max-evals",
        "3",
        "-o",
        s(out),
    ]);
}

#[test]
fn every_valid_layout_reads_in_every_command_with_the_same_result() {
    let d = tempfile::tempdir().unwrap();
    let written = python_ok(
        "mcap_layouts.py",
        &[s(&sample("short-run.mcap")), s(d.path())],
    );
    let messages = written["messages"].as_u64().unwrap();
    let mut baseline = None;
    let mut table = vec!["layout | info | refuse + eval | viz | tune | recover".to_owned()];
    for layout in written["layouts"].as_array().unwrap() {
        let layout = layout.as_str().unwrap();
        let log = d.path().join(format!("{layout}.mcap"));
        let extra = if layout == "schemaless_channel" {
            messages.div_ceil(100)
        } else {
            0
        };
        let info = json(&ok(&["info", s(&log), "--json"]));
        assert_eq!(
            info["messages"].as_u64(),
            Some(messages + extra),
            "{layout}"
        );
        // Gaps in log-time order: the same as the original's whatever the file order.
        let truth = info["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == "/truth")
            .unwrap();
        assert!(
            truth["largest_gap_s"].as_f64().unwrap() < 0.0101,
            "{layout}: {truth}"
        );

        let fused = d.path().join(format!("{layout}.fused.mcap"));
        refuse(&log, "kalman.toml", &fused);
        let got = accuracy(&fused);
        same_accuracy_as_the_original(layout, got, *baseline.get_or_insert(got));
        let rrd = d.path().join(format!("{layout}.rrd"));
        ok(&["viz", s(&log), "--save", s(&rrd)]);
        let verify = rerun(&["rrd", "verify", s(&rrd)]);
        assert!(verify.status.success(), "{layout}: {}", stderr(&verify));

        tune_three(
            &log,
            &sample("kalman.toml"),
            "kalman",
            &d.path().join(format!("{layout}.toml")),
        );

        let salvaged = d.path().join(format!("{layout}.recovered.mcap"));
        let r = json(&ok(&["recover", s(&log), "-o", s(&salvaged), "--json"]));
        assert_eq!(
            r["messages"].as_u64(),
            Some(messages + extra),
            "{layout}: {r}"
        );
        table.push(format!(
            "{layout} | {} msgs | {} states, RMSE {:.3} m | verified | ok | {} msgs",
            messages + extra,
            got.0,
            got.1,
            r["messages"]
        ));
    }
    println!("{}", table.join("\n"));
}

/// A layout reads as the original does: the same states and errors, but where measurements
/// arrive out of order (the reorder window takes most, not all).
fn same_accuracy_as_the_original(layout: &str, got: (u64, f64, f64), base: (u64, f64, f64)) {
    if layout == "log_times_out_of_order" {
        assert!(
            got.0 as f64 > 0.99 * base.0 as f64,
            "{layout}: {got:?} against {base:?}"
        );
        assert!(
            got.1 < 1.2 * base.1 && got.2 < 1.2 * base.2,
            "{layout}: {got:?} against {base:?}"
        );
    } else {
        assert_eq!(got, base, "{layout}");
    }
}

/// A ROS 2 bag as rosbags writes one (MCAP storage, CDR, its own chunking and summary) in
/// every command, with the default pipeline its topics give and the bag's track.
#[test]
fn a_ros2_bag_written_by_rosbags_reads_in_every_command() {
    let d = tempfile::tempdir().unwrap();
    let py = python("ros2_bag.py", &[s(&sample("short-run.mcap")), s(d.path())]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let counts: Value = serde_json::from_slice(&py.stdout).unwrap();
    let messages: u64 = counts
        .as_object()
        .unwrap()
        .values()
        .filter_map(Value::as_u64)
        .sum();
    let bag = d.path().join("bag/bag.mcap");
    let info = json(&ok(&["info", s(&bag), "--json"]));
    assert_eq!(info["messages"].as_u64(), Some(messages), "{info}");

    let (fused, config) = (d.path().join("bag.fused.mcap"), d.path().join("bag.toml"));
    let track = d.path().join("line.geojson");
    ok(&[
        "refuse",
        s(&bag),
        "--track",
        s(&track),
        "--save-config",
        s(&config),
        "-o",
        s(&fused),
    ]);
    // No ground truth in a bag: the table has the states, NIS and counts.
    let e = json(&ok(&["eval", s(&fused), "--json"]));
    let states = e["pipelines"][0]["states"].as_u64().unwrap();
    assert!(states > 1000, "{e}");

    let rrd = d.path().join("bag.rrd");
    ok(&["viz", s(&fused), "--save", s(&rrd)]);
    let verify = rerun(&["rrd", "verify", s(&rrd)]);
    assert!(verify.status.success(), "{}", stderr(&verify));

    tune_three(&bag, &config, "default", &d.path().join("bag.tuned.toml"));
    let salvaged = d.path().join("bag.recovered.mcap");
    let r = json(&ok(&["recover", s(&bag), "-o", s(&salvaged), "--json"]));
    assert_eq!(r["messages"].as_u64(), Some(messages), "{r}");
    println!(
        "rosbags bag | {messages} msgs | {states} states (default pipeline, no truth) | verified | ok | {} msgs",
        r["messages"]
    );
}
