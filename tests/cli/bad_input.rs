//! Bad input, user's and device's: one clear line naming the file, line, column or channel
//! and the cause, a non-zero exit; undecodable measurements counted and never fused.

use super::*;

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
    use railfuse_catalog::log::{LogWriter, WriterOptions};
    use railfuse_catalog::messages::{LoopPosition, RadarSpeed};
    use railfuse_catalog::protobuf::Encoding;
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (
        d.path().join("other.mcap"),
        d.path().join("other.fused.mcap"),
    );
    // A JSON log: the other recorder's text is what goes wrong.
    let json_log = WriterOptions {
        encoding: Encoding::Json,
        ..WriterOptions::default()
    };
    let mut w = LogWriter::create_with(&raw, &json_log).unwrap();
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
