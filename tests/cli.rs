//! End-to-end tests of the `railfuse` binary: what a user runs, on real files.

mod common;

use common::*;

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
    let info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&raw), "--json"]).stdout).unwrap();
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
    let info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&fused), "--json"]).stdout).unwrap();
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
    let out = ok(&[
        "refuse",
        s(&raw),
        "-c",
        s(&sample("kalman.toml")),
        "-o",
        s(&fused),
        "--json",
    ]);
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
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

    let raw_info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&raw), "--json"]).stdout).unwrap();
    let fused_info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&fused), "--json"]).stdout).unwrap();
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
    let again_info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&again), "--json"]).stdout).unwrap();
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
fn bad_files_get_one_clear_line_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("run.mcap");
    simulate(&["--seed", "1", "--duration", "30"], &raw);
    let bytes = std::fs::read(&raw).unwrap();
    let empty = d.path().join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let truncated = d.path().join("truncated.mcap");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let text = d.path().join("notes.mcap");
    std::fs::write(&text, b"this is not an MCAP file, just some notes\n").unwrap();
    let missing = d.path().join("missing.mcap");
    let cfg = sample("kalman.toml");
    let out = d.path().join("out.mcap");
    let rrd = d.path().join("out.rrd");
    for (file, cause) in [
        (&empty, "empty"),
        (&truncated, "truncated"),
        (&text, "magic"),
        (&missing, "No such file"),
    ] {
        assert_one_clear_line(&railfuse(&["info", s(file)]), &[s(file), cause]);
        assert_one_clear_line(
            &railfuse(&["refuse", s(file), "-c", s(&cfg), "-o", s(&out)]),
            &[s(file), cause],
        );
        assert_one_clear_line(
            &railfuse(&["viz", s(file), "--save", s(&rrd)]),
            &[s(file), cause],
        );
        assert!(!out.exists(), "a failed refuse left an output behind");
    }
}

#[test]
fn bad_configs_name_the_line_column_or_channel() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("run.mcap");
    simulate(&["--scenario", "seed000", "--seed", "1"], &raw);
    let out = d.path().join("out.mcap");
    let good = std::fs::read_to_string(sample("seed000.toml")).unwrap();
    let write = |name: &str, text: String| {
        let p = d.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let line_of = |text: &str| {
        format!(
            "line {}, column",
            good.lines().position(|l| l.starts_with(text)).unwrap() + 1
        )
    };
    // (file, edit of the sample, what its one line must say)
    let cases: Vec<(&str, String, Vec<String>)> = vec![
        (
            "unknown.toml",
            good.replacen("reorder_window_s = 0.0", "reorder_windw_s = 0.0", 1),
            vec![
                "unknown.toml".into(),
                line_of("reorder_window_s") + " 1",
                "unknown field `reorder_windw_s`".into(),
            ],
        ),
        (
            "type.toml",
            good.replacen("variance = 0.01", "variance = true", 1),
            vec![
                "type.toml".into(),
                line_of("variance = 0.01") + " 12",
                "a variance".into(),
            ],
        ),
        // seed000 logs have no odometer: a sensor that requires one names the channel.
        (
            "missing.toml",
            good.replacen("\"/radar/speed\"", "\"/odometer/1\"\nrequired = true", 1),
            vec!["/odometer/1".into(), "is not in the file".into(), "kf_no_balise".into()],
        ),
        (
            "schema.toml",
            good.replacen("/radar/speed", "/truth", 1),
            vec!["/truth".into(), "railfuse.GroundTruth".into()],
        ),
        // A radar gives speed only: a position bias for it could never be observed.
        (
            "state.toml",
            good.replacen(
                "\"/radar/speed\"\nvariance = 0.01\n",
                "\"/radar/speed\"\nvariance = 0.01\nchainage_bias = { std_m = 1.0, time_constant_s = 60.0 }\n",
                1,
            ),
            vec![
                "/radar/speed".into(),
                "has a chainage_bias state but gives no chainage to observe it".into(),
            ],
        ),
    ];
    for (name, text, says) in cases {
        let config = write(name, text);
        let says: Vec<&str> = says.iter().map(String::as_str).collect();
        assert_one_clear_line(
            &railfuse(&["refuse", s(&raw), "-c", s(&config), "-o", s(&out)]),
            &says,
        );
    }
    assert!(!out.exists());
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
    let r: serde_json::Value = serde_json::from_slice(
        &ok(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused), "--json"]).stdout,
    )
    .unwrap();
    let p = |name: &str| {
        r["eval"]["pipelines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap()
            .clone()
    };
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
    // Against the GNSS, silent in the tunnel: no state inside the outage is scored against a
    // line drawn across it; they are counted as inside a gap of the reference.
    let g: serde_json::Value = serde_json::from_slice(
        &ok(&["eval", s(&fused), "--reference", "/gnss/fix", "--json"]).stdout,
    )
    .unwrap();
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
        assert!(p["states_in_reference_gaps"].as_u64().unwrap() > 100, "{p}");
    }
}

