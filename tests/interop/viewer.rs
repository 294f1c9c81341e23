//! The Rerun side, checked by the `rerun` CLI (`rrd verify`, `rrd print`) and by a real Rerun
//! server on loopback that saves what it is streamed.

use super::*;

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
    the_layout_and_the_run_s_time_travel_in_the_file(&rrd);
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
    let py = python_ok("check_mcap.py", &[s(&fused)]);
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

/// What a stopped server saved, printed by `rerun rrd print -v`: the server was stopped
/// mid-stream, so the file has no footer and is read as far as it goes.
fn print_saved(saved: &std::path::Path) -> String {
    rerun_ok(&[
        "rrd",
        "print",
        "-v",
        "--continue-on-error",
        "true",
        s(saved),
    ])
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
    let printed = print_saved(&saved);
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
    let printed = print_saved(&saved);
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
    let printed = print_saved(&saved);
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

/// The layout travels in the file: a blueprint store with the views by name, and every
/// pipeline's diagnostics tab; the log_time timeline carries the MCAP log time of the
/// simulated run (2026-06-01), not the wall clock of the viz run.
fn the_layout_and_the_run_s_time_travel_in_the_file(rrd: &std::path::Path) {
    let data = rerun_ok(&["rrd", "print", "-vvv", s(rrd)]);
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
    assert!(
        data.contains("index_name: log_time"),
        "no log_time timeline"
    );
    assert!(
        data.contains("2026-06-01T08:01"),
        "log_time is not the run's time"
    );
}
