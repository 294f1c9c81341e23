//! Interop: railfuse's outputs checked by clients written by others (the official Python
//! `mcap` reader with `jsonschema`, the `rerun` CLI, filterpy). `tests/run` installs them.

mod common;

use common::live::free_port;
use common::*;

fn python_ok(script: &str, args: &[&str]) -> serde_json::Value {
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

fn rerun_ok(args: &[&str]) -> String {
    let out = rerun(args);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert!(out.status.success(), "rerun {args:?}: {text}");
    text
}

#[test]
fn python_mcap_reads_and_validates_every_message_and_rerun_accepts_the_files() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "11", "--duration", "200"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let info: serde_json::Value =
        serde_json::from_slice(&ok(&["info", s(&raw), "--json"]).stdout).unwrap();

    let r = python_ok("check_mcap.py", &[s(&raw)]);
    assert_eq!(r["messages"], info["messages"]);
    for t in [
        "/gnss/fix",
        "/imu",
        "/radar/speed",
        "/odometer/1",
        "/odometer/2",
        "/loop/position",
        "/balise",
        "/truth",
        "/events",
        "/track/map",
    ] {
        assert!(r["topics"][t].as_u64().unwrap_or(0) > 0, "no {t} read: {r}");
    }
    assert_eq!(r["compression"], serde_json::json!(["zstd"]));
    assert!(r["chunks"].as_u64().unwrap() > 1);
    assert_eq!(r["metadata"], serde_json::json!(["railfuse.run"]));

    let f = python_ok("check_mcap.py", &[s(&fused)]);
    assert!(f["topics"]["/fused/kalman/state"].as_u64().unwrap() > 1000);
    assert_eq!(
        f["metadata"],
        serde_json::json!(["railfuse.pipeline", "railfuse.run"])
    );

    for file in [&raw, &fused] {
        let text = rerun_ok(&["mcap", "check", s(file)]);
        assert!(!text.contains("PROBLEM"), "rerun mcap check: {text}");
        assert!(text.contains("/imu"), "{text}");
    }
}

#[test]
fn the_kalman_pipeline_and_its_rts_smoother_equal_filterpy_on_the_same_measurements() {
    let d = tempfile::tempdir().unwrap();
    for (scenario, config, duration) in [
        ("default", "kalman.toml", "300"),
        ("seed000", "seed000.toml", "100"),
        ("seed000_loop_drift", "seed000.toml", "100"),
    ] {
        let (raw, fused) = (
            d.path().join(format!("{scenario}.mcap")),
            d.path().join(format!("{scenario}.fused.mcap")),
        );
        ok(&[
            "simulate",
            "--scenario",
            scenario,
            "--seed",
            "21",
            "--duration",
            duration,
            "-o",
            s(&raw),
        ]);
        ok(&["refuse", s(&raw), "-c", s(&sample(config)), "-o", s(&fused)]);
        let r = python_ok("filterpy_kalman.py", &[s(&fused), "1e-9"]);
        assert!(r["updates_compared"].as_u64().unwrap() > 150, "{r}");
        if scenario != "default" {
            // kf_balise has the RTS smoother: every epoch compared with filterpy's rts_smoother.
            assert!(r["smoothed_compared"].as_u64().unwrap() > 100, "{r}");
        }
        assert!(
            r["worst_relative_difference"].as_f64().unwrap() <= 1e-9,
            "{r}"
        );
    }
}

#[test]
fn seed000_measurements_have_the_variances_source_000_states() {
    let d = tempfile::tempdir().unwrap();
    let files: Vec<String> = (0..12)
        .map(|seed| {
            let p = d.path().join(format!("s{seed}.mcap"));
            ok(&[
                "simulate",
                "--scenario",
                "seed000",
                "--seed",
                &seed.to_string(),
                "-o",
                s(&p),
            ]);
            s(&p).to_owned()
        })
        .collect();
    let args: Vec<&str> = files.iter().map(String::as_str).collect();
    let r = python_ok("seed000_stats.py", &args);
    for k in ["loop", "radar", "jerk"] {
        assert!(r[k]["n"].as_u64().unwrap() >= 1000, "{r}");
    }
}

/// `railfuse refuse` of the short sample run with a config, and any further arguments.
fn refuse_short_run(config: &std::path::Path, out: &std::path::Path, extra: &[&str]) {
    let run = sample("short-run.mcap");
    let mut args = vec!["refuse", s(&run), "-c", s(config), "-o", s(out)];
    args.extend(extra);
    ok(&args);
}