#[test]
fn viz_spawn_without_a_viewer_on_path_says_so_in_one_line() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args(["viz", s(&sample("short-run.mcap")), "--spawn"])
        .env("PATH", "/nonexistent")
        .output()
        .unwrap();
    assert_one_clear_line(
        &out,
        &[
            "Failed to find Rerun Viewer executable",
            "pip install rerun-sdk==0.36.3",
        ],
    );
}

/// A log written by some other recorder, with a null where a speed belongs and a radar value
/// of ±∞ spelled as an out-of-range number: the replay skips and counts them, says so once,
/// and no fused state or diagnostic carries anything but finite numbers.
#[test]
fn undecodable_and_non_finite_measurements_are_counted_and_never_fused() {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::{LoopPosition, RadarSpeed};
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (
        d.path().join("other.mcap"),
        d.path().join("other.fused.mcap"),
    );
    let mut w = LogWriter::create(&raw).unwrap();
    let lp = w.add_channel::<LoopPosition>("/loop/position").unwrap();
    let radar = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
    let mut bad = 0;
    for k in 0..200u64 {
        let t = 1_000_000_000 + k * 100_000_000;
        if k % 2 == 0 {
            w.write(
                lp,
                t,
                &LoopPosition {
                    stamp_ns: t,
                    chainage_m: k as f64,
                    crossing: None,
                    variance_m2: Some(0.01),
                },
            )
            .unwrap();
        }
        let json = match k {
            50 => {
                bad += 1;
                format!(r#"{{"stamp_ns":{t},"speed_mps":null,"quality":1.0,"valid":true}}"#)
            }
            60 => {
                bad += 1;
                format!(r#"{{"stamp_ns":{t},"speed_mps":1e400,"quality":1.0,"valid":true}}"#)
            }
            _ => format!(
                r#"{{"stamp_ns":{t},"speed_mps":10.0,"quality":1.0,"valid":true,"speed_variance_m2ps2":0.01}}"#
            ),
        };
        w.write_raw(radar.0, 0, t, t, json.as_bytes()).unwrap();
    }
    w.finish().unwrap();
    let cfg = d.path().join("p.toml");
    std::fs::write(
        &cfg,
        "[[pipeline]]\nname = \"kf\"\nfilter = \"kalman\"\nmotion = { model = \"constant_acceleration\", jerk_psd = 0.1 }\n\
         [[pipeline.sensor]]\ntopic = \"/loop/position\"\nvariance = \"message\"\n[[pipeline.sensor]]\ntopic = \"/radar/speed\"\nvariance = \"message\"\n",
    )
    .unwrap();
    let out = ok(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused), "--json"]);
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["refuse"]["undecodable"]["total"], bad, "{r}");
    assert!(
        stderr(&out).contains("2 sensor messages did not decode and were skipped"),
        "{}",
        stderr(&out)
    );
    // Every fused message decodes with finite numbers.
    let mut reader = railfuse_catalog::log::LogReader::open(&fused).unwrap();
    let mut states = 0;
    while let Some(rec) = reader.next() {
        if let railfuse_catalog::log::LogRecord::Message(m) = rec.unwrap() {
            if m.channel.topic == "/fused/kf/state" {
                let st: railfuse_catalog::messages::FusedState = m.decode(&fused).unwrap();
                assert!(
                    st.chainage_m.is_finite()
                        && st.speed_mps.is_finite()
                        && st.covariance.iter().all(|c| c.is_finite())
                );
                states += 1;
            }
        }
    }
    assert_eq!(states, 298, "one state per usable measurement");
}

#[test]
fn eval_scores_against_truth_another_pipeline_or_a_gnss_receiver() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "3", "--duration", "200"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let eval = |reference: &str| -> serde_json::Value {
        serde_json::from_slice(&ok(&["eval", s(&fused), "--reference", reference, "--json"]).stdout)
            .unwrap()
    };
    let truth = eval("/truth");
    let kalman = &truth["pipelines"][0];
    assert!(
        kalman["position_error_m"]["rmse"].as_f64().unwrap() < 1.0,
        "{kalman}"
    );
    // The default run's correction-link outage (120–165 s) is a marked window.
    let w = kalman["windows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["label"] == "no RTK corrections")
        .expect("the outage window");
    assert!(
        w["position_error_m"]["samples"].as_u64().unwrap() > 100,
        "{w}"
    );
    // Against the RTK receiver, matched on the track map: metres at worst (single fixes in the
    // outage), far from the kilometres a wrong projection would give.
    let gnss = eval("/gnss/fix");
    assert_eq!(gnss["reference"], "/gnss/fix");
    assert!(
        gnss["pipelines"][0]["position_error_m"]["rmse"]
            .as_f64()
            .unwrap()
            < 3.0,
        "{}",
        gnss["pipelines"][0]
    );
    let table = String::from_utf8(ok(&["eval", s(&fused)]).stdout).unwrap();
    assert!(
        table.contains("NEES in 95%") && table.contains("in no RTK corrections"),
        "{table}"
    );
}

