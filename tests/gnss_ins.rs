//! Source 003's `gnss_ins` pipelines end to end: simulated runs re-fused from the CLI with
//! `samples/seed003.toml`, read back from the file and scored against the truth in the plane.

mod common;

use std::path::{Path, PathBuf};

use common::{import_eth, messages, ok, refuse, s, sample, simulate, truth_at};
use railfuse_catalog::messages::{FusedDiagnostics, FusedState, GroundTruth, ImuErrorModel};

const PIPELINES: [&str; 4] = ["kf", "akf", "rls", "pu_rls"];

fn simulate_and_refuse(dir: &Path, extra: &[&str]) -> PathBuf {
    let run = dir.join("run.mcap");
    // The whole default run: the correction outage at 120 s, the tunnel near 7 km.
    let mut args = vec!["simulate", "--scenario", "default", "--seed", "1"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", s(&run)]);
    ok(&args);
    let fused = dir.join("run.fused.mcap");
    refuse(&run, "seed003.toml", &fused);
    fused
}

/// The `kf` pipeline of samples/seed003.toml, alone.
fn kf_pipeline() -> String {
    let text = std::fs::read_to_string(sample("seed003.toml")).unwrap();
    let start = text.find("[[pipeline]]\nname = \"kf\"").unwrap();
    let end = text.find("[[pipeline]]\nname = \"akf\"").unwrap();
    text[start..end].to_owned()
}

#[test]
fn every_pipeline_fuses_the_plane_with_velocity_and_refuses_what_the_gate_refuses() {
    let d = tempfile::tempdir().unwrap();
    let fused = simulate_and_refuse(d.path(), &[]);
    let truth: Vec<GroundTruth> = messages(&fused, "/truth");
    let eval = ok(&["eval", s(&fused), "--json"]);
    let report: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    for name in PIPELINES {
        let states: Vec<FusedState> = messages(&fused, &format!("/fused/{name}/state"));
        assert!(states.len() > 2000, "{name}: {} states", states.len());
        let (mut sq, mut sq_east) = (0.0, 0.0);
        for st in &states {
            let p = st.plane.as_ref().expect("a plane position");
            let v = p.velocity_en_mps.expect("east/north velocity");
            assert!(p.east_m.is_finite() && v[0].is_finite() && v[1].is_finite());
            let g = truth_at(&truth, st.stamp_ns);
            sq += (p.east_m - g.east_m).powi(2) + (p.north_m - g.north_m).powi(2);
            sq_east += (p.east_m - g.east_m).powi(2);
        }
        let rmse = (sq / states.len() as f64).sqrt();
        // `eval` scores the plane too, and agrees (it interpolates the truth, this takes the
        // nearest 100 Hz sample).
        let pipeline = report["pipelines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap();
        let east = pipeline["plane"]["east_error_m"]["rmse"].as_f64().unwrap();
        let ours = (sq_east / states.len() as f64).sqrt();
        assert!(
            (east - ours).abs() < 0.05,
            "{name}: eval {east:.3} m, test {ours:.3} m"
        );
        // RTK most of the way, single-point fixes through the correction outage, the tunnel
        // dead-reckoned: well inside a metre overall.
        assert!(rmse < 1.0, "{name}: horizontal RMSE {rmse:.3} m");
        let diagnostics: Vec<FusedDiagnostics> =
            messages(&fused, &format!("/fused/{name}/diagnostics"));
        let refused_in_tunnel = diagnostics
            .iter()
            .filter(|d| d.reason.as_deref() == Some("fix type none, below single"))
            .count();
        assert!(
            refused_in_tunnel > 50,
            "{name}: {refused_in_tunnel} no-fix fixes refused"
        );
        // Every gate decision is written: RTK fixed fused as the reference, the correction
        // outage's single-point fixes through the pre-filter class.
        let class = |c: &str| {
            diagnostics
                .iter()
                .filter(|d| d.reason.as_deref() == Some(c) && d.axis.as_deref() == Some("east"))
                .count()
        };
        assert!(class("reference: fix type rtk_fixed") > 2000, "{name}");
        assert!(class("pre-filtered: fix type single") > 100, "{name}");
        let models: Vec<ImuErrorModel> =
            messages(&fused, &format!("/fused/{name}/imu_error_model"));
        assert!(models.len() > 200, "{name}: {} models", models.len());
        assert!(
            models.iter().any(|m| m.applied),
            "{name}: the tunnel is a GNSS loss"
        );
        assert!(models.iter().all(|m| m.gyro_bias_radps.is_finite()));
    }
}

#[test]
fn a_stuck_imu_is_refused_counted_and_said_once() {
    let d = tempfile::tempdir().unwrap();
    let fused = simulate_and_refuse(d.path(), &["--fault", "imu:stuck:100:130"]);
    let diagnostics: Vec<FusedDiagnostics> = messages(&fused, "/fused/kf/diagnostics");
    let stuck: Vec<&FusedDiagnostics> = diagnostics.iter().filter(|d| d.source == "/imu").collect();
    assert_eq!(stuck.len(), 1, "one record for the episode: {stuck:?}");
    let why = stuck[0].reason.as_deref().unwrap();
    assert!(why.starts_with("stuck: every axis has repeated"), "{why}");
    let truth: Vec<GroundTruth> = messages(&fused, "/truth");
    let at = (stuck[0].stamp_ns - truth[0].stamp_ns) as f64 / 1e9;
    assert!((100.0..102.0).contains(&at), "flagged at {at} s");
    let states: Vec<FusedState> = messages(&fused, "/fused/kf/state");
    assert!(states.iter().all(|s| s.speed_mps.is_finite()));
}

#[test]
fn real_eth_samples_no_fix_refused_and_the_standing_imus_offsets_measured() {
    // Real ETR103 recordings (GNSS and a 1.6 kHz IMU, the train standing): the gate refuses
    // the no-fix NAV-PVT with its reason; after the 3-D fix of a standing train the IMU's
    // static offsets are measured; the filter waits for the train to move.
    let d = tempfile::tempdir().unwrap();
    let import = |name: &str| {
        let log = d.path().join(format!("{name}.mcap"));
        import_eth(name, &log);
        let fused = d.path().join(format!("{name}.fused.mcap"));
        refuse(&log, "seed003.toml", &fused);
        fused
    };
    let sn1 = import("20221020_1030_R90117_Modena_SN1_sample.csv");
    let refused: Vec<FusedDiagnostics> = messages(&sn1, "/fused/pu_rls/diagnostics");
    assert_eq!(refused.len(), 2, "{refused:?}");
    for r in &refused {
        assert_eq!(r.reason.as_deref(), Some("fix type none, below single"));
    }
    let sn2 = import("20221020_1030_R90117_Modena_SN2_sample.csv");
    let waiting: Vec<FusedDiagnostics> = messages(&sn2, "/fused/kf/diagnostics");
    assert!(
        waiting
            .iter()
            .any(|w| w.reason.as_deref() == Some("waiting for a moving fix with a course")),
        "{waiting:?}"
    );
    assert!(messages::<FusedState>(&sn2, "/fused/kf/state").is_empty());
    let models: Vec<ImuErrorModel> = messages(&sn2, "/fused/kf/imu_error_model");
    let last = models.last().expect("the standing IMU's offsets");
    assert!(last.standstill_samples > 100, "{last:?}");
    // A MEMS gyro standing still: its bias, well under a degree per second.
    assert!(last.gyro_bias_radps.abs() < 1f64.to_radians(), "{last:?}");
    assert!(last.accel_bias_mps2.is_finite() && !last.applied);
}

#[test]
fn the_seed003_receiver_gives_rtk_at_5_hz_loses_satellites_in_cuttings_and_all_for_150_s() {
    use railfuse_catalog::messages::{FixType, GnssFix, Imu};
    let d = tempfile::tempdir().unwrap();
    let run = d.path().join("s3.mcap");
    simulate(&["--scenario", "seed003", "--seed", "1"], &run);
    let fixes: Vec<GnssFix> = messages(&run, "/gnss/fix");
    let t0 = fixes[0].stamp_ns;
    let at = |f: &GnssFix| (f.stamp_ns - t0) as f64 / 1e9;
    let rate = |pred: &dyn Fn(&GnssFix) -> bool| {
        let picked: Vec<f64> = fixes.iter().filter(|f| pred(f)).map(at).collect();
        let gaps: Vec<f64> = picked.windows(2).map(|w| w[1] - w[0]).collect();
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        sorted[sorted.len() / 2]
    };
    // The median interval: 0.2 s between RTK fixed fixes, 0.1 s between single-point ones.
    assert!((rate(&|f| f.fix_type == FixType::RtkFixed) - 0.2).abs() < 1e-3);
    assert!((rate(&|f| f.fix_type == FixType::Single) - 0.1).abs() < 1e-3);
    // The 150 s loss from 330 s: not one position in it.
    let lost: Vec<&GnssFix> = fixes
        .iter()
        .filter(|f| (331.0..479.0).contains(&at(f)))
        .collect();
    assert!(lost.len() > 1000 && lost.iter().all(|f| f.fix_type == FixType::None));
    // Cuttings take the sky: satellites fall well below the open line's, HDOP rises.
    let open = fixes.iter().map(|f| f.satellites).max().unwrap();
    let fewest = fixes
        .iter()
        .filter(|f| f.fix_type.has_position())
        .map(|f| f.satellites)
        .min()
        .unwrap();
    assert!(open >= 16 && fewest <= 8, "satellites {fewest}..{open}");
    let imu: Vec<Imu> = messages(&run, "/imu");
    let span = (imu.last().unwrap().stamp_ns - imu[0].stamp_ns) as f64 / 1e9;
    assert!((imu.len() as f64 / span - 30.0).abs() < 0.1, "IMU at 30 Hz");
}

#[test]
fn learnt_imu_errors_carry_the_navigation_through_the_tunnel_after_a_bias_shift() {
    // The forward accelerometer's bias jumps by 0.05 m/s² at 100 s, far faster than the bias
    // state's hour-long random walk lets it follow: GNSS keeps correcting the speed at a
    // steady rate, that rate is learnt, and through the tunnel (near 7 km) it keeps
    // correcting. Without learning the tunnel error is many times larger.
    let d = tempfile::tempdir().unwrap();
    let kf = &kf_pipeline();
    let off = kf
        .replace("name = \"kf\"", "name = \"kf_unlearnt\"")
        .replacen(
            "imu = \"/imu\"\n",
            "imu = \"/imu\"\nlearning = { enabled = false }\n",
            1,
        );
    let config = d.path().join("learning.toml");
    std::fs::write(&config, format!("{kf}{off}")).unwrap();
    let run = d.path().join("run.mcap");
    // The flat world: on the railway the IMU's mounting (1.8° of pitch the drawing does not
    // know) would be what is learnt; `calibrate` is the tool for that.
    simulate(
        &[
            "--scenario",
            "flat",
            "--seed",
            "1",
            "--fault",
            "imu:bias=0.05:100:500",
        ],
        &run,
    );
    let fused = d.path().join("run.fused.mcap");
    ok(&["refuse", s(&run), "-c", s(&config), "-o", s(&fused)]);
    let truth: Vec<GroundTruth> = messages(&fused, "/truth");
    let (tunnel_in, tunnel_out) = (7000.0, 7800.0);
    let tunnel_rmse = |name: &str| {
        let states: Vec<FusedState> = messages(&fused, &format!("/fused/{name}/state"));
        let errors: Vec<f64> = states
            .iter()
            .filter_map(|st| {
                let g = truth_at(&truth, st.stamp_ns);
                (tunnel_in..tunnel_out)
                    .contains(&g.chainage_m)
                    .then(|| st.chainage_m - g.chainage_m)
            })
            .collect();
        assert!(
            errors.len() > 200,
            "{name}: {} states in the tunnel",
            errors.len()
        );
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
    };
    let (learnt, unlearnt) = (tunnel_rmse("kf"), tunnel_rmse("kf_unlearnt"));
    assert!(
        learnt < 0.3 * unlearnt,
        "tunnel chainage RMSE {learnt:.3} m learnt, {unlearnt:.3} m without"
    );
    let models: Vec<ImuErrorModel> = messages(&fused, "/fused/kf/imu_error_model");
    let applied = models
        .iter()
        .find(|m| m.applied)
        .expect("applied in the tunnel");
    // The bias reads too much acceleration: GNSS kept pulling the speed down.
    assert!(applied.speed_residual_mps2 < -0.003, "{applied:?}");
}

#[test]
fn bad_fixes_and_imu_samples_get_their_reason_nothing_fused_from_them_and_are_counted() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("bad.mcap");
    let t0 = write_east_run_with_bad_samples(&log);
    let config = d.path().join("kf.toml");
    std::fs::write(&config, kf_pipeline()).unwrap();
    let fused = d.path().join("bad.fused.mcap");
    let out = ok(&["refuse", s(&log), "-c", s(&config), "-o", s(&fused)]);
    let printed = String::from_utf8_lossy(&out.stdout).into_owned() + &common::stderr(&out);
    let diagnostics: Vec<FusedDiagnostics> = messages(&fused, "/fused/kf/diagnostics");
    let reasons: Vec<&str> = diagnostics
        .iter()
        .filter_map(|d| d.reason.as_deref())
        .collect();
    let absurd = reasons
        .iter()
        .filter(|r| r.starts_with("absurd coordinates"))
        .count();
    assert_eq!(absurd, 2, "{reasons:?}");
    assert!(
        reasons
            .iter()
            .any(|r| r.starts_with("saturated: specific force x")),
        "{reasons:?}"
    );
    assert!(
        reasons.contains(&"older than the filter's time"),
        "{reasons:?}"
    );
    // Counted: 2 fixes and the saturated sample invalid, the old sample late.
    assert!(printed.contains("3 invalid, 1 late"), "{printed}");
    assert!(
        printed.contains("GNSS gate: 58 fixes taken as the reference, 0 pre-filtered, 2 refused"),
        "{printed}"
    );
    // Nothing fused from them: the track stays on the line the good fixes give.
    let states: Vec<FusedState> = messages(&fused, "/fused/kf/state");
    assert!(states.len() > 50, "{} states", states.len());
    for st in &states {
        let p = st.plane.as_ref().unwrap();
        assert!(p.north_m.abs() < 0.5, "{} m off the line", p.north_m);
        let t = (st.stamp_ns - t0) as f64 / 1e9;
        assert!((p.east_m - 10.0 * t).abs() < 0.5, "{} m at {t} s", p.east_m);
    }
}

#[test]
fn a_bad_pre_filter_setting_is_one_line_naming_the_table() {
    let d = tempfile::tempdir().unwrap();
    let bad = kf_pipeline().replacen(
        "imu = \"/imu\"\n",
        "imu = \"/imu\"\nprefilter.imu = { kind = \"rls\", lambda = 1.5 }\n",
        1,
    );
    let config = d.path().join("bad.toml");
    std::fs::write(&config, bad).unwrap();
    let run = d.path().join("run.mcap");
    simulate(
        &["--scenario", "default", "--seed", "1", "--duration", "20"],
        &run,
    );
    let out = common::railfuse(&[
        "refuse",
        s(&run),
        "-c",
        s(&config),
        "-o",
        s(&d.path().join("f.mcap")),
    ]);
    assert!(!out.status.success());
    let err = common::stderr(&out);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("gnss_ins.prefilter.imu") && err.contains("lambda = 1.5"),
        "{err}"
    );
}

