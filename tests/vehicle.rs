//! The railway in three dimensions and a train with its sensors where they sit: the
//! `railway` scenario's run re-fused with the vehicle as installed, and with a compensation
//! taken away from the pipeline but not from the simulator, which must cost about what it
//! compensates.

mod common;

use std::path::Path;

use common::*;
use railfuse_catalog::log::read_metadata;
use railfuse_catalog::messages::Vehicle;
use railfuse_refuse::config::VehicleConfig;

/// The train as the simulator installed it (the run's metadata), as a `[vehicle]` table
/// placing the sensors the default pipeline reads.
fn installed(log: &Path) -> Vehicle {
    let run = read_metadata(log, railfuse_catalog::topics::metadata::RUN)
        .unwrap()
        .expect("run metadata");
    serde_json::from_str(&run["vehicle_installed"]).unwrap()
}

/// The default pipeline (as `--save-config` writes it) with `vehicle` as its `[vehicle]`.
fn config_with(dir: &Path, log: &Path, vehicle: &Vehicle, name: &str) -> std::path::PathBuf {
    let default = dir.join("default.toml");
    let out = dir.join("ignored.mcap");
    ok(&[
        "refuse",
        s(log),
        "-o",
        s(&out),
        "--save-config",
        s(&default),
    ]);
    let text = std::fs::read_to_string(&default).unwrap();
    // The saved configuration holds the log's drawing, for the sensors it reads.
    let mut saved: toml::Table = toml::from_str(&text).unwrap();
    let drawn = saved
        .remove("vehicle")
        .expect("the log's /vehicle is saved");
    assert!(drawn["sensor"].get("/gnss/fix").is_some(), "{drawn}");
    let mut v = vehicle.clone();
    v.sensors
        .retain(|m| text.contains(&format!("topic = \"{}\"", m.topic)));
    saved.insert(
        "vehicle".into(),
        toml::Value::try_from(VehicleConfig::of(&v)).unwrap(),
    );
    let path = dir.join(name);
    std::fs::write(&path, toml::to_string(&saved).unwrap()).unwrap();
    path
}

fn position_rmse(log: &Path, config: &Path, out: &Path) -> f64 {
    let report = ok_json(&["refuse", s(log), "-c", s(config), "-o", s(out), "--json"]);
    pipeline_eval(&report, "default")["position_error_m"]["rmse"]
        .as_f64()
        .unwrap_or_else(|| panic!("{report}"))
}

#[test]
fn the_front_end_is_found_where_the_sensors_sit_and_a_lever_arm_left_out_costs_its_length() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("railway.mcap");
    simulate(
        &["--scenario", "default", "--duration", "300", "--seed", "5"],
        &log,
    );
    let truth = installed(&log);
    let gnss = truth.mount("/gnss/fix").expect("the antenna is placed");
    assert!(gnss.lever_arm_m[0] < -12.0, "{gnss:?}");

    let as_installed = config_with(dir.path(), &log, &truth, "installed.toml");
    let good = position_rmse(&log, &as_installed, &dir.path().join("a.mcap"));
    assert!(
        good < 0.5,
        "front end RMSE {good:.3} m with the vehicle as installed"
    );

    // The pipeline told every sensor is at the front end, the simulator not.
    let mut point = truth.clone();
    for m in &mut point.sensors {
        m.lever_arm_m = [0.0; 3];
    }
    let without = config_with(dir.path(), &log, &point, "no_lever_arms.toml");
    let bad = position_rmse(&log, &without, &dir.path().join("b.mcap"));
    assert!(
        bad > good + 5.0,
        "without lever arms {bad:.3} m, with {good:.3} m: the antenna is 12.5 m back"
    );
}

#[test]
fn a_vehicle_table_that_puts_a_sensor_off_the_train_or_on_an_unread_topic_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("railway.mcap");
    simulate(
        &["--scenario", "default", "--duration", "20", "--seed", "1"],
        &log,
    );
    let mut v = installed(&log);
    v.sensors.retain(|m| m.topic == "/gnss/fix");
    v.sensors[0].lever_arm_m[0] = -150.0;
    let cfg = config_with(dir.path(), &log, &v, "outside.toml");
    let out = dir.path().join("x.mcap");
    let e = fails(&["refuse", s(&log), "-c", s(&cfg), "-o", s(&out)]);
    assert!(
        e.contains("[vehicle]") && e.contains("outside the train"),
        "{e}"
    );

    let mut v = installed(&log);
    v.sensors.retain(|m| m.topic == "/gnss/fix");
    v.sensors[0].mounting_deg[1] = 60.0;
    let cfg = config_with(dir.path(), &log, &v, "turned.toml");
    let e = fails(&["refuse", s(&log), "-c", s(&cfg), "-o", s(&out)]);
    assert!(e.contains("pitch of 60°"), "{e}");

    // A misspelt topic.
    let cfg = config_with(dir.path(), &log, &installed(&log), "unread.toml");
    let mut table: toml::Table = toml::from_str(&std::fs::read_to_string(&cfg).unwrap()).unwrap();
    let sensors = table["vehicle"]["sensor"].as_table().unwrap().clone();
    let mut renamed = sensors.clone();
    renamed.insert("/gnss/fixx".into(), sensors["/gnss/fix"].clone());
    table["vehicle"]
        .as_table_mut()
        .unwrap()
        .insert("sensor".into(), toml::Value::Table(renamed));
    std::fs::write(&cfg, toml::to_string(&table).unwrap()).unwrap();
    let e = fails(&["refuse", s(&log), "-c", s(&cfg), "-o", s(&out)]);
    assert!(
        e.contains("'/gnss/fixx'") && e.contains("no pipeline reads"),
        "{e}"
    );
}

