//! `railfuse calibrate`: the IMU's mounting from one 20-minute run of the railway scenario,
//! against the simulator's installed truth, on the preset and on a simulator whose vibration,
//! IMU and installation differ from the preset's; the calibrated train then given to
//! `refuse --vehicle`; and the runs it cannot calibrate from, refused in one line.

mod common;

use std::path::Path;

use common::*;
use railfuse_catalog::log::read_metadata;
use railfuse_catalog::messages::Vehicle;
use railfuse_record::simulator::LineScenario;
use railfuse_record::Scenario;

/// The simulator's installed mounting of the IMU, degrees.
fn installed_imu(log: &Path) -> [f64; 3] {
    let run = read_metadata(log, railfuse_catalog::topics::metadata::RUN)
        .unwrap()
        .expect("run metadata");
    let v: Vehicle = serde_json::from_str(&run["vehicle_installed"]).unwrap();
    v.mount("/imu").expect("an installed IMU").mounting_deg
}

/// Calibrates `log`, checks each angle against the truth within `limits` (degrees) and its
/// σ, and returns the errors.
fn calibrated_within(log: &Path, out: &Path, limits: [f64; 3]) -> [f64; 3] {
    let r = ok_json(&["calibrate", s(log), "-o", s(out), "--json"]);
    let truth = installed_imu(log);
    let angle = |key: &str, i: usize| r[key][i].as_f64().unwrap();
    let errors: [f64; 3] = std::array::from_fn(|i| angle("mounting_deg", i) - truth[i]);
    for (i, name) in ["roll", "pitch", "yaw"].iter().enumerate() {
        let sigma = angle("sigma_deg", i);
        assert!(r["observable"][i].as_bool().unwrap(), "{name}: {r}");
        assert!(
            errors[i].abs() <= limits[i],
            "{name}: error {:.3}° over {}°: {r}",
            errors[i],
            limits[i]
        );
        // The σ covers the error (3σ: one angle in 370 may fall outside by chance).
        assert!(
            errors[i].abs() <= 3.0 * sigma,
            "{name}: error {:.3}° beyond 3σ = {:.3}°: {r}",
            errors[i],
            3.0 * sigma
        );
    }
    println!(
        "{}: errors {errors:.3?}°, σ [{:.3}, {:.3}, {:.3}]°",
        log.display(),
        angle("sigma_deg", 0),
        angle("sigma_deg", 1),
        angle("sigma_deg", 2)
    );
    errors
}

#[test]
fn one_railway_run_gives_the_imu_mounting_to_the_goal_with_an_honest_sigma() {
    let dir = tempfile::tempdir().unwrap();
    let (log, vehicle) = (dir.path().join("run.mcap"), dir.path().join("vehicle.toml"));
    simulate(
        &[
            "--scenario",
            "default",
            "--seed",
            "21",
            "--duration",
            "1200",
        ],
        &log,
    );
    // The goal: roll and pitch within 0.05°, yaw within 0.1°.
    calibrated_within(&log, &vehicle, [0.05, 0.05, 0.1]);
    // The file is a [vehicle] table `refuse --vehicle` takes, with the calibrated IMU.
    let text = std::fs::read_to_string(&vehicle).unwrap();
    assert!(text.contains("[vehicle.sensor.\"/imu\"]"), "{text}");
    // The pipeline takes the mounting out of the IMU's reading: with the drawing's level IMU
    // its acceleration bias state takes up g sin(pitch) of the true mounting, with the
    // calibrated one next to nothing.
    let fused = dir.path().join("fused.mcap");
    let imu_bias = |extra: &[&str]| {
        let mut args = vec!["refuse", s(&log), "-o", s(&fused)];
        args.extend_from_slice(extra);
        ok(&args);
        let states: Vec<railfuse_catalog::messages::FusedState> =
            messages(&fused, "/fused/default/state");
        let last = states.last().expect("states");
        last.sensor_states
            .iter()
            .find(|x| x.topic == "/imu" && x.kind == "acceleration_bias")
            .map(|x| x.value)
            .expect("the IMU's bias is a state of the default pipeline")
    };
    let pitch = installed_imu(&log)[1].to_radians();
    let (drawing, calibrated) = (imu_bias(&[]), imu_bias(&["--vehicle", s(&vehicle)]));
    println!(
        "IMU bias state: drawing {drawing:.4} m/s², calibrated {calibrated:.4} m/s², g sin(pitch) {:.4}",
        9.80665 * pitch.sin()
    );
    assert!(
        (drawing.abs() - 9.80665 * pitch.sin().abs()).abs() < 0.03,
        "{drawing} vs g sin(pitch) {}",
        9.80665 * pitch.sin()
    );
    assert!(calibrated.abs() < 0.03, "{calibrated}");
}

