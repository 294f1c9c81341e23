//! End-to-end tests of the `railfuse` binary: what a user runs, on real files.

#[path = "../common/mod.rs"]
mod common;

use common::*;

mod bad_input;
mod eval;
mod import;

#[test]
fn simulation_is_deterministic_for_a_seed_and_differs_across_seeds() {
    let d = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        d.path().join("a.mcap"),
        d.path().join("b.mcap"),
        d.path().join("c.mcap"),
    );
    simulate(
        &["--scenario", "default", "--seed", "3", "--duration", "40"],
        &a,
    );
    simulate(
        &["--scenario", "default", "--seed", "3", "--duration", "40"],
        &b,
    );
    simulate(
        &["--scenario", "default", "--seed", "4", "--duration", "40"],
        &c,
    );
    let (a, b, c) = (
        std::fs::read(a).unwrap(),
        std::fs::read(b).unwrap(),
        std::fs::read(c).unwrap(),
    );
    assert_eq!(a, b);
    assert_ne!(a, c);
}

#[test]
fn info_reports_channels_rates_gaps_metadata_and_fused_pipelines() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "1", "--duration", "120"], &raw);
    let info: serde_json::Value = ok_json(&["info", s(&raw), "--json"]);
    let topic = |t: &str| {
        info["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == t)
            .cloned()
            .unwrap_or_else(|| panic!("{t}"))
    };
    let imu = topic("/imu");
    assert!(
        (imu["mean_rate_hz"].as_f64().unwrap() - 200.0).abs() < 1.0,
        "{imu}"
    );
    assert_eq!(topic("/gnss/fix")["schema"], "railfuse.GnssFix");
    assert!((topic("/gnss/fix")["mean_rate_hz"].as_f64().unwrap() - 10.0).abs() < 0.2);
    assert_eq!(topic("/track/map")["messages"], 1);
    // Balises lie about 1 km apart: tens of seconds between passages.
    assert!(topic("/balise")["largest_gap_s"].as_f64().unwrap() > 20.0);
    let run = info["metadata"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m[0] == "railfuse.run")
        .unwrap();
    assert_eq!(run[1]["scenario"], "default");
    assert!(run[1]["scenario_parameters"]
        .as_str()
        .unwrap()
        .contains("\"gnss\""));
    assert_eq!(info["fused_pipelines"].as_array().unwrap().len(), 0);

    refuse(&raw, "kalman.toml", &fused);
    let info: serde_json::Value = ok_json(&["info", s(&fused), "--json"]);
    assert_eq!(info["fused_pipelines"], serde_json::json!(["kalman"]));
    let text = String::from_utf8(ok(&["info", s(&fused)]).stdout).unwrap();
    assert!(
        text.contains("/fused/kalman/state") && text.contains("fused pipelines: kalman"),
        "{text}"
    );
}

#[test]
fn refuse_copies_every_input_record_and_reports_accuracy() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused, again) = (
        d.path().join("run.mcap"),
        d.path().join("f.mcap"),
        d.path().join("g.mcap"),
    );
    simulate(&["--seed", "2", "--duration", "150"], &raw);
    let r = refuse_json(&raw, "kalman.toml", &fused);
    let p = &r["eval"]["pipelines"][0];
    assert_eq!(r["eval"]["reference"], "/truth");
    assert_eq!(p["states"], r["refuse"]["pipelines"][0]["fused_states"]);
    assert!(p["states"].as_u64().unwrap() > 1000);
    // The Kalman filter's innovations are consistent: NIS inside its 95 % bounds ≈ 95 %.
    assert!(
        (0.85..=0.99).contains(&p["nis"]["inside_95"].as_f64().unwrap()),
        "{p}"
    );
    // The default pipeline on the default run: sub-metre position, sub-0.3 m/s speed.
    assert!(p["position_error_m"]["rmse"].as_f64().unwrap() < 1.0, "{p}");
    assert!(p["speed_error_mps"]["rmse"].as_f64().unwrap() < 0.3, "{p}");

    let raw_info: serde_json::Value = ok_json(&["info", s(&raw), "--json"]);
    let fused_info: serde_json::Value = ok_json(&["info", s(&fused), "--json"]);
    for c in raw_info["channels"].as_array().unwrap() {
        let f = fused_info["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["topic"] == c["topic"])
            .unwrap();
        assert_eq!(c, f, "copied channel differs");
    }
    // Re-fusing a fused file replaces that pipeline's channels instead of adding more.
    refuse(&fused, "kalman.toml", &again);
    let again_info: serde_json::Value = ok_json(&["info", s(&again), "--json"]);
    let n = |v: &serde_json::Value| v["channels"].as_array().unwrap().len();
    assert_eq!(n(&again_info), n(&fused_info));
    let pipelines = again_info["metadata"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|m| m[0] == "railfuse.pipeline")
        .count();
    assert_eq!(pipelines, 1);
}

