use super::*;
use crate::filter::Centralised;
use crate::model::{ConstantAcceleration, ProcessNoise};
use nalgebra::{Matrix3, RowVector3, Vector3};

fn settings(feedback: Feedback) -> FederatedSettings {
    let detector = DetectorSettings {
        timeout_s: 1e9,
        stuck_messages: u32::MAX,
        gate_failures: u32::MAX,
        consistency_chi2: 0.0,
        ..Default::default()
    };
    FederatedSettings {
        feedback,
        fusion: Fusion::Information,
        fusion_period_ns: 0,
        sharing: SharingTable::source_001(),
        redistribution: Redistribution::Even,
        detector,
    }
}

/// Three devices (INS acceleration, GNSS position and speed, radar speed), measurements at
/// irregular times, speeds across all three β bands.
fn run(estimator: &mut dyn Estimator<3>) -> Vec<StateAndCovariance<3>> {
    let mut out = Vec::new();
    let mut t = 1_000_000_000u64;
    for k in 0..600u64 {
        t += 50_000_000 + (k % 7) * 3_000_000;
        let ts = t as f64 / 1e9;
        let (v, a) = (0.5 * ts.min(120.0), if ts < 120.0 { 0.5 } else { 0.0 });
        let noise = ((k * 7919) % 17) as f64 / 17.0 - 0.5;
        let (device, h, r, z) = match k % 4 {
            0 => (0, RowVector3::new(0.0, 0.0, 1.0), 0.01, a + 0.1 * noise),
            1 => (
                1,
                RowVector3::new(1.0, 0.0, 0.0),
                4.0,
                0.25 * ts * ts.min(120.0) + 2.0 * noise,
            ),
            2 => (1, RowVector3::new(0.0, 1.0, 0.0), 0.04, v + 0.2 * noise),
            _ => (2, RowVector3::new(0.0, 1.0, 0.0), 0.01, v + 0.1 * noise),
        };
        estimator.advance_to(t);
        let quantity = h.iamax_full().1;
        let o = estimator.process(&ScalarMeasurement {
            device,
            quantity,
            h,
            offset: 0.0,
            r,
            z,
            gate_nis: None,
        });
        assert!(matches!(o, Outcome::Accepted(_)), "{o:?}");
        out.push(estimator.estimate());
    }
    out
}

fn model() -> Box<dyn TransitionModel<3>> {
    Box::new(ConstantAcceleration {
        noise: ProcessNoise::WhiteJerkPsd(0.02),
    })
}

fn initial() -> StateAndCovariance<3> {
    StateAndCovariance {
        state: Vector3::new(0.5, 0.4, 0.0),
        covariance: Matrix3::from_diagonal(&Vector3::new(25.0, 4.0, 1.0)),
    }
}

fn federated(feedback: Feedback) -> Federated<3, KalmanFilter<3>> {
    let names = vec!["ins".into(), "gnss".into(), "radar".into()];
    Federated::new(
        settings(feedback),
        model(),
        names,
        &initial(),
        1_000_000_000,
        |_, s| KalmanFilter::new(s.state, s.covariance),
    )
}

#[test]
fn fusion_reset_with_information_sharing_is_the_centralised_kalman_filter() {
    let init = initial();
    let mut central = Centralised::new(
        KalmanFilter::new(init.state, init.covariance),
        model(),
        1_000_000_000,
        None,
    );
    let c = run(&mut central);
    let f = run(&mut federated(Feedback::FusionReset));
    let mut worst = 0.0f64;
    for (a, b) in c.iter().zip(&f) {
        for (x, y) in a
            .state
            .iter()
            .chain(a.covariance.iter())
            .zip(b.state.iter().chain(b.covariance.iter()))
        {
            worst = worst.max((x - y).abs() / x.abs().max(1.0));
        }
    }
    eprintln!("federated (fusion-reset) vs centralised: worst relative difference {worst:e}");
    assert!(
        worst < 1e-6,
        "federated (fusion-reset) differs from centralised by {worst}"
    );
}