/// Kalman, federated and particle pipelines side by side, as the viewer's layout test run.
const THREE_PIPELINES: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
motion = { model = "constant_acceleration", jerk_psd = 0.2 }
[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"
[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.1
scale_factor = { std = 0.01 }

[[pipeline]]
name = "fkf"
filter = "federated_kalman"
motion = { model = "constant_acceleration", jerk_psd = 0.2 }
federated = { fusion_period_s = 1.0 }
[[pipeline.sensor]]
topic = "/loop/position"
device = "loop"
variance = "message"
[[pipeline.sensor]]
topic = "/radar/speed"
device = "radar"
variance = 0.1

[[pipeline]]
name = "pf"
filter = "particle"
motion = { model = "constant_acceleration", jerk_psd = 0.2 }
particle = { particles = 300, seed = 7 }
[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"
[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.1
"#;

/// Data rows per entity path, from `rerun rrd print -v` (one line per chunk: "with N rows … -
/// /path - data columns: […]"); style chunks (series names, colours) are not data.
fn rows_per_entity(printed: &str) -> std::collections::BTreeMap<String, u64> {
    let data = [
        "Scalars:scalars",
        "Points2D:positions",
        "LineStrips2D:strips",
        "TextLog:text",
    ];
    let mut rows = std::collections::BTreeMap::new();
    for line in printed
        .lines()
        .filter(|l| l.starts_with("Chunk(") && data.iter().any(|d| l.contains(d)))
    {
        let n = line
            .split(" with ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok());
        let path = line.split(" - ").nth(1).map(str::trim);
        if let (Some(n), Some(path)) = (n, path) {
            *rows.entry(path.to_owned()).or_default() += n;
        }
    }
    rows
}

#[test]
fn rerun_verifies_the_recording_with_its_layout_and_every_pipelines_entities() {
    let d = tempfile::tempdir().unwrap();
    let (config, fused, rrd) = (
        d.path().join("three.toml"),
        d.path().join("f.mcap"),
        d.path().join("run.rrd"),
    );
    std::fs::write(&config, THREE_PIPELINES).unwrap();
    refuse_short_run(&config, &fused, &[]);
    ok(&["viz", s(&fused), "--save", s(&rrd)]);
    rerun_ok(&["rrd", "verify", s(&rrd)]);
    let printed = rerun_ok(&["rrd", "print", "-v", s(&rrd)]);
    let rows = rows_per_entity(&printed);
    // Every pipeline's series, its place on the map and its diagnostics, with data in them.
    let mut expected: Vec<String> = [
        "/map/track",
        "/map/km_marks",
        "/map/balises",
        "/map/stations",
        "/map/legend",
        "/map/truth/train",
        "/map/truth/path",
        "/map/gnss/rtk_fixed",
        "/speed/truth",
        "/speed/radar",
        "/speed/odometer_1",
        "/events",
        "/diagnostics/kf/sensor_states/radar_speed/scale_factor",
        "/diagnostics/fkf/sharing",
        "/diagnostics/pf/effective_sample_size",
    ]
    .map(str::to_owned)
    .to_vec();
    for p in ["kf", "fkf", "pf"] {
        expected.extend([
            format!("/speed/fused/{p}"),
            format!("/chainage_error/{p}"),
            format!("/speed_error/{p}"),
            format!("/map/fused/{p}/position"),
            format!("/map/fused/{p}/extent"),
            format!("/diagnostics/{p}/nis/loop_position"),
            format!("/diagnostics/{p}/nis/chi2_bounds"),
        ]);
    }
    for entity in &expected {
        assert!(
            rows.get(entity).is_some_and(|&n| n > 0),
            "no rows on {entity}: {rows:?}"
        );
    }
    // A short run is kept at full rate: one error row per fused state.
    let states = python_ok("check_mcap.py", &[s(&fused)]);
    for p in ["kf", "fkf", "pf"] {
        let n = states["topics"][format!("/fused/{p}/state")]
            .as_u64()
            .unwrap();
        let logged = rows[&format!("/chainage_error/{p}")];
        // States before the truth starts or after it ends have no error to draw.
        assert!(
            logged <= n && logged + 50 >= n,
            "{p}: {logged} error rows for {n} states"
        );
    }
    // The layout travels in the file: a blueprint store with the views by name, and every
    // pipeline's diagnostics tab.
    let data = rerun_ok(&["rrd", "print", "-vvv", s(&rrd)]);
    assert!(data.contains("Blueprint"), "no blueprint store");
    for view in [
        "Map (east →, north ↑)",
        "Speed (m/s)",
        "Chainage error: fused − truth, ±3σ (m)",
        "Speed error: fused − truth, ±3σ (m/s)",
        "β per device",
        "effective sample size",
        "Events",
    ] {
        assert!(data.contains(view), "blueprint lacks the view {view:?}");
    }
    for p in ["kf", "fkf", "pf"] {
        assert!(data.contains(&format!("{p}: NIS")), "no NIS view for {p}");
    }
    // The log_time timeline carries the MCAP log time of the simulated run (2026-06-01), not
    // the wall clock of the viz run.
    assert!(
        data.contains("index_name: log_time"),
        "no log_time timeline"
    );
    assert!(
        data.contains("2026-06-01T08:01"),
        "log_time is not the run's time"
    );
}

#[test]
fn foxglove_twins_validate_against_foxglove_s_published_schemas() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("raw.mcap"), d.path().join("fused.mcap"));
    simulate(&["--duration", "120", "--seed", "3"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let schemas = std::env::var("RAILFUSE_FOXGLOVE_SCHEMAS")
        .expect("RAILFUSE_FOXGLOVE_SCHEMAS: run the tests with tests/run, which fetches them");
    let r = python_ok("check_foxglove.py", &[s(&fused), &schemas]);
    // Every fix with a position, every event and the map have a twin.
    let counts = python_ok("check_mcap.py", &[s(&fused)]);
    let n = |topic: &str| counts["topics"][topic].as_u64().unwrap_or(0);
    let twins = |topic: &str| r["topics"][topic].as_u64().unwrap_or(0);
    assert!(
        twins("/foxglove/gnss/fix") > 0 && twins("/foxglove/gnss/fix") <= n("/gnss/fix"),
        "{r}"
    );
    assert_eq!(twins("/foxglove/events"), n("/events"), "{r}");
    assert_eq!(twins("/foxglove/track/map"), 1, "{r}");
    // Positions at 10 a second at most (the states come at about 70): a 120 s run holds at
    // most 1 201 of them.
    let fused = twins("/foxglove/fused/kalman/state");
    assert!(
        fused > 500 && fused <= 1201 && fused < n("/fused/kalman/state"),
        "{r}"
    );
    assert_eq!(r["geojson_type"], "FeatureCollection", "{r}");
    assert!(r["track_points"].as_u64().unwrap() > 10, "{r}");
    assert_eq!(
        r["geometries"],
        serde_json::json!(["LineString", "Point"]),
        "{r}"
    );
}

/// A 2-D pipeline's state (east/north with its covariance) is drawn on the map as its 3σ
/// ellipse; an along-track one as its ±3σ stretch of track.
#[test]
fn a_2d_pipeline_is_drawn_with_its_covariance_ellipse() {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::{
        AnyMessage, FusedState, MessageKind, PlanePosition, TrackMap,
    };
    let d = tempfile::tempdir().unwrap();
    let (log, rrd) = (d.path().join("2d.mcap"), d.path().join("2d.rrd"));
    let mut w = LogWriter::create(&log).unwrap();
    let AnyMessage::TrackMap(map) = MessageKind::TrackMap.example() else {
        panic!("a map example")
    };
    let map_channel = w.add_channel::<TrackMap>("/track/map").unwrap();
    w.write(map_channel, 1_000, &map).unwrap();
    let states = w.add_channel::<FusedState>("/fused/p2/state").unwrap();
    for k in 0..50u64 {
        let t = 1_000_000_000 + k * 100_000_000;
        let state = FusedState {
            stamp_ns: t,
            chainage_m: k as f64,
            speed_mps: 10.0,
            acceleration_mps2: 0.0,
            covariance: [1.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 0.01],
            source: "/gnss/fix".into(),
            sensor_states: Vec::new(),
            plane: Some(PlanePosition {
                east_m: k as f64,
                north_m: 0.5,
                covariance_en_m2: [4.0, 1.0, 1.0, 1.0],
                latitude_deg: 44.6,
                longitude_deg: 10.9,
                ..Default::default()
            }),
        };
        w.write(states, t, &state).unwrap();
    }
    w.finish().unwrap();
    ok(&["viz", s(&log), "--save", s(&rrd)]);
    rerun_ok(&["rrd", "verify", s(&rrd)]);
    let rows = rows_per_entity(&rerun_ok(&["rrd", "print", "-v", s(&rrd)]));
    assert_eq!(rows.get("/map/fused/p2/ellipse"), Some(&50), "{rows:?}");
    assert_eq!(rows.get("/map/fused/p2/position"), Some(&50), "{rows:?}");
    assert_eq!(rows.get("/map/fused/p2/extent"), None, "{rows:?}");
}

#[test]
fn sensor_states_reach_the_fused_file_and_the_viewer() {
    let d = tempfile::tempdir().unwrap();
    let (config, fused, rrd) = (
        d.path().join("sf.toml"),
        d.path().join("sf.mcap"),
        d.path().join("sf.rrd"),
    );
    std::fs::write(
        &config,
        "[[pipeline]]\nname = \"sf\"\nfilter = \"kalman\"\nmotion = { model = \"constant_acceleration\", jerk_psd = 0.2 }\n\n\
         [[pipeline.sensor]]\ntopic = \"/loop/position\"\nvariance = \"message\"\n\n\
         [[pipeline.sensor]]\ntopic = \"/radar/speed\"\nvariance = 0.01\nscale_factor = { std = 0.01 }\n",
    )
    .unwrap();
    refuse_short_run(&config, &fused, &[]);
    // Every fused state, with its sensor state, fits the schema stored in the file.
    let py = python("check_mcap.py", &[s(&fused)]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let py: serde_json::Value = serde_json::from_slice(&py.stdout).unwrap();
    assert!(
        py["topics"]["/fused/sf/state"].as_u64().unwrap() > 100,
        "{py}"
    );
    ok(&["viz", s(&fused), "--save", s(&rrd)]);
    rerun_ok(&["rrd", "verify", s(&rrd)]);
    assert!(rerun_ok(&["rrd", "print", "-v", s(&rrd)])
        .contains("/diagnostics/sf/sensor_states/radar_speed/scale_factor"));
}

/// A real Rerun server on loopback that saves what it receives: (process, URL, file).
fn rerun_server(dir: &std::path::Path) -> (std::process::Child, String, std::path::PathBuf) {
    use std::time::{Duration, Instant};
    let port = free_port();
    let saved = dir.join(format!("streamed-{port}.rrd"));
    let server = std::process::Command::new(client("RAILFUSE_RERUN", "rerun"))
        .env("RERUN_ANALYTICS", "0")
        .args(["--port", &port.to_string(), "--save", s(&saved)])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "rerun server did not start"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    (
        server,
        format!("rerun+http://127.0.0.1:{port}/proxy"),
        saved,
    )
}

/// Waits until the server has written what it received (the file stops growing), then stops it.
fn stop_when_saved(mut server: std::process::Child, saved: &std::path::Path) {
    use std::time::{Duration, Instant};
    let mut last = 0;
    let waited = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(1000));
        let size = std::fs::metadata(saved).map(|m| m.len()).unwrap_or(0);
        if (size > 0 && size == last) || waited.elapsed() > Duration::from_secs(30) {
            break;
        }
        last = size;
    }
    server.kill().unwrap();
    server.wait().unwrap();
}

#[test]
fn record_viz_streams_the_incoming_channels_to_a_running_viewer() {
    let d = tempfile::tempdir().unwrap();
    let (server, url, saved) = rerun_server(d.path());
    let out = d.path().join("live.mcap");
    let o = ok(&[
        "record",
        "-o",
        s(&out),
        "--speed",
        "40",
        "--duration",
        "3",
        "--viz",
        &url,
        "--json",
    ]);
    stop_when_saved(server, &saved);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // The simulator runs in real time (×40): a machine busy with other work records fewer
    // messages in the 3 s, so only a working flow is asserted, not a rate.
    assert!(r["messages"].as_u64().unwrap() > 100, "{r}");
    let printed = rerun_ok(&[
        "rrd",
        "print",
        "-v",
        "--continue-on-error",
        "true",
        s(&saved),
    ]);
    for entity in [
        "/map/track",
        "/map/truth/train",
        "/speed/truth",
        "/speed/radar",
    ] {
        assert!(
            printed.contains(entity),
            "the viewer did not receive {entity}"
        );
    }
}

#[test]
fn refuse_viz_streams_the_fused_channels_while_refusing() {
    let d = tempfile::tempdir().unwrap();
    let (server, url, saved) = rerun_server(d.path());
    let fused = d.path().join("f.mcap");
    refuse_short_run(&sample("kalman.toml"), &fused, &["--viz", &url]);
    stop_when_saved(server, &saved);
    let printed = rerun_ok(&[
        "rrd",
        "print",
        "-v",
        "--continue-on-error",
        "true",
        s(&saved),
    ]);
    let rows = rows_per_entity(&printed);
    // The pipeline's output as it was made, against the truth the replay read.
    for entity in [
        "/map/track",
        "/speed/truth",
        "/speed/radar",
        "/chainage_error/kalman",
        "/speed_error/kalman",
        "/diagnostics/kalman/nis/loop_position",
        "/map/fused/kalman/position",
    ] {
        assert!(
            rows.get(entity).is_some_and(|&n| n > 0),
            "the viewer did not receive {entity}: {rows:?}"
        );
    }
    assert!(printed.contains("Blueprint"), "no layout was sent");
}

#[test]
fn viz_streams_to_a_running_viewer_and_refuses_an_absent_one() {
    use std::time::{Duration, Instant};
    let d = tempfile::tempdir().unwrap();
    let fused = d.path().join("f.mcap");
    refuse_short_run(&sample("kalman.toml"), &fused, &[]);

    let (server, url, saved) = rerun_server(d.path());
    let streamed = railfuse(&["viz", s(&fused), "--connect", &url]);
    stop_when_saved(server, &saved);
    assert!(streamed.status.success(), "{}", stderr(&streamed));
    // The server was stopped mid-stream, so the file has no footer: read what it holds.
    let printed = rerun_ok(&[
        "rrd",
        "print",
        "-v",
        "--continue-on-error",
        "true",
        s(&saved),
    ]);
    for entity in [
        "/map/track",
        "/speed/fused/kalman",
        "/chainage_error/kalman",
    ] {
        assert!(
            printed.contains(entity),
            "the viewer did not receive {entity}"
        );
    }

    // No viewer at the address: one clear line at once, no hang.
    let absent = format!("rerun+http://127.0.0.1:{}/proxy", free_port());
    let t = Instant::now();
    let out = railfuse(&["viz", s(&fused), "--connect", &absent]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no Rerun viewer is listening"),
        "{}",
        stderr(&out)
    );
    assert!(t.elapsed() < Duration::from_secs(10));
}

/// A recording killed with SIGKILL mid-write (here the simulator, which writes the same way):
/// `recover` salvages every complete chunk into a valid file that the official Python reader
/// reads and validates, and the salvage is a prefix of what was being written.
#[test]
fn a_log_killed_mid_write_is_recovered_and_the_python_reader_reads_it() {
    let d = tempfile::tempdir().unwrap();
    let (out, fixed) = (d.path().join("long.mcap"), d.path().join("fixed.mcap"));
    let partial = d.path().join("long.mcap.partial");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args([
            "simulate",
            "--seed",
            "9",
            "--duration",
            "36000",
            "-o",
            s(&out),
        ])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    // 8 MiB: past the first minute of the run (the eddy-current blocks are most of the bytes).
    while std::fs::metadata(&partial).map_or(0, |m| m.len()) < 8 << 20 {
        assert!(
            started.elapsed().as_secs() < 120,
            "the simulator wrote nothing"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(
        !out.exists(),
        "a killed run must not leave a file that looks complete"
    );
    let r: serde_json::Value =
        serde_json::from_slice(&ok(&["recover", s(&partial), "-o", s(&fixed), "--json"]).stdout)
            .unwrap();
    assert!(
        r["stopped_by"].as_str().unwrap().contains("truncated"),
        "{r}"
    );
    let messages = r["messages"].as_u64().unwrap();
    assert!(messages > 40_000, "{r}");
    let py = python_ok("check_mcap.py", &[s(&fixed)]);
    assert_eq!(py["messages"].as_u64().unwrap(), messages);
    assert_eq!(py["topics"]["/imu"], r["messages_per_topic"]["/imu"]);
}

/// Per topic, the messages of the chunks of `path` that hold no damage; the byte range of the
/// chunk nearest the middle.
fn chunks_around_the_middle(
    path: &std::path::Path,
) -> (
    std::ops::Range<usize>,
    std::collections::BTreeMap<String, u64>,
) {
    use railfuse_catalog::log::format::{parse_message, Records};
    use railfuse_catalog::log::scan::{Item, Scanner};
    let size = std::fs::metadata(path).unwrap().len() as usize;
    let topics: std::collections::HashMap<u16, String> = railfuse_catalog::log::read_channels(path)
        .unwrap()
        .unwrap()
        .iter()
        .map(|c| (c.id, c.topic.clone()))
        .collect();
    let mut scanner = Scanner::open(path).unwrap();
    let mut middle = None;
    let mut lost = std::collections::BTreeMap::new();
    while let Some(item) = scanner.next() {
        if let Item::Chunk(c) = item.unwrap() {
            if middle.is_none() && c.offset as usize > size / 2 {
                middle = Some(c.offset as usize..c.offset as usize + c.raw.len());
                for r in Records::new(&c.records).flatten() {
                    if let Some(m) = parse_message(r.body) {
                        *lost
                            .entry(topics[&m.header.channel_id].clone())
                            .or_insert(0) += 1;
                    }
                }
            }
        }
    }
    (middle.unwrap(), lost)
}

#[test]
fn a_corrupt_chunk_in_the_middle_costs_that_chunk_only_and_python_reads_the_rest() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("run.mcap");
    simulate(&["--seed", "2", "--duration", "120"], &raw);
    let original = python_ok("check_mcap.py", &[s(&raw)]);
    let (chunk, lost) = chunks_around_the_middle(&raw);
    let mut bytes = std::fs::read(&raw).unwrap();
    for b in &mut bytes[chunk.start + 100..chunk.start + 164] {
        *b ^= 0xa5; // flipped bits inside the compressed records
    }
    let broken = d.path().join("broken.mcap");
    std::fs::write(&broken, &bytes).unwrap();
    // Every reader says it is damaged, where, and what salvages it: one line, exit 1.
    let cfg = common::sample("kalman.toml");
    let (out, rrd) = (d.path().join("f.mcap"), d.path().join("f.rrd"));
    let mut lines = Vec::new();
    for args in [
        vec!["info", s(&broken)],
        vec!["refuse", s(&broken), "-c", s(&cfg), "-o", s(&out)],
        vec!["viz", s(&broken), "--save", s(&rrd)],
    ] {
        let o = railfuse(&args);
        let err = stderr(&o);
        assert!(
            !o.status.success() && err.lines().count() == 1,
            "{args:?}: {err}"
        );
        assert!(
            err.contains(&format!("damaged at byte {}", chunk.start)),
            "{err}"
        );
        assert!(
            err.contains("railfuse recover") && err.contains(s(&broken)),
            "{err}"
        );
        lines.push(err.trim().to_owned());
    }
    assert!(lines.windows(2).all(|w| w[0] == w[1]), "{lines:?}");
    let fixed = d.path().join("fixed.mcap");
    let r: serde_json::Value =
        serde_json::from_slice(&ok(&["recover", s(&broken), "-o", s(&fixed), "--json"]).stdout)
            .unwrap();
    assert_eq!(r["skipped"].as_array().unwrap().len(), 1, "{r}");
    assert_eq!(r["skipped"][0]["offset"], chunk.start as u64, "{r}");
    // The official reader reads the salvage: every message of the original but the lost
    // chunk's, topic by topic.
    let py = python_ok("check_mcap.py", &[s(&fixed)]);
    for (topic, n) in original["topics"].as_object().unwrap() {
        let want = n.as_u64().unwrap() - lost.get(topic).copied().unwrap_or(0);
        assert_eq!(py["topics"][topic].as_u64().unwrap_or(0), want, "{topic}");
    }
    assert_eq!(py["messages"], r["messages"]);
    assert!(lost.values().sum::<u64>() < original["messages"].as_u64().unwrap() / 10);
}

#[test]
fn every_message_kind_validates_against_its_schema_in_the_python_reader() {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::MessageKind;
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("kinds.mcap");
    // The catalogue's own kinds only: no Foxglove twins.
    let options = railfuse_catalog::log::WriterOptions {
        foxglove: false,
        ..Default::default()
    };
    let mut w = LogWriter::create_with(&path, &options).unwrap();
    for &kind in MessageKind::ALL {
        let topic = format!("/sample/{}", kind.type_name());
        let channel = w.add_channel_of(kind, &topic).unwrap();
        let m = kind.example();
        w.write_any(channel, m.stamp_ns(), &m).unwrap();
    }
    w.finish().unwrap();
    let py = python_ok("check_mcap.py", &[s(&path)]);
    assert_eq!(py["messages"], MessageKind::ALL.len(), "{py}");
    for &kind in MessageKind::ALL {
        assert_eq!(
            py["topics"][format!("/sample/{}", kind.type_name())],
            1,
            "{kind:?}: {py}"
        );
    }
}

#[test]
fn em_estimates_equal_pykalman_s_on_the_same_data_and_start() {
    let d = tempfile::tempdir().unwrap();
    let python = client("RAILFUSE_PYTHON", "python");
    let out = ok(&[
        "bench",
        "--em",
        "--em-steps",
        "2000",
        "--em-iterations",
        "5",
        "--json",
        "--python",
        s(&python),
        "--dir",
        s(d.path()),
    ]);
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let (q, r) = (
        c["q_relative_difference"].as_f64().unwrap(),
        c["r_relative_difference"].as_f64().unwrap(),
    );
    assert!(q < 1e-6 && r < 1e-6, "{c}");
    // EM moved the estimates far from the start (10x off), so agreeing means something.
    let r00 = c["railfuse_r"][0][0].as_f64().unwrap();
    assert!((r00 / 0.01 - 1.0).abs() < 0.1, "{c}");
}

/// Two figures equal but for the last bits (serde_json reads floats to within an ulp, and sums
/// in another order differ there).
fn close(a: &serde_json::Value, b: &serde_json::Value) {
    let (x, y) = (a.as_f64().unwrap(), b.as_f64().unwrap());
    assert!((x - y).abs() <= 1e-12 * y.abs().max(1e-300), "{x} vs {y}");
}

/// The Python package's `refuse` writes exactly what the CLI writes; its tables, tuning and
/// errors are the CLI's.
#[test]
fn the_python_package_refuses_byte_for_byte_like_the_cli_and_reads_tables() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("raw.mcap");
    simulate(&["--seed", "6", "--duration", "60"], &raw);
    let config = sample("kalman.toml");
    let cli = d.path().join("cli.fused.mcap");
    ok(&["refuse", s(&raw), "-c", s(&config), "-o", s(&cli)]);
    let v = python_ok(
        "python_package.py",
        &[s(d.path()), s(&config), s(&cli), s(&raw)],
    );
    let py = d.path().join("py.fused.mcap");
    assert_eq!(
        std::fs::read(&cli).unwrap(),
        std::fs::read(&py).unwrap(),
        "railfuse.refuse and railfuse refuse write the same bytes"
    );
    let states: Vec<railfuse_catalog::messages::FusedState> = messages(&cli, "/fused/kalman/state");
    assert_eq!(v["state_rows"].as_u64().unwrap() as usize, states.len());
    assert_eq!(v["first_chainage"].as_f64().unwrap(), states[0].chainage_m);
    assert_eq!(v["covariance_type"], "list<item: double>");
    assert_eq!(v["state_columns"][0], "log_time_ns");
    let radar: Vec<railfuse_catalog::messages::RadarSpeed> = messages(&raw, "/radar/speed");
    assert_eq!(v["radar_rows"].as_u64().unwrap() as usize, radar.len());
    // (refuse scores in the same pass, evaluate from the file: sums in another order)
    close(&v["refuse_rmse"], &v["evaluate_rmse"]);
    // Errors: the CLI's one line, as RailfuseError.
    let e = &v["errors"];
    let missing = d.path().join("nope.toml");
    let cli_err = stderr(&railfuse(&[
        "refuse",
        s(&raw),
        "-c",
        s(&missing),
        "-o",
        s(&py),
    ]));
    assert!(
        cli_err.contains(e["missing_config"].as_str().unwrap()),
        "{cli_err} / {e}"
    );
    assert!(
        e["missing_topic"]
            .as_str()
            .unwrap()
            .contains("no channel /nope"),
        "{e}"
    );
    assert!(
        e["unknown_reference"]
            .as_str()
            .unwrap()
            .contains("reference /nothere is not in the log"),
        "{e}"
    );
    assert_eq!(v["pandas_rows"], v["state_rows"], "{v}");
    assert!(
        e["unknown_param"]
            .as_str()
            .unwrap()
            .contains("motion.jerk_pds: not found"),
        "{e}"
    );
    assert!(
        e["unknown_scenario"]
            .as_str()
            .unwrap()
            .contains("unknown scenario 'nope'"),
        "{e}"
    );
    // Tuning from Python finds what the CLI finds.
    let out = d.path().join("cli-tuned.toml");
    let cli_tune: serde_json::Value = serde_json::from_slice(
        &ok(&[
            "tune",
            s(&raw),
            "-c",
            s(&config),
            "--pipeline",
            "kalman",
            "--reference",
            "/truth",
            "--params",
            "motion.jerk_psd=0.001..10",
            "--optimiser",
            "grid",
            "-o",
            s(&out),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert_eq!(
        v["tuned"]["motion.jerk_psd"],
        cli_tune["params"][0]["after"]
    );
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(d.path().join("py-tuned.toml")).unwrap()
    );
}

/// railfuse.ray on a local Ray cluster: tasks give the local figures, and the Ray Tune grid
/// search finds the values the local grid search finds.
#[test]
fn the_ray_path_refuses_many_logs_and_tunes_to_the_local_values() {
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<std::path::PathBuf> = (1..=2)
        .map(|seed| {
            let log = d.path().join(format!("r{seed}.mcap"));
            ok(&[
                "simulate",
                "--seed",
                &seed.to_string(),
                "--duration",
                "60",
                "-o",
                s(&log),
            ]);
            log
        })
        .collect();
    let config = sample("kalman.toml");
    let mut args = vec![s(d.path()), s(&config)];
    args.extend(logs.iter().map(|l| s(l)));
    let v = python_ok("ray_fleet.py", &args);
    for (i, log) in logs.iter().enumerate() {
        let local = d.path().join(format!("local{i}.fused.mcap"));
        let r: serde_json::Value = serde_json::from_slice(
            &ok(&[
                "refuse",
                s(log),
                "-c",
                s(&config),
                "-o",
                s(&local),
                "--json",
            ])
            .stdout,
        )
        .unwrap();
        close(
            &v["refuse_rmse"][i],
            &r["eval"]["pipelines"][0]["position_error_m"]["rmse"],
        );
        close(&v["evaluate_rmse"][i], &v["refuse_rmse"][i]);
    }
    assert_eq!(v["ray"], v["local"], "{v}");
    let (a, b) = (
        v["ray_objective"].as_f64().unwrap(),
        v["local_objective"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-9 * b.abs(), "{v}");
    assert_eq!(v["trials"], 9);
    assert!(
        v["missing_log"].as_str().unwrap().contains("missing.mcap"),
        "{v}"
    );
}

/// WGS-84 geodetic ↔ ECEF ↔ local east/north/up against pyproj: published places and random
/// points up to 100 km from random origins, within a millimetre.
#[test]
fn geodesy_agrees_with_pyproj_to_the_millimetre_over_100_km() {
    use railfuse_catalog::geodesy::{ecef_to_geodetic, geodetic_to_ecef, GeodeticOrigin};
    // Published places (Greenwich, Zürich HB, Modena, Quito, Tromsø, Wellington) and a
    // seeded spread of others.
    let mut places = vec![
        (51.4779, -0.0015, 45.0),
        (47.3782, 8.5402, 408.0),
        (44.6551, 10.9297, 40.0),
        (-0.1807, -78.4678, 2850.0),
        (69.6492, 18.9553, 10.0),
        (-41.2865, 174.7762, 5.0),
    ];
    let mut state: u64 = 0x9e3779b97f4a7c15;
    let mut uniform = |lo: f64, hi: f64| {
        // SplitMix64: a seeded spread, no dependency.
        state = state.wrapping_add(0x9e3779b97f4a7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
        lo + (hi - lo) * ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..200 {
        places.push((
            uniform(-80.0, 80.0),
            uniform(-180.0, 180.0),
            uniform(-100.0, 3000.0),
        ));
    }
    let points: Vec<serde_json::Value> = places
        .iter()
        .map(|&(lat, lon, h)| {
            let origin = GeodeticOrigin {
                latitude_deg: lat,
                longitude_deg: lon,
                altitude_m: h,
            };
            // A point up to 100 km away in the origin's frame.
            let (e, n, u) = (
                uniform(-70_000.0, 70_000.0),
                uniform(-70_000.0, 70_000.0),
                uniform(-50.0, 500.0),
            );
            let (glat, glon, gh) = origin.to_geodetic(e, n, u);
            let ecef = geodetic_to_ecef(glat, glon, gh);
            serde_json::json!({
                "origin": [lat, lon, h],
                "geodetic": [glat, glon, gh],
                "ecef": [ecef.0, ecef.1, ecef.2],
                "geodetic_of_ecef": <[f64; 3]>::from(ecef_to_geodetic(ecef.0, ecef.1, ecef.2)),
                "enu": [e, n, u],
                "geodetic_of_enu": [glat, glon, gh],
                "enu_of_geodetic": <[f64; 3]>::from(origin.to_enu(glat, glon, gh)),
            })
        })
        .collect();
    let d = tempfile::tempdir().unwrap();
    let file = d.path().join("points.json");
    std::fs::write(&file, serde_json::to_vec(&points).unwrap()).unwrap();
    let v = python_ok("pyproj_geodesy.py", &[s(&file)]);
    eprintln!("railfuse against pyproj: {v}");
    assert_eq!(v["points"], 206);
    for (what, worst) in v["worst_m"].as_object().unwrap() {
        assert!(worst.as_f64().unwrap() < 1e-3, "{what}: {worst} m: {v}");
    }
}

/// The configuration schema (`refuse --config-schema`) checked by `jsonschema`: every sample
/// configuration is valid, a misspelt key, a wrong type and an unknown setting are not.
#[test]
fn every_sample_configuration_is_valid_against_the_schema_jsonschema_reads() {
    let d = tempfile::tempdir().unwrap();
    let schema = d.path().join("schema.json");
    let out = ok(&["refuse", "--config-schema"]);
    std::fs::write(&schema, &out.stdout).unwrap();
    let samples = sample("");
    let py = python("config_schema.py", &[s(&schema), s(&samples)]);
    assert!(
        py.status.success(),
        "{}{}",
        String::from_utf8_lossy(&py.stdout),
        String::from_utf8_lossy(&py.stderr)
    );
    println!("{}", String::from_utf8_lossy(&py.stdout));
}