/// The three real ETH-PBL samples import; their NAV-PVT values are those SOURCE.md decodes,
/// a NAV-PVT without a fix arrives as a fix that says so (no position), and the IMU is in SI
/// units (a node lying on the cab floor of a standing train feels 1 g up).
#[test]
fn the_eth_railway_samples_import_with_the_documented_values() {
    use railfuse_catalog::log::{LogReader, LogRecord};
    use railfuse_catalog::messages::{FixType, GnssFix, Imu};
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/eth-pbl-railway");
    let d = tempfile::tempdir().unwrap();
    let read = |name: &str| -> (Vec<GnssFix>, Vec<Imu>, serde_json::Value) {
        let out = d.path().join(format!("{name}.mcap"));
        let report = ok(&[
            "import",
            s(&data.join(format!("{name}.csv"))),
            "-o",
            s(&out),
            "--json",
        ]);
        let report: serde_json::Value = serde_json::from_slice(&report.stdout).unwrap();
        let (mut fixes, mut imu) = (Vec::new(), Vec::new());
        let mut r = LogReader::open(&out).unwrap();
        while let Some(rec) = r.next() {
            if let LogRecord::Message(m) = rec.unwrap() {
                match m.channel.topic.as_str() {
                    "/gnss/fix" => fixes.push(m.decode(&out).unwrap()),
                    "/imu" => imu.push(m.decode(&out).unwrap()),
                    _ => {}
                }
            }
        }
        (fixes, imu, report)
    };
    let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 5e-8);

    let (fixes, imu, report) = read("20221020_1030_R90117_Modena_SN1_sample");
    assert_eq!(fixes.len(), 2, "{report}");
    for f in &fixes {
        assert_eq!(
            (f.fix_type, f.satellites, f.latitude_deg, f.longitude_deg),
            (FixType::None, 0, None, None)
        );
    }
    assert_eq!(imu.len(), 1997);
    let (fixes, _, report) = read("20221020_1030_R90117_Modena_SN2_sample");
    assert_eq!(fixes.len(), 1, "{report}");
    assert!(fixes[0].fix_type.has_position() && fixes[0].satellites == 29);
    assert!(
        close(fixes[0].latitude_deg, 44.6551106) && close(fixes[0].longitude_deg, 10.9297304),
        "{:?}",
        fixes[0]
    );
    let h = fixes[0].position_covariance_enu_m2.unwrap();
    assert!((h[0] + h[4]).sqrt() < 1.5, "NAV-COV horizontal σ {h:?}");
    assert_eq!(
        report["skipped"]["NMEA sentence type not used (GSV, GLL, …)"],
        4
    );
    let (fixes, imu, _) = read("20221019_1252_R90120_Formigine_SN1_sample");
    assert!(
        fixes[0].satellites == 28
            && close(fixes[0].latitude_deg, 44.5775211)
            && close(fixes[0].longitude_deg, 10.8457549),
        "{:?}",
        fixes[0]
    );
    // UTC from the receiver: 2022-10-19, the run's date.
    assert_eq!(fixes[0].stamp_ns / 86_400_000_000_000, 19_284);
    let g = imu.iter().map(|m| m.specific_force_mps2[2]).sum::<f64>() / imu.len() as f64;
    assert!((g - 9.81).abs() < 0.3, "mean z specific force {g} m/s²");
    let rate = imu
        .iter()
        .map(|m| m.angular_rate_radps[2].abs())
        .fold(0.0, f64::max);
    assert!(rate < 0.1, "a standing train does not turn: {rate} rad/s");
    // IMU about 1.6 kHz on the node clock.
    let span = (imu.last().unwrap().stamp_ns - imu[0].stamp_ns) as f64 / 1e9;
    assert!(
        (1300.0..2000.0).contains(&(imu.len() as f64 / span)),
        "{} Hz",
        imu.len() as f64 / span
    );
}