#[test]
fn the_viewer_draws_the_plane_velocity_the_learnt_model_and_a_gap_through_the_gnss_loss() {
    // seed003's first 500 s: the 150 s loss of every satellite from 330 s inside.
    let d = tempfile::tempdir().unwrap();
    let config = d.path().join("kf.toml");
    std::fs::write(&config, kf_pipeline()).unwrap();
    let run = d.path().join("s3.mcap");
    simulate(
        &["--scenario", "seed003", "--seed", "1", "--duration", "500"],
        &run,
    );
    let fused = d.path().join("s3.fused.mcap");
    ok(&["refuse", s(&run), "-c", s(&config), "-o", s(&fused)]);
    let rrd = d.path().join("s3.rrd");
    ok(&["viz", s(&fused), "--save", s(&rrd)]);
    let verify = common::rerun(&["rrd", "verify", s(&rrd)]);
    assert!(verify.status.success(), "{}", common::stderr(&verify));
    let printed = String::from_utf8_lossy(&common::rerun(&["rrd", "print", "-v", s(&rrd)]).stdout)
        .into_owned();
    for entity in [
        "/diagnostics/kf/velocity_error/east",
        "/diagnostics/kf/velocity_error/north",
        "/diagnostics/kf/imu_error_model/speed_residual",
        "/diagnostics/kf/imu_error_model/heading_residual",
    ] {
        assert!(printed.contains(entity), "{entity} missing");
    }
    // The receiver's speed line breaks where it fell silent: a Clear on its entity.
    assert!(
        printed
            .lines()
            .any(|l| l.contains("- /speed/gnss -") && l.contains("Clear")),
        "no break in /speed/gnss"
    );
}