#[test]
fn a_track_map_without_heights_is_flat_and_said_once_not_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (flat, railway) = (dir.path().join("flat.mcap"), dir.path().join("rail.mcap"));
    simulate(
        &["--scenario", "flat", "--duration", "60", "--seed", "2"],
        &flat,
    );
    simulate(
        &["--scenario", "default", "--duration", "60", "--seed", "2"],
        &railway,
    );
    let out = dir.path().join("out.mcap");
    let said = stderr(&ok(&["refuse", s(&flat), "-o", s(&out)]));
    let lines = said
        .lines()
        .filter(|l| l.contains("has no heights"))
        .count();
    assert_eq!(lines, 1, "{said}");
    assert!(said.contains("taken as flat"), "{said}");
    let said = stderr(&ok(&["refuse", s(&railway), "-o", s(&out)]));
    assert!(!said.contains("has no heights"), "{said}");
}

#[test]
fn every_pipeline_writes_the_whole_train_with_its_safe_front_end_at_the_stated_confidence() {
    use railfuse_catalog::messages::TrainPosition;
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("railway.mcap");
    simulate(
        &["--scenario", "default", "--duration", "120", "--seed", "2"],
        &log,
    );
    let out = dir.path().join("fused.mcap");
    let train_of = |confidence: Option<&str>| {
        let mut args = vec!["refuse", s(&log), "-o", s(&out), "--json"];
        if let Some(c) = confidence {
            args.extend(["--confidence", c]);
        }
        let report = ok_json(&args);
        let trains: Vec<TrainPosition> = messages(&out, "/fused/default/train");
        (report, trains)
    };
    let (report, trains) = train_of(None);
    // Ten a second at most, over the two minutes.
    assert!(
        (1000..=1210).contains(&trains.len()),
        "{} trains",
        trains.len()
    );
    for t in &trains {
        assert_eq!(t.length_m, 104.0);
        assert!((t.front_chainage_m - t.rear_chainage_m - 104.0).abs() < 1e-9);
        let k = (t.max_safe_front_m - t.front_chainage_m) / t.front_std_m;
        assert!((k - 3.8906).abs() < 1e-3, "{t:?}");
        assert!((t.min_safe_rear_m - (t.min_safe_front_m - 104.0)).abs() < 1e-9);
        let (front, rear) = (t.front.unwrap(), t.rear.unwrap());
        // 104 m of track apart on the map (a chord is shorter than the arc it spans).
        let apart = (front.east_m - rear.east_m).hypot(front.north_m - rear.north_m);
        assert!((100.0..=104.01).contains(&apart), "{apart}");
    }
    // Scored against the truth's front end, beside the confidence it claims.
    let safe = &pipeline_eval(&report, "default")["safe_front"];
    assert_eq!(safe["confidence"].as_f64(), Some(0.9999), "{report}");
    assert!(safe["checked"].as_u64().unwrap() > 1000, "{safe}");
    // The option wins over the configuration's default: a 95 % interval is ±1.96 σ.
    let (_, narrow) = train_of(Some("0.95"));
    let t = &narrow[narrow.len() / 2];
    let k = (t.max_safe_front_m - t.front_chainage_m) / t.front_std_m;
    assert!((k - 1.96).abs() < 1e-2, "{t:?}");
    let e = fails(&["refuse", s(&log), "-o", s(&out), "--confidence", "1.5"]);
    assert!(
        e.contains("--confidence 1.5: a confidence must be at least 0.5"),
        "{e}"
    );
}

/// A `--vehicle` file of `vehicle`, every sensor it places.
fn vehicle_file(dir: &Path, vehicle: &Vehicle, name: &str) -> std::path::PathBuf {
    let mut table = toml::Table::new();
    table.insert(
        "vehicle".into(),
        toml::Value::try_from(VehicleConfig::of(vehicle)).unwrap(),
    );
    let path = dir.join(name);
    std::fs::write(&path, toml::to_string(&table).unwrap()).unwrap();
    path
}