fn assert_one_clear_line(out: &std::process::Output, must_contain: &[&str]) {
    assert!(!out.status.success());
    let err = stderr(out);
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
        "{err}"
    );
    for m in must_contain {
        assert!(err.contains(m), "{err:?} lacks {m:?}");
    }
}

#[test]
fn the_samples_refuse_as_the_readme_says() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("sample.fused.mcap");
    let r = ok(&[
        "refuse",
        s(&sample("short-run.mcap")),
        "-c",
        s(&sample("kalman.toml")),
        "-o",
        s(&out),
    ]);
    let table = String::from_utf8(r.stdout).unwrap();
    assert!(
        table.contains("pos RMSE m") && table.contains("kalman"),
        "{table}"
    );
    // The motion models and the particle filter side by side, each under a metre.
    let r = ok(&[
        "refuse",
        s(&sample("short-run.mcap")),
        "-c",
        s(&sample("models.toml")),
        "-o",
        s(&out),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let names: Vec<&str> = v["eval"]["pipelines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["cv", "ca", "singer", "pf"]);
    for p in v["eval"]["pipelines"].as_array().unwrap() {
        assert!(p["position_error_m"]["rmse"].as_f64().unwrap() < 1.0, "{p}");
    }
}

#[test]
fn sensor_states_shrink_the_default_runs_errors_and_make_its_covariance_honest() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused, cfg) = (
        d.path().join("run.mcap"),
        d.path().join("run.fused.mcap"),
        d.path().join("both.toml"),
    );
    simulate(&["--seed", "2"], &raw);
    // Both samples side by side, as `railfuse demo` runs them.
    let text = [sample("kalman.toml"), sample("sensor-states.toml")]
        .map(|p| std::fs::read_to_string(p).unwrap())
        .join("\n");
    std::fs::write(&cfg, text).unwrap();
    let r: serde_json::Value =
        ok_json(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused), "--json"]);
    let p = |name: &str| pipeline_eval(&r, name);
    let (plain, cal) = (p("kalman"), p("kalman_cal"));
    let f = |p: &serde_json::Value, path: [&str; 2]| p[path[0]][path[1]].as_f64().unwrap();
    for path in [
        ["position_error_m", "rmse"],
        ["position_error_m", "max_abs"],
        ["speed_error_mps", "rmse"],
    ] {
        assert!(
            f(&cal, path) < 0.8 * f(&plain, path),
            "{path:?}: kalman_cal {} vs kalman {}",
            f(&cal, path),
            f(&plain, path)
        );
    }
    // White-noise sensor models leave the covariance far too small; with the loop's survey
    // scale, the radar's and odometers' scale factors and the odometers' window modelled the
    // NEES lies inside its 95 % interval most of the time.
    assert!(
        f(&plain, ["nees", "inside_95"]) < 0.5 && f(&cal, ["nees", "inside_95"]) > 0.8,
        "{plain} {cal}"
    );
    // Against the GNSS, silent in the tunnel: scored at the fixes, so nothing inside the
    // outage is scored against a line drawn across it.
    let g: serde_json::Value = ok_json(&["eval", s(&fused), "--reference", "/gnss/fix", "--json"]);
    for p in g["pipelines"].as_array().unwrap() {
        let tunnel = p["windows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|w| w["label"] == "tunnel");
        let scored = tunnel.map_or(0, |w| {
            w["position_error_m"]["samples"].as_u64().unwrap_or(0)
        });
        assert_eq!(
            scored, 0,
            "{}: {scored} states scored in the tunnel",
            p["name"]
        );
        assert!(
            p["reference_fixes"]["matched"].as_u64().unwrap() > 100,
            "{p}"
        );
    }
}