/// A train heading east at 10 m/s near Modena: RTK fixes at 10 Hz, an IMU at 100 Hz. Into it:
/// a fix off the globe, a fix 5000 km away, a saturated IMU sample, and an IMU sample stamped
/// a second in the past. Returns the first stamp.
fn write_east_run_with_bad_samples(log: &Path) -> u64 {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::{FixType, GnssFix, Imu};
    let origin = railfuse_catalog::geodesy::GeodeticOrigin {
        latitude_deg: 44.6551,
        longitude_deg: 10.9297,
        altitude_m: 40.0,
    };
    let mut w = LogWriter::create(log).unwrap();
    let gnss = w.add_channel::<GnssFix>("/gnss/fix").unwrap();
    let imu = w.add_channel::<Imu>("/imu").unwrap();
    let t0 = 1_780_300_800_000_000_000u64;
    let fix_at = |k: u64| {
        let t = k as f64 * 0.1;
        let (lat, lon, alt) = origin.to_geodetic(10.0 * t, 0.0, 0.0);
        GnssFix {
            stamp_ns: t0 + k * 100_000_000,
            fix_type: FixType::RtkFixed,
            satellites: 18,
            hdop: Some(0.8),
            latitude_deg: Some(lat),
            longitude_deg: Some(lon),
            altitude_m: Some(alt),
            altitude_msl_m: None,
            position_covariance_enu_m2: Some([4e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 1e-3]),
            speed_mps: Some(10.0),
            course_rad: Some(std::f64::consts::FRAC_PI_2),
        }
    };
    for k in 0..600u64 {
        let t = t0 + k * 10_000_000;
        // A little noise on every axis, as a real sensor has.
        let wobble = 1e-3 * ((k * 7919) % 13) as f64;
        let mut m = Imu {
            stamp_ns: t,
            sensor_id: "imu".into(),
            specific_force_mps2: [wobble, -wobble, 9.80665 + wobble],
            angular_rate_radps: [wobble * 0.1, -wobble * 0.1, wobble * 0.01],
            accel_lsb_mps2: None,
            gyro_lsb_radps: None,
        };
        match k {
            300 => m.specific_force_mps2[0] = 60.0,
            400 => m.stamp_ns -= 1_000_000_000,
            _ => {}
        }
        w.write(imu, t, &m).unwrap();
        if k % 10 == 0 {
            let mut f = fix_at(k / 10);
            match k / 10 {
                20 => f.latitude_deg = Some(95.0),
                30 => f.latitude_deg = Some(f.latitude_deg.unwrap() + 45.0),
                _ => {}
            }
            w.write(gnss, t, &f).unwrap();
        }
    }
    w.finish().unwrap();
    t0
}