/// The pipelines that read whole messages (source 002's EKF with its safety checks, source
/// 003's GNSS/INS, source 004's eddy-current correlation) place each sensor as the along-track
/// ones do: told the train as installed they find its front end; told every sensor is at the
/// front end (the simulator not), they miss it by about the lever arm of the sensor that
/// positions them (the roof antenna 12.5 m back, the eddy-current sensor 6 m).
#[test]
fn the_pipelines_in_the_plane_and_the_eddy_current_one_place_each_sensor_where_it_sits() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("railway.mcap");
    simulate(
        &["--scenario", "default", "--duration", "150", "--seed", "6"],
        &log,
    );
    let truth = installed(&log);
    let mut point = truth.clone();
    point.sensors.clear();
    let as_installed = vehicle_file(dir.path(), &truth, "installed.toml");
    let point = vehicle_file(dir.path(), &point, "point.toml");
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples");
    for (config, pipeline, lever_arm, good_below) in [
        ("seed002.toml", "ekf_safety_cal", 12.5, 1.5),
        ("seed003.toml", "kf_track", 12.5, 0.5),
        ("seed004.toml", "warped_kf", 6.0, 2.5),
    ] {
        let rmse = |vehicle: &Path, out: &str| {
            let config = samples.join(config);
            let out = dir.path().join(out);
            let args = ["refuse", s(&log), "-c", s(&config), "--vehicle", s(vehicle)];
            let report = ok_json(&[&args[..], &["-o", s(&out), "--json"]].concat());
            pipeline_eval(&report, pipeline)["position_error_m"]["rmse"]
                .as_f64()
                .unwrap_or_else(|| panic!("{report}"))
        };
        let good = rmse(&as_installed, "a.mcap");
        if pipeline == "kf_track" {
            // The front end's velocity, not the IMU's: on the run's 1 500 m curve the track
            // turns 0.5° between the two, 0.3 m/s across at line speed.
            let worst = front_velocity_error_max(&dir.path().join("a.mcap"), pipeline);
            assert!(
                worst < 0.25,
                "{pipeline}: front end velocity off by {worst:.3} m/s"
            );
        }
        let bad = rmse(&point, "b.mcap");
        assert!(
            good < good_below,
            "{pipeline}: front end RMSE {good:.3} m with the train as installed"
        );
        assert!(
            bad > good + 0.7 * lever_arm,
            "{pipeline}: every sensor at the front end {bad:.3} m, as installed {good:.3} m"
        );
    }
}

/// The largest error of `pipeline`'s plane velocity against the truth's front end (its
/// speed along its heading) once the run is moving, m/s.
fn front_velocity_error_max(fused: &Path, pipeline: &str) -> f64 {
    use railfuse_catalog::messages::{FusedState, GroundTruth};
    let truth: Vec<GroundTruth> = messages(fused, "/truth");
    let states: Vec<FusedState> = messages(fused, &format!("/fused/{pipeline}/state"));
    let mut worst: f64 = 0.0;
    for st in &states {
        let k = truth.partition_point(|g| g.stamp_ns < st.stamp_ns);
        let (Some(g), Some(p)) = (truth.get(k), st.plane.as_ref()) else {
            continue;
        };
        let Some([ve, vn]) = p.velocity_en_mps else {
            continue;
        };
        // The truth's nearest sample at or after the state (100 Hz): 0.01 m/s at most apart.
        if g.stamp_ns - st.stamp_ns > 10_000_000 || g.speed_mps < 5.0 {
            continue;
        }
        let (te, tn) = (
            g.speed_mps * g.heading_rad.sin(),
            g.speed_mps * g.heading_rad.cos(),
        );
        worst = worst.max((ve - te).hypot(vn - tn));
    }
    assert!(
        worst > 0.0,
        "no state of {pipeline} met the truth at its stamp"
    );
    worst
}

/// The drawing's installation tolerance is in every front end's covariance: a lever arm off by
/// its tolerance moves the front end for good, which no filter sees. The railway run's default
/// pipeline is honest with it (NEES in its 95 % interval at least 90 % of the time, at most
/// 1 % of states beyond 3σ) and overconfident with the same drawing stated exact.
#[test]
fn the_installation_tolerance_keeps_the_front_ends_covariance_honest() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("railway.mcap");
    simulate(
        &["--scenario", "default", "--duration", "300", "--seed", "9"],
        &log,
    );
    let honesty = |vehicle: Option<&Path>, out: &str| {
        let out = dir.path().join(out);
        let mut args = vec!["refuse", s(&log), "-o", s(&out), "--json"];
        if let Some(v) = vehicle {
            args.extend(["--vehicle", s(v)]);
        }
        let p = pipeline_eval(&ok_json(&args), "default");
        let inside = p["nees"]["inside_95"].as_f64().unwrap();
        (inside, p["beyond_3_sigma"].as_f64().unwrap())
    };
    let drawing: Vehicle = messages(&log, "/vehicle").remove(0);
    assert_eq!(drawing.installation_std_m, 0.03);
    let (inside, beyond) = honesty(None, "a.mcap");
    assert!(
        inside >= 0.9 && beyond <= 0.01,
        "{inside} in 95 %, {beyond} beyond 3σ"
    );
    let exact = Vehicle {
        installation_std_m: 0.0,
        ..drawing
    };
    let exact = vehicle_file(dir.path(), &exact, "exact.toml");
    let (inside_exact, _) = honesty(Some(&exact), "b.mcap");
    assert!(
        inside_exact < inside - 0.1,
        "stated exact: {inside_exact} in 95 %, with its tolerance {inside}"
    );
}