#[test]
fn a_simulator_unlike_the_preset_is_calibrated_within_the_sigma_it_states() {
    // Twice the vibration, an IMU whose biases wander three times faster than the
    // calibration's prior allows for, and an IMU installed up to 3° off the drawing.
    let mut p = LineScenario::default_run();
    if let Some(ride) = &mut p.ride {
        ride.resonances.iter_mut().for_each(|r| r.rms *= 2.0);
    }
    p.imu.accel_bias_walk *= 3.0;
    p.imu.gyro_bias_walk *= 3.0;
    if let Some(v) = &mut p.vehicle {
        v.mounting_tolerance_deg = 3.0;
    }
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("run.mcap");
    railfuse_record::simulate(&Scenario::Default(Box::new(p)), 22, Some(1200.0), &[], &log)
        .unwrap();
    // Looser than the preset's goal, and said so (the docs give the figures): the σ must still
    // cover the error.
    calibrated_within(&log, &dir.path().join("v.toml"), [0.2, 0.2, 0.2]);
}

#[test]
fn a_run_it_cannot_calibrate_from_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v.toml");
    // Source 000's maglev run has no IMU.
    let maglev = dir.path().join("maglev.mcap");
    simulate(&["--scenario", "seed000", "--duration", "60"], &maglev);
    let e = fails(&["calibrate", s(&maglev), "-o", s(&out)]);
    assert!(e.contains("has no IMU channel to calibrate"), "{e}");
    // An IMU named that the run does not have.
    let run = dir.path().join("run.mcap");
    simulate(&["--scenario", "default", "--duration", "60"], &run);
    let e = fails(&["calibrate", s(&run), "--imu", "/imu/2", "-o", s(&out)]);
    assert!(
        e.contains("has no IMU channel /imu/2 (its IMU channels: /imu)"),
        "{e}"
    );
    assert!(!out.exists());
    // `refuse --vehicle` with a file that has no train in it, or places a sensor on a topic
    // neither the run nor a pipeline has.
    let fused = dir.path().join("fused.mcap");
    let no_table = dir.path().join("empty.toml");
    std::fs::write(&no_table, "# nothing\n").unwrap();
    let e = fails(&[
        "refuse",
        s(&run),
        "--vehicle",
        s(&no_table),
        "-o",
        s(&fused),
    ]);
    assert!(e.contains("empty.toml: has no [vehicle] table"), "{e}");
    let stray = dir.path().join("stray.toml");
    std::fs::write(
        &stray,
        "[vehicle]\nlength_m = 104.0\n\n[vehicle.sensor.\"/radar/sped\"]\nlever_arm_m = [-3.2, 0.0, 0.5]\n",
    )
    .unwrap();
    let e = fails(&["refuse", s(&run), "--vehicle", s(&stray), "-o", s(&fused)]);
    assert!(
        e.contains("stray.toml: [vehicle]: sensor '/radar/sped' is on no channel of the run"),
        "{e}"
    );
    assert!(!fused.exists());
}