#[test]
fn a_pipeline_without_a_position_sensor_starts_at_distance_zero_or_where_told() {
    let d = tempfile::tempdir().unwrap();
    let run = sample("short-run.mcap");
    let speed_only = "[[pipeline]]\nname = \"odo\"\nfilter = \"kalman\"\n\
        motion = { model = \"constant_acceleration\", jerk_psd = 0.2 }\n\
        [[pipeline.sensor]]\ntopic = \"/radar/speed\"\nvariance = 0.1\n\
        [[pipeline.sensor]]\ntopic = \"/odometer/1\"\nvariance = 0.1\n\
        [[pipeline.sensor]]\ntopic = \"/odometer/2\"\nvariance = 0.1\n";
    let told = speed_only.replace("name = \"odo\"", "name = \"told\"")
        + "[pipeline.initial]\nchainage_m = 1234.5\nchainage_std_m = 2.0\n";
    let truth: Vec<railfuse_catalog::messages::GroundTruth> = messages(&run, "/truth");
    let travelled = truth.last().unwrap().chainage_m - truth[0].chainage_m;
    for (name, text, start) in [("odo", speed_only.to_owned(), 0.0), ("told", told, 1234.5)] {
        let (cfg, out) = (
            d.path().join(format!("{name}.toml")),
            d.path().join(format!("{name}.mcap")),
        );
        std::fs::write(&cfg, text).unwrap();
        let o = ok(&["refuse", s(&run), "-c", s(&cfg), "-o", s(&out), "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let counts = &v["refuse"]["pipelines"][0]["counts"];
        assert_eq!(counts["before_initialisation"], 0, "{name}: {counts}");
        let states: Vec<railfuse_catalog::messages::FusedState> =
            messages(&out, &format!("/fused/{name}/state"));
        assert!(states.len() > 1000, "{name}: {} states", states.len());
        assert!(
            (states[0].chainage_m - start).abs() < 0.5,
            "{name}: {}",
            states[0].chainage_m
        );
        assert!(
            states[0].covariance[0] < 4.5,
            "{name}: starts with the given spread"
        );
        // Distance travelled from speeds alone, within 2 % of the truth.
        let moved = states.last().unwrap().chainage_m - states[0].chainage_m;
        assert!(
            (moved - travelled).abs() < 0.02 * travelled,
            "{name}: {moved} vs {travelled}"
        );
    }
}

/// The Foxglove twins sit beside railfuse's channels without changing them, and
/// `--no-foxglove` leaves them out.
#[test]
fn foxglove_twins_are_added_beside_the_channels_and_left_out_on_request() {
    let d = tempfile::tempdir().unwrap();
    let topics = |path: &std::path::Path| -> Vec<(String, u64)> {
        let info: serde_json::Value = ok_json(&["info", s(path), "--json"]);
        let mut t: Vec<_> = info["channels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                (
                    c["topic"].as_str().unwrap().to_owned(),
                    c["messages"].as_u64().unwrap(),
                )
            })
            .collect();
        t.sort();
        t
    };
    let (with, without) = (d.path().join("with.mcap"), d.path().join("without.mcap"));
    simulate(&["--duration", "30"], &with);
    ok(&[
        "--no-foxglove",
        "simulate",
        "--duration",
        "30",
        "-o",
        s(&without),
    ]);
    let (with, without) = (topics(&with), topics(&without));
    assert!(
        without.iter().all(|(t, _)| !t.starts_with("/foxglove")),
        "{without:?}"
    );
    let own: Vec<_> = with
        .iter()
        .filter(|(t, _)| !t.starts_with("/foxglove"))
        .cloned()
        .collect();
    assert_eq!(own, without, "the twins changed railfuse's own channels");
    for twin in [
        "/foxglove/gnss/fix",
        "/foxglove/track/map",
        "/foxglove/events",
    ] {
        assert!(
            with.iter().any(|(t, n)| t == twin && *n > 0),
            "no {twin}: {with:?}"
        );
    }
}