#[test]
fn without_reset_the_federated_filter_is_not_the_centralised_one() {
    let init = initial();
    let mut central = Centralised::new(
        KalmanFilter::new(init.state, init.covariance),
        model(),
        1_000_000_000,
        None,
    );
    let c = run(&mut central);
    let f = run(&mut federated(Feedback::NoReset));
    let gap = c
        .iter()
        .zip(&f)
        .map(|(a, b)| (a.state[0] - b.state[0]).abs())
        .fold(0.0, f64::max);
    // It double-counts the common prior and process noise: a visible, not a rounding, gap.
    eprintln!("federated (no reset) vs centralised: largest chainage gap {gap:.4} m");
    assert!(gap > 1e-3, "no-reset gap {gap}");
    let pc = c.last().unwrap().covariance[(0, 0)];
    let pf = f.last().unwrap().covariance[(0, 0)];
    assert!((pc - pf).abs() / pc > 1e-3, "variances {pc} vs {pf}");
}

/// The estimates of a federated filter with `feedback`, master fusion every `period_ns`
/// (0: after every update), and sharing table `sharing`.
fn run_with(
    feedback: Feedback,
    period_ns: u64,
    sharing: SharingTable,
) -> Vec<StateAndCovariance<3>> {
    run_fused(feedback, Fusion::Information, period_ns, sharing)
}

fn run_fused(
    feedback: Feedback,
    fusion: Fusion,
    period_ns: u64,
    sharing: SharingTable,
) -> Vec<StateAndCovariance<3>> {
    let names = vec!["ins".into(), "gnss".into(), "radar".into()];
    let mut f = Federated::new(
        FederatedSettings {
            fusion,
            fusion_period_ns: period_ns,
            sharing,
            ..settings(feedback)
        },
        model(),
        names,
        &initial(),
        1_000_000_000,
        |_, s| KalmanFilter::new(s.state, s.covariance),
    );
    run(&mut f)
}

fn largest_chainage_gap(a: &[StateAndCovariance<3>], b: &[StateAndCovariance<3>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.state[0] - y.state[0]).abs())
        .fold(0.0, f64::max)
}

/// Where β can act, and where it cannot: the docs' claim, kept true by this test.
#[test]
fn information_sharing_changes_the_estimate_only_between_fusions_of_a_reset_filter() {
    let gap = |feedback, period| {
        let a = run_with(feedback, period, SharingTable::source_001());
        let b = run_with(feedback, period, SharingTable::even(3));
        largest_chainage_gap(&a, &b)
    };
    // Fusion-reset with a fusion after every update is the centralised filter: β cannot
    // change anything.
    let every_update = gap(Feedback::FusionReset, 0);
    assert!(every_update < 1e-9, "{every_update}");
    // With a master period the sub-filters run on their own shares between fusions, and
    // the estimate depends on those shares.
    let periodic = gap(Feedback::FusionReset, 1_000_000_000);
    assert!(periodic > 1e-3, "{periodic}");
    // Without reset each sub-filter keeps its full information: β is not used.
    assert_eq!(gap(Feedback::NoReset, 0), 0.0);
    assert_eq!(gap(Feedback::NoReset, 1_000_000_000), 0.0);
    eprintln!("β: fusion every update {every_update:e} m, fusion every 1 s {periodic:.4} m");
}

/// With β weighting the local estimates (`fusion = "shares"`, the sources' weighting)
/// β changes the fused estimate in every mode: with a fusion after every update (where
/// information sharing is the centralised filter whatever β), with a master period (by
/// more than information sharing between its fusions), and without reset (where
/// information sharing does not use β at all).
#[test]
fn weighting_by_shares_makes_beta_change_every_fused_estimate() {
    let gap = |feedback, period| {
        let a = run_fused(feedback, Fusion::Shares, period, SharingTable::source_001());
        let b = run_fused(feedback, Fusion::Shares, period, SharingTable::even(3));
        largest_chainage_gap(&a, &b)
    };
    let information = largest_chainage_gap(
        &run_with(
            Feedback::FusionReset,
            1_000_000_000,
            SharingTable::source_001(),
        ),
        &run_with(Feedback::FusionReset, 1_000_000_000, SharingTable::even(3)),
    );
    for (feedback, period) in [
        (Feedback::FusionReset, 0),
        (Feedback::FusionReset, 1_000_000_000),
        (Feedback::NoReset, 1_000_000_000),
    ] {
        let g = gap(feedback, period);
        eprintln!("shares, {feedback:?}, period {period} ns: β moves the chainage {g:.4} m (information sharing: {information:.4} m)");
        let least = match (feedback, period) {
            (Feedback::FusionReset, 0) => 1e-3,
            (Feedback::FusionReset, _) => 5.0 * information,
            (Feedback::NoReset, _) => 0.1,
        };
        assert!(g > least, "{feedback:?}, period {period}: {g} m");
    }
}

