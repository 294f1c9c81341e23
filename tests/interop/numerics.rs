//! railfuse's numbers against other people's implementations of the same maths: filterpy's
//! Kalman filter and RTS smoother, pykalman's EM, pyproj's geodesy, numpy's statistics.

use super::*;
use std::path::Path;

#[test]
fn the_kalman_pipeline_and_its_rts_smoother_equal_filterpy_on_the_same_measurements() {
    let d = tempfile::tempdir().unwrap();
    // The flat world: filterpy is given the raw readings, which on the railway railfuse's
    // sensor models first move (a balise antenna's place to the front end, a wheel's rail
    // length to chainage): the filter is compared here, the geometry in tests/vehicle.rs.
    for (scenario, config, duration) in [
        ("flat", "kalman.toml", "300"),
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
        // On the drift variant, also kf_balise with the loop at its stated variance: the
        // drifting loop sets off resets to balises there (with the loop weighted by its
        // innovations, as the sample has it, they rarely come).
        let mut text = std::fs::read_to_string(sample(config)).unwrap();
        if scenario == "seed000_loop_drift" {
            let stated = text
                .split("[[pipeline]]")
                .find(|b| b.contains("name = \"kf_balise\""))
                .unwrap()
                .replace("name = \"kf_balise\"", "name = \"kf_balise_stated\"")
                .lines()
                .filter(|l| !l.starts_with("adaptive_variance"))
                .map(|l| format!("{l}\n"))
                .collect::<String>();
            text = format!("{text}\n[[pipeline]]{stated}");
        }
        let config_path = d.path().join(format!("{scenario}.toml"));
        std::fs::write(&config_path, text).unwrap();
        ok(&["refuse", s(&raw), "-c", s(&config_path), "-o", s(&fused)]);
        let r = python_ok("filterpy_kalman.py", &[s(&fused), "1e-9"]);
        assert!(r["updates_compared"].as_u64().unwrap() > 150, "{r}");
        if scenario != "flat" {
            // kf_balise has the RTS smoother: every epoch compared with filterpy's rts_smoother.
            assert!(r["smoothed_compared"].as_u64().unwrap() > 100, "{r}");
        }
        if scenario == "seed000_loop_drift" {
            // The drifting loop sets off resets to balises (and back to the loop): each one
            // replayed in numpy from the prediction.
            assert!(r["resets_compared"].as_u64().unwrap() > 0, "{r}");
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

/// The bench's Python peer (bench/peer_refuse.py) writes the records railfuse writes for the
/// same pipelines: every fused channel, a diagnostics record per measurement as railfuse, the
/// states and twins within a tenth (its filter starts, gates and ticks on its own: in file
/// order, without railfuse's reorder window), so that the bench's ratio compares the same work.
#[test]
fn the_bench_peer_writes_the_records_railfuse_writes() {
    let d = tempfile::tempdir().unwrap();
    let python = client("RAILFUSE_PYTHON", "python");
    let peer = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/peer_refuse.py");
    for (scenario, config, duration) in [
        ("seed001", "seed001.toml", "40"),
        ("default", "kalman.toml", "120"),
    ] {
        let raw = d.path().join(format!("{scenario}.mcap"));
        let (ours, theirs) = (
            raw.with_extension("fused.mcap"),
            raw.with_extension("peer.mcap"),
        );
        ok(&[
            "simulate",
            "--scenario",
            scenario,
            "--duration",
            duration,
            "-o",
            s(&raw),
        ]);
        ok(&["refuse", s(&raw), "-c", s(&sample(config)), "-o", s(&ours)]);
        let out = std::process::Command::new(&python)
            .args([s(&peer), s(&raw), s(&sample(config)), s(&theirs)])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        let counts = |log: &Path| -> std::collections::BTreeMap<String, u64> {
            let info = ok_json(&["info", "--json", s(log)]);
            info["channels"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| {
                    (
                        c["topic"].as_str().unwrap().to_owned(),
                        c["messages"].as_u64().unwrap(),
                    )
                })
                .filter(|(t, _)| t.contains("/fused/"))
                .collect()
        };
        let (ours, theirs) = (counts(&ours), counts(&theirs));
        assert_eq!(
            ours.keys().collect::<Vec<_>>(),
            theirs.keys().collect::<Vec<_>>(),
            "{scenario}"
        );
        for (topic, &n) in &ours {
            let m = theirs[topic];
            if topic.ends_with("/diagnostics") {
                assert_eq!(n, m, "{scenario} {topic}");
            }
            assert!(
                n > 100 && n.abs_diff(m) <= 2 + n / 10,
                "{scenario} {topic}: railfuse {n}, peer {m}"
            );
        }
    }
}
