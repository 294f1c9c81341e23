//! Source 002's `ekf_safety` pipeline end to end: simulated runs, re-fused from the CLI with
//! `samples/seed002.toml`, read back from the file.

mod common;

use std::path::Path;

use common::{messages, ok, railfuse, s, sample, stderr};
use railfuse_catalog::messages::{FusedState, GroundTruth, SafetyStatus};

/// The truth's chainage at a stamp, interpolated.
fn truth_at(truth: &[GroundTruth], t: u64) -> Option<f64> {
    let i = truth.partition_point(|g| g.stamp_ns < t);
    let (a, b) = (truth.get(i.checked_sub(1)?)?, truth.get(i)?);
    let w = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns).max(1) as f64;
    Some(a.chainage_m + w * (b.chainage_m - a.chainage_m))
}

/// Usable share and containment of the truth in U_safe over the usable epochs.
fn availability_and_containment(status: &[SafetyStatus], truth: &[GroundTruth]) -> (f64, f64) {
    let usable: Vec<&SafetyStatus> = status.iter().filter(|s| s.usable).collect();
    let inside = usable
        .iter()
        .filter(|s| {
            let u = s.safe_interval.expect("a usable epoch has its interval");
            truth_at(truth, s.stamp_ns).is_some_and(|c| u.contains(c))
        })
        .count();
    (
        usable.len() as f64 / status.len() as f64,
        inside as f64 / usable.len().max(1) as f64,
    )
}

fn simulate(dir: &Path, name: &str, extra: &[&str]) -> std::path::PathBuf {
    let run = dir.join(name);
    let mut args = vec![
        "simulate",
        "--scenario",
        "default",
        "--seed",
        "1",
        "--duration",
        "320",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", s(&run)]);
    ok(&args);
    run
}

fn refuse(run: &Path) -> std::path::PathBuf {
    let fused = run.with_extension("fused.mcap");
    ok(&[
        "refuse",
        s(run),
        "-c",
        s(&sample("seed002.toml")),
        "-o",
        s(&fused),
    ]);
    fused
}

#[test]
fn the_safe_interval_holds_the_truth_and_an_injected_jump_is_flagged_at_once() {
    let d = tempfile::tempdir().unwrap();
    // The GNSS jumps 20 m along the track from 250 s to 260 s.
    let run = simulate(d.path(), "jump.mcap", &["--fault", "gnss:bias=20:250:260"]);
    let fused = refuse(&run);
    let truth: Vec<GroundTruth> = messages(&fused, "/truth");
    let start = truth[0].stamp_ns;
    let cal: Vec<SafetyStatus> = messages(&fused, "/fused/ekf_safety_cal/safety");
    let (available, contained) = availability_and_containment(&cal, &truth);
    assert!(contained == 1.0, "containment {contained}");
    assert!(available > 0.8, "availability {available}");
    // The first epoch at or after the jump's first fix is not usable, and says why.
    let jump = start + 250_000_000_000;
    let at_jump = cal
        .iter()
        .find(|s| s.stamp_ns >= jump && s.checks.iter().any(|c| c.check == "s4_map"))
        .unwrap();
    let within_one_fix = cal
        .iter()
        .filter(|s| s.stamp_ns >= jump && s.stamp_ns <= jump + 100_000_000)
        .any(|s| !s.usable);
    assert!(
        within_one_fix,
        "no unusable epoch within 0.1 s of the jump: {at_jump:?}"
    );
    // Every fused state is finite and carries its place in the plane.
    let states: Vec<FusedState> = messages(&fused, "/fused/ekf_safety_cal/state");
    assert!(states.iter().all(|s| s.chainage_m.is_finite()
        && s.covariance.iter().all(|c| c.is_finite())
        && s.plane.as_ref().is_some_and(|p| p.latitude_deg.is_finite())));
    // The source as stated (white-noise sensors) claims more than it holds: the sensor states
    // are what makes the interval honest.
    let plain: Vec<SafetyStatus> = messages(&fused, "/fused/ekf_safety/safety");
    let (_, plain_contained) = availability_and_containment(&plain, &truth);
    assert!(
        plain_contained < 0.99,
        "source as stated: containment {plain_contained}"
    );
}

#[test]
fn a_stuck_axle_is_diagnosed_and_nothing_is_usable_while_it_lasts() {
    let d = tempfile::tempdir().unwrap();
    let run = simulate(
        d.path(),
        "stuck.mcap",
        &["--fault", "odometer1:stuck:200:230"],
    );
    let fused = refuse(&run);
    let truth: Vec<GroundTruth> = messages(&fused, "/truth");
    let start = truth[0].stamp_ns;
    let cal: Vec<SafetyStatus> = messages(&fused, "/fused/ekf_safety_cal/safety");
    let window: Vec<&SafetyStatus> = cal
        .iter()
        .filter(|s| s.stamp_ns >= start + 201_000_000_000 && s.stamp_ns < start + 229_000_000_000)
        .collect();
    assert!(!window.is_empty());
    // Stuck while the train moves (it stands at a station part of the time).
    let flagged = window
        .iter()
        .filter(|s| s.checks.iter().any(|c| c.check == "s1_axle_1" && !c.passed))
        .count();
    assert!(flagged > 0, "axle 1 never diagnosed stuck");
    let (_, contained) = availability_and_containment(&cal, &truth);
    assert!(contained == 1.0, "containment {contained}");
}

#[test]
fn bad_maps_and_roles_get_one_clear_line() {
    let d = tempfile::tempdir().unwrap();
    let run = d.path().join("run.mcap");
    ok(&[
        "simulate",
        "--scenario",
        "default",
        "--seed",
        "2",
        "--duration",
        "30",
        "-o",
        s(&run),
    ]);
    let base = std::fs::read_to_string(sample("seed002.toml")).unwrap();
    // A map that crosses itself.
    let map = d.path().join("eight.geojson");
    std::fs::write(
        &map,
        r#"{"type":"Feature","properties":{"name":"eight"},"geometry":{"type":"LineString",
            "coordinates":[[10.9,44.6],[10.91,44.6],[10.91,44.61],[10.905,44.61],[10.905,44.59]]}}"#,
    )
    .unwrap();
    let with_map = base.replacen(
        "[pipeline.safety]\n",
        &format!("[pipeline.safety]\nmap = {:?}\n", s(&map)),
        1,
    );
    let wrong_role = base.replacen("axle_2 = \"/odometer/2\"", "axle_2 = \"/radar/speed\"", 1);
    for (text, want) in [
        (with_map, "crosses itself"),
        (
            wrong_role,
            "safety.axle_2 is /radar/speed, which is not one of the pipeline's sensors",
        ),
    ] {
        let cfg = d.path().join("bad.toml");
        std::fs::write(&cfg, text).unwrap();
        let out = railfuse(&[
            "refuse",
            s(&run),
            "-c",
            s(&cfg),
            "-o",
            s(&d.path().join("o.mcap")),
        ]);
        let err = stderr(&out);
        assert!(!out.status.success() && err.contains(want), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}