#[test]
fn a_csv_log_imports_through_its_column_mapping_and_bad_rows_are_named() {
    let d = tempfile::tempdir().unwrap();
    let (csv, map, out) = (
        d.path().join("logger.csv"),
        d.path().join("map.toml"),
        d.path().join("logger.mcap"),
    );
    let mut text = String::from("t;v_radar;pos;note\n");
    for k in 0..100 {
        let pos = if k % 10 == 0 {
            format!("{}", k as f64 * 2.5)
        } else {
            String::new()
        };
        text += &format!("{};{};{pos};ok\n", k as f64 * 0.1, 25.0 + k as f64 * 0.01);
    }
    text += "oops;1;2;x\n7.0;fast;;x\n";
    std::fs::write(&csv, text).unwrap();
    std::fs::write(
        &map,
        "time_column = \"t\"\ntime_unit = \"s\"\ntime_offset_ns = 1780300800000000000\ndelimiter = \";\"\n\
         [[channel]]\ntopic = \"/radar/speed\"\nfields = { speed_mps = \"v_radar\" }\nconstants = { quality = 1.0, valid = true }\n\
         [[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"pos\" }\n",
    )
    .unwrap();
    let r: serde_json::Value = serde_json::from_slice(
        &ok(&[
            "import",
            "--format",
            "csv",
            "--map",
            s(&map),
            s(&csv),
            "-o",
            s(&out),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert_eq!(
        (
            r["per_topic"]["/radar/speed"].as_u64(),
            r["per_topic"]["/loop/position"].as_u64()
        ),
        (Some(100), Some(10)),
        "{r}"
    );
    let problems = r["first_problems"].to_string();
    assert!(
        problems.contains("line 102: bad time")
            && problems.contains("line 103: row does not make a valid message"),
        "{problems}"
    );
    let info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&out), "--json"]).stdout).unwrap();
    assert_eq!(info["channels"].as_array().unwrap().len(), 2);
    // A mapping naming a column the file does not have is refused, naming both.
    std::fs::write(&map, "time_column = \"t\"\ndelimiter = \";\"\n[[channel]]\ntopic = \"/radar/speed\"\nfields = { speed_mps = \"v\" }\n").unwrap();
    let bad = railfuse(&[
        "import",
        "--format",
        "csv",
        "--map",
        s(&map),
        s(&csv),
        "-o",
        s(&out),
    ]);
    assert!(
        !bad.status.success()
            && stderr(&bad).contains("channel /radar/speed: column 'v' is not a column of"),
        "{}",
        stderr(&bad)
    );
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

#[test]
fn the_accuracy_refuse_prints_in_its_pass_equals_eval_of_the_written_file() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("s0.mcap"), d.path().join("s0.fused.mcap"));
    simulate(&["--scenario", "seed000", "--seed", "3"], &raw);
    let cfg = sample("seed000.toml"); // kf_balise has an RTS smoother
    let o = ok(&["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused), "--json"]);
    let in_pass: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let o = ok(&["eval", s(&fused), "--json"]);
    let from_file: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (a, b) = (&in_pass["eval"]["pipelines"], &from_file["pipelines"]);
    assert!(
        a.as_array()
            .unwrap()
            .iter()
            .any(|p| p["name"] == "kf_balise/smoothed"),
        "{a}"
    );
    // The same states and counts; figures equal but for the last bits: the file's JSON floats
    // are parsed by serde_json's fast parser (within an ulp), the in-pass ones never left f64.
    let worst = differ(a, b);
    assert!(
        worst < 1e-9,
        "in-pass and file evaluations differ by {worst}:\n{a}\n{b}"
    );
    assert_eq!(in_pass["eval"]["windows"], from_file["windows"]);
}

/// The largest relative difference between two JSON documents of the same shape (∞ where
/// the shapes or any non-number differ).
fn differ(a: &serde_json::Value, b: &serde_json::Value) -> f64 {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (x - y).abs() / x.abs().max(y.abs()).max(1e-300)
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .map(|(x, y)| differ(x, y))
            .fold(0.0, f64::max),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => x
            .iter()
            .map(|(k, v)| y.get(k).map_or(f64::INFINITY, |w| differ(v, w)))
            .fold(0.0, f64::max),
        _ if a == b => 0.0,
        _ => f64::INFINITY,
    }
}

/// The Foxglove twins sit beside railfuse's channels without changing them, and
/// `--no-foxglove` leaves them out.
#[test]
fn foxglove_twins_are_added_beside_the_channels_and_left_out_on_request() {
    let d = tempfile::tempdir().unwrap();
    let topics = |path: &std::path::Path| -> Vec<(String, u64)> {
        let info: serde_json::Value =
            serde_json::from_slice(&ok(&["info", s(path), "--json"]).stdout).unwrap();
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