/// Source 001's INS and radar sub-filters take the devices' navigation solutions
/// (strapdown: acceleration integrated twice; radar: speed integrated once), compensated
/// with the fed-back fused state at every fusion. railfuse's sub-filters take the raw
/// acceleration and speed instead. Between two fusions, started from the same reset, the
/// two carry the same position and speed: the sub-filter is the navigation solution,
/// smoothed by its model. Run on seed001's settings (IMU at 100 Hz, σ 0.03 m/s²; radar
/// at 50 Hz, σ 0.1 m/s; jerk PSD 0.02; fusion every 1 s) over a 150 s profile of
/// acceleration, cruise and braking, with every reset at the true state.
#[test]
fn between_fusions_a_sub_filter_on_raw_samples_carries_its_devices_navigation_solution() {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};
    let model = model();
    let accel = |t: f64| match t {
        t if t < 60.0 => 1.0,
        t if t < 100.0 => 0.0,
        _ => -0.9,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (imu_noise, radar_noise) = (
        Normal::new(0.0, 0.03).unwrap(),
        Normal::new(0.0, 0.1).unwrap(),
    );
    let dt = 0.01;
    // Truth, integrated finely.
    let (mut s, mut v) = (0.0f64, 0.0f64);
    let reset_cov = Matrix3::from_diagonal(&Vector3::new(0.25, 0.01, 0.01));
    let reset = |s: f64, v: f64, a: f64| KalmanFilter::new(Vector3::new(s, v, a), reset_cov);
    let (mut ins, mut radar) = (reset(s, v, accel(0.0)), reset(s, v, accel(0.0)));
    let (mut nav_s, mut nav_v, mut dr_s) = (s, v, s);
    let (mut worst_ins_s, mut worst_ins_v, mut worst_radar_s) = (0.0f64, 0.0f64, 0.0f64);
    let (mut worst_nav_s, mut worst_dr_s) = (0.0f64, 0.0f64);
    for k in 1..=15_000u32 {
        let t = k as f64 * dt;
        let a = accel(t - dt);
        s += v * dt + a * dt * dt / 2.0;
        v += a * dt;
        // The INS: its sub-filter on the raw sample, its strapdown solution on the same.
        let a_meas = accel(t) + imu_noise.sample(&mut rng);
        ins.predict(model.as_ref(), dt);
        ins.update(&RowVector3::new(0.0, 0.0, 1.0), 0.0009, a_meas);
        nav_s += nav_v * dt + a_meas * dt * dt / 2.0;
        nav_v += a_meas * dt;
        // The radar, every other tick: sub-filter on the speed, dead reckoning on it.
        radar.predict(model.as_ref(), dt);
        if k % 2 == 0 {
            let v_meas = v + radar_noise.sample(&mut rng);
            radar.update(&RowVector3::new(0.0, 1.0, 0.0), 0.01, v_meas);
            dr_s += v_meas * 2.0 * dt;
        }
        if k % 100 == 0 {
            // The end of a fusion cycle: compare, then reset all to the (true) fused state.
            let (i, r) = (ins.estimate.state, radar.estimate.state);
            worst_ins_s = worst_ins_s.max((i[0] - nav_s).abs());
            worst_ins_v = worst_ins_v.max((i[1] - nav_v).abs());
            worst_radar_s = worst_radar_s.max((r[0] - dr_s).abs());
            worst_nav_s = worst_nav_s.max((nav_s - s).abs());
            worst_dr_s = worst_dr_s.max((dr_s - s).abs());
            ins = reset(s, v, accel(t));
            radar = reset(s, v, accel(t));
            (nav_s, nav_v, dr_s) = (s, v, s);
        }
    }
    eprintln!(
        "after 1 s from a reset, over 150 cycles: INS sub-filter − strapdown solution ≤ \
         {worst_ins_s:.4} m, {worst_ins_v:.4} m/s (strapdown − truth ≤ {worst_nav_s:.4} m); \
         radar sub-filter − dead reckoning ≤ {worst_radar_s:.4} m (dead reckoning − truth \
         ≤ {worst_dr_s:.4} m)"
    );
    // The two forms differ by less than either differs from the truth.
    assert!(
        worst_ins_s < 0.005 && worst_ins_v < 0.01,
        "{worst_ins_s} {worst_ins_v}"
    );
    assert!(worst_ins_s < worst_nav_s, "{worst_ins_s} vs {worst_nav_s}");
    assert!(
        worst_radar_s < 0.03 && worst_radar_s < worst_dr_s,
        "{worst_radar_s}"
    );
}