/// `viz --pipelines`, `--topics` and `--from/--to` choose what reaches the recording; a window
/// the wrong way round is one clear line.
#[test]
fn viz_shows_the_chosen_pipelines_topics_and_window() {
    let d = tempfile::tempdir().unwrap();
    let fused = d.path().join("f.mcap");
    ok(&[
        "refuse",
        s(&sample("short-run.mcap")),
        "-c",
        s(&sample("models.toml")),
        "-o",
        s(&fused),
    ]);
    let viz = |extra: &[&str]| -> serde_json::Value {
        let rrd = d.path().join("v.rrd");
        let mut args = vec!["viz", s(&fused), "--save", s(&rrd), "--json"];
        args.extend(extra);
        serde_json::from_slice(&ok(&args).stdout).unwrap()
    };
    let has =
        |v: &serde_json::Value, e: &str| v["entities"].as_array().unwrap().iter().any(|x| x == e);
    let all = viz(&[]);
    for p in ["ca", "cv", "singer", "pf"] {
        assert!(has(&all, &format!("chainage_error/{p}")), "{all}");
    }
    let one = viz(&["--pipelines", "pf"]);
    assert!(
        has(&one, "chainage_error/pf") && !has(&one, "chainage_error/ca"),
        "{one}"
    );
    let radar_only = viz(&["--topics", "/radar/speed"]);
    assert!(has(&radar_only, "speed/radar") && !has(&radar_only, "speed/odometer_1"));
    // The truth is always read: the errors still have their reference.
    assert!(has(&radar_only, "chainage_error/ca"), "{radar_only}");
    // A third of the 90 s run gives about a third of the rows.
    let (rows, window) = (
        all["rows"].as_u64().unwrap() as f64,
        viz(&["--from", "30", "--to", "60"])["rows"]
            .as_u64()
            .unwrap() as f64,
    );
    assert!(
        window > 0.2 * rows && window < 0.5 * rows,
        "{window} of {rows}"
    );
    let bad = railfuse(&[
        "viz",
        s(&fused),
        "--save",
        "x.rrd",
        "--from",
        "60",
        "--to",
        "30",
    ]);
    assert_one_clear_line(&bad, &["--from 60 must be before --to 30"]);
}

/// A log written by an older railfuse, every channel JSON (samples/short-run.mcap, kept as it
/// was written, before protobuf): every command that reads logs reads it as it did.
#[test]
fn an_old_all_json_log_still_reads_in_every_command() {
    let d = tempfile::tempdir().unwrap();
    let old = sample("short-run.mcap");
    let info = ok_json(&["info", s(&old), "--json"]);
    let channels = info["channels"].as_array().unwrap();
    assert!(channels.len() > 5, "{info}");
    assert!(
        channels.iter().all(|c| c["message_encoding"] == "json"),
        "{info}"
    );
    let fused = d.path().join("f.mcap");
    let r = refuse_json(&old, "kalman.toml", &fused);
    assert!(
        r["refuse"]["pipelines"][0]["fused_states"].as_u64() > Some(100),
        "{r}"
    );
    let e = ok_json(&["eval", s(&fused), "--json"]);
    // (The same figure, summed in another order: equal to the last bits.)
    let rmse = |v: &serde_json::Value| v["position_error_m"]["rmse"].as_f64().unwrap();
    let (a, b) = (rmse(&e["pipelines"][0]), rmse(&r["eval"]["pipelines"][0]));
    assert!((a - b).abs() < 1e-12 * b, "{a} vs {b}");
    ok(&["viz", s(&old), "--save", s(&d.path().join("v.rrd"))]);
    let salvaged = ok_json(&[
        "recover",
        s(&old),
        "-o",
        s(&d.path().join("r.mcap")),
        "--json",
    ]);
    assert_eq!(salvaged["messages"], info["messages"], "{salvaged}");
}
