//! Source 001's federated Kalman filter end to end, on the `seed001` preset with a device
//! killed mid-run: its β goes to the others, it comes back when it recovers, and the fused
//! error stays within the source's targets (position < 10 m, speed < 1 km/h).

mod common;

use common::*;
use railfuse_catalog::messages::{FusedDiagnostics, FusedState};

const START_NS: u64 = 1_780_300_800 * 1_000_000_000;

/// β and fault of each device at one diagnostics message.
type Shares = Vec<(String, f64, Option<String>)>;

/// (time s, β and fault per device) of every diagnostics message of `pipeline`.
fn sharing(path: &std::path::Path, pipeline: &str) -> Vec<(f64, Shares)> {
    messages::<FusedDiagnostics>(path, &format!("/fused/{pipeline}/diagnostics"))
        .into_iter()
        .filter_map(|d| {
            let t = (d.stamp_ns - START_NS) as f64 / 1e9;
            d.sharing.map(|sh| {
                (
                    t,
                    sh.into_iter()
                        .map(|s| (s.device, s.beta, s.fault))
                        .collect(),
                )
            })
        })
        .collect()
}

#[test]
fn a_killed_device_gives_its_share_to_the_others_and_the_error_stays_within_the_source_targets() {
    let d = tempfile::tempdir().unwrap();
    let (fused, r) = seed001_with(d.path(), "4", "radar:dropout:200:300");

    let rows = sharing(&fused, "fkf");
    assert!(
        rows.len() > 10_000,
        "{} diagnostics with sharing",
        rows.len()
    );
    let radar = |row: &Shares| row.iter().find(|(n, _, _)| n == "radar").cloned().unwrap();
    for (t, row) in &rows {
        let sum: f64 = row.iter().map(|(_, b, _)| b).sum();
        assert!(
            (sum - 1.0).abs() < 1e-9,
            "at {t:.2} s β sums to {sum}: {row:?}"
        );
        let (_, beta, fault) = radar(row);
        if (202.0..299.0).contains(t) {
            assert_eq!(
                (beta, fault.as_deref()),
                (0.0, Some("timeout")),
                "at {t:.2} s the dead radar still has a share"
            );
        }
        if (20.0..199.0).contains(t) || (305.0..480.0).contains(t) {
            assert!(
                beta > 0.0 && fault.is_none(),
                "at {t:.2} s the working radar is out: {row:?}"
            );
        }
    }
    // While the radar is dead its share goes to the INS and GNSS in proportion to their own
    // (redistribution = "accuracy"): at cruise (> 150 km/h) 0.4/0.4/0.2 becomes 0.5/0.5/0.
    let (_, row) = rows.iter().find(|(t, _)| *t > 250.0).unwrap();
    assert!(
        row.iter()
            .filter(|(n, _, _)| n != "radar")
            .all(|(_, b, _)| (b - 0.5).abs() < 1e-9),
        "{row:?}"
    );

    let fkf = r["eval"]["pipelines"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "fkf")
        .unwrap();
    let pos = fkf["position_error_m"]["max_abs"].as_f64().unwrap();
    let speed = fkf["speed_error_mps"]["max_abs"].as_f64().unwrap();
    assert!(
        pos < 10.0 && speed < 1.0 / 3.6,
        "fkf with the radar dead 100 s: max position error {pos} m, speed {speed} m/s"
    );
    // Output refresh ≥ 50 Hz over the 500 s run.
    assert!(fkf["states"].as_u64().unwrap() >= 50 * 495, "{fkf}");
    let window = fkf["windows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["label"] == "fault radar: dropout")
        .expect("the fault window is evaluated");
    assert!(
        window["position_error_m"]["samples"].as_u64().unwrap() >= 4900,
        "{window}"
    );
}

#[test]
fn a_biased_ins_is_caught_and_kept_out_until_it_agrees_again() {
    let d = tempfile::tempdir().unwrap();
    let (fused, r) = seed001_with(d.path(), "2", "imu:bias=0.5:200:300");
    let rows = sharing(&fused, "fkf");
    let ins_out = |t0: f64, t1: f64| {
        rows.iter()
            .filter(|(t, _)| (t0..t1).contains(t))
            .all(|(_, row)| row[0].1 == 0.0 && row[0].2.is_some())
    };
    assert!(ins_out(201.0, 299.0), "the biased INS kept a share");
    assert!(
        rows.iter()
            .any(|(t, row)| *t > 300.0 && *t < 320.0 && row[0].1 > 0.0),
        "the INS never came back"
    );
    let pos = |name: &str| {
        let p = r["eval"]["pipelines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap();
        p["position_error_m"]["max_abs"].as_f64().unwrap()
    };
    // The centralised filter has no detector and fuses the biased INS: only its gate-lockout
    // recovery keeps it from running away (without it, 13 km), and it ends up worse than fkf.
    assert!(
        pos("fkf") < 10.0 && pos("kf") > pos("fkf"),
        "fkf {} m, kf {} m",
        pos("fkf"),
        pos("kf")
    );
}

#[test]
fn a_device_that_reports_its_own_fault_is_taken_out_and_back_by_its_events() {
    let d = tempfile::tempdir().unwrap();
    // A 0.05 m/s radar bias is below what the gates see; only the radar's own report says so.
    let (fused, _) = seed001_with(d.path(), "5", "radar:bias=0.05:150:250:reported");
    let rows = sharing(&fused, "fkf");
    let radar_fault = |t0: f64, t1: f64| {
        rows.iter()
            .filter(|(t, _)| (t0..t1).contains(t))
            .map(|(_, row)| row[2].2.clone())
            .collect::<std::collections::BTreeSet<_>>()
    };
    assert_eq!(
        radar_fault(151.0, 249.0),
        [Some("reported".to_owned())].into(),
        "the radar's report was not honoured"
    );
    assert_eq!(
        radar_fault(270.0, 480.0),
        [None].into(),
        "the radar did not come back after its recovery report"
    );
}

/// Source 001's scenario on `seed` with one injected `fault`, re-fused with seed001.toml: the
/// fused file (in `dir`) and the run's report.
fn seed001_with(
    dir: &std::path::Path,
    seed: &str,
    fault: &str,
) -> (std::path::PathBuf, serde_json::Value) {
    let (raw, fused) = (dir.join("s1.mcap"), dir.join("s1.fused.mcap"));
    simulate(
        &["--scenario", "seed001", "--seed", seed, "--fault", fault],
        &raw,
    );
    let r = refuse_json(&raw, "seed001.toml", &fused);
    (fused, r)
}

/// The last fused state of `pipeline`.
fn last_state(path: &std::path::Path, pipeline: &str) -> FusedState {
    messages::<FusedState>(path, &format!("/fused/{pipeline}/state"))
        .pop()
        .expect("fused states")
}

#[test]
fn sensor_states_learn_the_radar_scale_factor_and_carry_the_position_through_a_gnss_outage() {
    let d = tempfile::tempdir().unwrap();
    // GNSS, the only absolute position, dead for 100 s at up to 432 km/h.
    let (fused, r) = seed001_with(d.path(), "3", "gnss:dropout:200:300");
    let eval = |name: &str| pipeline_eval(&r, name);
    let max_pos = |name: &str| eval(name)["position_error_m"]["max_abs"].as_f64().unwrap();
    // Without sensor states the radar's 0.3 % scale error dead-reckons tens of metres away;
    // with them the position stays within the source's 10 m.
    assert!(
        max_pos("fkf") > 20.0 && max_pos("fkf_cal") < 10.0 && max_pos("kf_cal") < 10.0,
        "fkf {} m, fkf_cal {} m, kf_cal {} m",
        max_pos("fkf"),
        max_pos("fkf_cal"),
        max_pos("kf_cal")
    );
    // The estimate is the simulator's scale error (0.003), and knows how well it knows it.
    for name in ["fkf_cal", "kf_cal"] {
        let st = last_state(&fused, name);
        let k = st
            .sensor_states
            .iter()
            .find(|x| x.topic == "/radar/speed" && x.kind == "scale_factor")
            .expect("a scale-factor state");
        assert!(
            k.std < 2e-4 && (k.value - 0.003).abs() < 4.0 * k.std.max(2e-5),
            "{name}: {k:?}"
        );
        // Modelled errors make an honest covariance: NEES mostly inside its 95 % interval
        // (the white-noise model of the source manages a few per cent).
        let nees = eval(name)["nees"]["inside_95"].as_f64().unwrap();
        assert!(nees > 0.8, "{name}: NEES inside 95 % for {nees}");
    }
    assert!(eval("fkf")["nees"]["inside_95"].as_f64().unwrap() < 0.5);
}
