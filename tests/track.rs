//! `railfuse track`: the centre line and chainage fitted from the RTK fixes of simulated runs
//! over the default line, scored against the simulator's own line (across the track, in the
//! gaps crossed by the runs' motion and without it, chainage, against an OpenStreetMap way); a
//! ROS 2 bag re-fused on a line fitted from itself; and bad input.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use railfuse_catalog::map_matching::nearest_on;
use railfuse_catalog::messages::{FusedState, GroundTruth, TrackMap, TrackVertex};
use railfuse_catalog::track_geojson::read_track_file;

/// Default runs (507 s each) of `seeds`, in `dir`.
fn runs(dir: &Path, seeds: &[&str]) -> Vec<PathBuf> {
    runs_in(dir, "default", seeds)
}

/// [`runs`] of the scenario `scenario`.
fn runs_in(dir: &Path, scenario: &str, seeds: &[&str]) -> Vec<PathBuf> {
    seeds
        .iter()
        .map(|seed| {
            let p = dir.join(format!("run{seed}.mcap"));
            simulate(&["--scenario", scenario, "--seed", seed], &p);
            p
        })
        .collect()
}

#[test]
fn three_runs_give_the_true_line_to_centimetres_and_its_chainage() {
    let d = tempfile::tempdir().unwrap();
    // The railway: the roof antenna leans into the canted curves by up to 0.4 m, which the
    // runs' IMUs take out.
    let logs = runs(d.path(), &["1", "2", "3"]);
    let truth: TrackMap = messages(&logs[0], "/track/map").remove(0);
    // A kilometre post: where the true line is at 1 km.
    let (e, n, _) = truth.locate(1000.0).unwrap();
    let (lat, lon, _) = truth.origin.to_geodetic(e, n, 0.0);
    let (line, csv) = (d.path().join("line.geojson"), d.path().join("line.csv"));
    let post = format!("{lat},{lon}=1");
    let mut args = vec!["track"];
    args.extend(logs.iter().map(|p| s(p)));
    args.extend([
        "-o",
        s(&line),
        "--csv",
        s(&csv),
        "--chainage-at",
        &post,
        "--json",
    ]);
    let report = ok_json(&args);
    assert_eq!(report["runs"].as_array().unwrap().len(), 3);
    assert!(
        report["lateral_residual_rms_m"].as_f64().unwrap() < 0.03,
        "{report}"
    );
    let gaps = stretches(&report["gaps"]);
    // The tunnel (7.0–7.8 km) has no fix: bridged, and said so.
    assert!(
        gaps.iter().any(|&(a, b)| a < 7000.0 && b > 7800.0),
        "{gaps:?}"
    );

    // What --track reads, GeoJSON and CSV alike, lies on the true line.
    let fitted = read_track_file(&line).unwrap();
    let cant = |m: &TrackMap| m.vertices.iter().map(|v| v.cant_m).collect::<Vec<_>>();
    assert_eq!(cant(&read_track_file(&csv).unwrap()), cant(&fitted));
    let score = score(&fitted, &truth, &gaps);
    assert!(score.covered_rms < 0.03, "{score:?}");
    // The cant from the runs' IMU roll, where there are fixes (up to 150 mm on this line).
    let cant_rms = cant_error_rms(&fitted, &truth, &gaps);
    assert!(cant_rms < 0.005, "cant {cant_rms} m RMS");
    assert!(score.whole_rms < 0.10, "{score:?}");
    assert!(score.worst_chainage < 0.0005, "{score:?}");
    // Each gap crossed by all three runs' motion; without it the spline alone bridges them
    // metres off.
    assert!(
        report["gaps"]
            .as_array()
            .unwrap()
            .iter()
            .all(|g| g["crossed_by_runs"] == 3),
        "{report}"
    );
    let alone = d.path().join("spline-alone.geojson");
    let mut args_alone = args.clone();
    let at = args_alone.iter().position(|a| *a == s(&line)).unwrap();
    args_alone[at] = s(&alone);
    args_alone.push("--no-motion");
    ok(&args_alone);
    let without = score_of(&alone, &truth, &gaps);
    assert!(
        without.gaps_rms > 5.0 * score.gaps_rms,
        "{without:?} against {score:?}"
    );

    // Checked against an OpenStreetMap extract of the true line drawn 1.5 m to its left,
    // as .osm XML and as GeoJSON, beside a road that is no railway.
    let (osm, geo) = (d.path().join("line.osm"), d.path().join("osm.geojson"));
    let drawn = osm_extract(&truth, 1.5, &osm, &geo);
    for extract in [&osm, &geo] {
        let mut with_osm = args.clone();
        with_osm[at] = s(&alone);
        with_osm.extend(["--osm", s(extract)]);
        let r = ok_json(&with_osm);
        let o = &r["osm"];
        assert_eq!(o["ways"], 1, "{r}");
        assert!(o["share_near"].as_f64().unwrap() > 0.99, "{o}");
        assert!(
            (o["rms_m"].as_f64().unwrap() - drawn).abs() < 0.1,
            "{o} against {drawn}"
        );
    }

    // A log re-fuses on it.
    let out = d.path().join("on-line.mcap");
    ok(&["refuse", s(&logs[0]), "--track", s(&line), "-o", s(&out)]);
}

/// `truth`'s line drawn `left_m` to its left as an OpenStreetMap way (`railway=rail`) beside a
/// road, written as .osm XML and as GeoJSON; the offset as drawn (its RMS over the line).
fn osm_extract(truth: &TrackMap, left_m: f64, osm: &Path, geo: &Path) -> f64 {
    let v = &truth.vertices;
    let points: Vec<(f64, f64)> = (0..v.len())
        .map(|i| {
            let (a, b) = (v[i.saturating_sub(1)], v[(i + 1).min(v.len() - 1)]);
            let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
            let len = de.hypot(dn);
            // Left of the direction (de, dn) is (−dn, de).
            let (e, n) = (
                v[i].east_m - left_m * dn / len,
                v[i].north_m + left_m * de / len,
            );
            let (lat, lon, _) = truth.origin.to_geodetic(e, n, 0.0);
            (lat, lon)
        })
        .collect();
    let mut xml = String::from("<?xml version=\"1.0\"?>\n<osm version=\"0.6\">\n");
    for (i, (lat, lon)) in points.iter().enumerate() {
        xml += &format!("<node id=\"{}\" lat=\"{lat}\" lon=\"{lon}\"/>\n", i + 1);
    }
    xml += "<way id=\"1\">";
    for i in 0..points.len() {
        xml += &format!("<nd ref=\"{}\"/>", i + 1);
    }
    xml += "<tag k=\"railway\" v=\"rail\"/></way>\n";
    xml += "<way id=\"2\"><nd ref=\"1\"/><nd ref=\"2\"/><tag k=\"highway\" v=\"primary\"/></way>\n</osm>\n";
    std::fs::write(osm, xml).unwrap();
    let coordinates: Vec<[f64; 2]> = points.iter().map(|&(lat, lon)| [lon, lat]).collect();
    let road = [coordinates[0], coordinates[1]];
    let collection = serde_json::json!({ "type": "FeatureCollection", "features": [
        { "type": "Feature", "properties": { "railway": "rail" },
          "geometry": { "type": "LineString", "coordinates": coordinates } },
        { "type": "Feature", "properties": { "highway": "primary" },
          "geometry": { "type": "LineString", "coordinates": road } } ] });
    std::fs::write(geo, collection.to_string()).unwrap();
    left_m
}

#[test]
fn a_2d_pipelines_fused_states_make_a_line_and_an_along_track_ones_are_refused() {
    // seed003's first two minutes re-fused by its GNSS/INS pipelines (positions in the
    // plane), and the default run's by the default pipeline (chainage on its map).
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("s3.mcap"), d.path().join("s3.fused.mcap"));
    simulate(&["--scenario", "seed003", "--duration", "120"], &raw);
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/seed003.toml");
    ok(&["refuse", s(&raw), "-c", s(&config), "-o", s(&fused)]);
    let line = d.path().join("line.geojson");
    let report = ok_json(&[
        "track",
        s(&fused),
        "--topic",
        "/fused/kf/state",
        "-o",
        s(&line),
        "--tolerance",
        "1",
        "--json",
    ]);
    assert_eq!(report["fix_quality"], "fused states", "{report}");
    let states: Vec<FusedState> = messages(&fused, "/fused/kf/state");
    let with_position = states.iter().filter(|st| st.plane.is_some()).count();
    assert!(with_position > 1000, "{with_position}");
    assert_eq!(report["runs"][0]["fixes"], with_position, "{report}");
    // Past the first station's multipath (which the plain KF follows, as the fixes do) the
    // line lies on the true one to a fused state's decimetres.
    let truth = true_line(&raw);
    let fitted = read_track_file(&line).unwrap();
    let mut worst = 0.0f64;
    for v in &fitted.vertices {
        let (lat, lon, _) = fitted.origin.to_geodetic(v.east_m, v.north_m, 0.0);
        let (te, tn, _) = truth.origin.to_enu(lat, lon, 0.0);
        let m = nearest_on(&truth.vertices, 0..truth.vertices.len(), te, tn).unwrap();
        if !m.beyond_end && m.chainage_m > 400.0 && m.chainage_m < truth.length_m() - 10.0 {
            worst = worst.max(m.lateral_m.abs());
        }
    }
    assert!(worst < 0.5, "{worst} m off the true line");
    // An along-track pipeline's states have no position to fit.
    let run = &runs(d.path(), &["1"])[0];
    let along = d.path().join("along.mcap");
    ok(&["refuse", s(run), "-o", s(&along)]);
    let r = railfuse(&[
        "track",
        s(&along),
        "--topic",
        "/fused/default/state",
        "-o",
        s(&line),
    ]);
    let err = stderr(&r);
    assert!(
        !r.status.success() && err.contains("holds no fused state with a position"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// A report's stretches (gaps, set aside), from–to m.
fn stretches(list: &serde_json::Value) -> Vec<(f64, f64)> {
    list.as_array()
        .unwrap()
        .iter()
        .map(|g| (g["from_m"].as_f64().unwrap(), g["to_m"].as_f64().unwrap()))
        .collect()
}

/// The true centre line of a run: where its train was (`/truth`), a vertex every metre of
/// chainage, in its map's frame (seed002's map has its survey's error; the truth does not).
fn true_line(log: &Path) -> TrackMap {
    let map: TrackMap = messages(log, "/track/map").remove(0);
    let mut vertices: Vec<TrackVertex> = Vec::new();
    for t in messages::<GroundTruth>(log, "/truth") {
        if vertices
            .last()
            .is_none_or(|v| t.chainage_m >= v.chainage_m + 1.0)
        {
            vertices.push(TrackVertex::at(t.chainage_m, t.east_m, t.north_m));
        }
    }
    TrackMap { vertices, ..map }
}

#[test]
fn station_multipath_is_set_aside_by_the_runs_gyros() {
    // seed002: four stations whose buildings pull every fix, RTK fixed ones too, up to 3 m
    // to the left within 300 m, the same on every run; the runs start and stop at the end
    // ones.
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<PathBuf> = ["1", "2", "3"]
        .iter()
        .map(|seed| {
            let p = d.path().join(format!("station{seed}.mcap"));
            simulate(&["--scenario", "seed002", "--seed", seed], &p);
            p
        })
        .collect();
    let truth = true_line(&logs[0]);
    let line = d.path().join("line.geojson");
    let mut args = vec!["track"];
    args.extend(logs.iter().map(|p| s(p)));
    args.extend(["-o", s(&line), "--json"]);
    let report = ok_json(&args);
    // One stretch set aside around each station (0, 5.7, 11.4 and 17.1 km).
    let aside = stretches(&report["set_aside"]);
    assert_eq!(aside.len(), 4, "{report}");
    for ((from, to), station) in aside.iter().zip([0.0, 5700.0, 11_400.0, 17_100.0]) {
        assert!(
            *from <= (station - 250.0f64).max(0.0) && *to >= (station + 250.0f64).min(17_050.0),
            "{aside:?}"
        );
    }
    let gaps = stretches(&report["gaps"]);
    let score = score_of(&line, &truth, &gaps);
    assert!(score.whole_rms < 0.10, "{score:?}");
    assert!(score.covered_rms < 0.03, "{score:?}");
    assert!(score.worst_chainage < 0.0005, "{score:?}");
    // Without the runs' motion the line follows the pull.
    let no_motion = d.path().join("no-motion.geojson");
    let mut args = vec!["track"];
    args.extend(logs.iter().map(|p| s(p)));
    args.extend(["-o", s(&no_motion), "--no-motion", "--json"]);
    let report = ok_json(&args);
    assert!(report["set_aside"].as_array().unwrap().is_empty());
    let pulled = score_of(&no_motion, &truth, &[]);
    assert!(pulled.whole_rms > 0.5, "{pulled:?}");
}

/// A fitted line against the true one, every metre of its chainage.
#[derive(Debug)]
struct Score {
    /// Across the track where the runs have fixes, in the gaps, and over the whole line, m.
    covered_rms: f64,
    gaps_rms: f64,
    whole_rms: f64,
    /// The largest chainage error as a share of the chainage, beyond 1 km.
    worst_chainage: f64,
}

/// RMS of `fitted`'s cant against `truth`'s every 10 m of its chainage outside `gaps`, m.
fn cant_error_rms(fitted: &TrackMap, truth: &TrackMap, gaps: &[(f64, f64)]) -> f64 {
    let (first, last) = (fitted.vertices[0].chainage_m, fitted.length_m());
    let errors: Vec<f64> = (0..)
        .map(|k| first + 10.0 * k as f64)
        .take_while(|&c| c < last)
        .filter(|&c| !gaps.iter().any(|&(a, b)| (a..=b).contains(&c)))
        .map(|c| {
            let (e, n, _) = fitted.locate(c).unwrap();
            let (lat, lon, _) = fitted.origin.to_geodetic(e, n, 0.0);
            let (te, tn, _) = truth.origin.to_enu(lat, lon, 0.0);
            let m = nearest_on(&truth.vertices, 0..truth.vertices.len(), te, tn).unwrap();
            fitted.cant_at(c) - truth.cant_at(m.chainage_m)
        })
        .collect();
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

fn score_of(path: &Path, truth: &TrackMap, gaps: &[(f64, f64)]) -> Score {
    score(&read_track_file(path).unwrap(), truth, gaps)
}

fn score(fitted: &TrackMap, truth: &TrackMap, gaps: &[(f64, f64)]) -> Score {
    let (mut covered, mut bridged, mut worst_chainage) = (Vec::new(), Vec::new(), 0.0f64);
    let first = fitted.vertices.first().unwrap().chainage_m;
    let last = fitted.vertices.last().unwrap().chainage_m;
    let mut c = first.ceil();
    while c < last {
        let (fe, fn_, _) = fitted.locate(c).unwrap();
        let (lat, lon, _) = fitted.origin.to_geodetic(fe, fn_, 0.0);
        let (te, tn, _) = truth.origin.to_enu(lat, lon, 0.0);
        let m = nearest_on(&truth.vertices, 0..truth.vertices.len(), te, tn).unwrap();
        match gaps.iter().any(|&(a, b)| (a..=b).contains(&c)) {
            true => bridged.push(m.lateral_m),
            false => covered.push(m.lateral_m),
        }
        if m.chainage_m > 1000.0 {
            worst_chainage = worst_chainage.max((c - m.chainage_m).abs() / m.chainage_m);
        }
        c += 1.0;
    }
    let rms = |x: &[f64]| (x.iter().map(|e| e * e).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let whole: Vec<f64> = covered.iter().chain(&bridged).copied().collect();
    assert!(
        covered.len() > 7000 && (bridged.len() > 3000 || gaps.is_empty()),
        "{} {}",
        covered.len(),
        bridged.len()
    );
    Score {
        covered_rms: rms(&covered),
        gaps_rms: rms(&bridged),
        whole_rms: rms(&whole),
        worst_chainage,
    }
}

#[test]
fn a_ros2_bag_refuses_on_a_line_fitted_from_itself_as_on_the_simulators() {
    // The default run of seed 1 rewritten by rosbags as a bag with no track map
    // (tests/interop/ros2_bag.py writes the simulator's line beside it); the line fitted
    // from the bag and two other runs. A NavSatFix says GBAS for RTK float and fixed alike,
    // so the float fixes count: their σ weights them, the promise needs 0.5 m.
    let d = tempfile::tempdir().unwrap();
    let logs = runs(d.path(), &["1", "4", "5"]);
    let py = python("ros2_bag.py", &[s(&logs[0]), s(d.path())]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let (bag, simulators) = (d.path().join("bag"), d.path().join("line.geojson"));
    let truth_map: TrackMap = messages(&logs[0], "/track/map").remove(0);
    let (e, n, _) = truth_map.locate(1000.0).unwrap();
    let (lat, lon, _) = truth_map.origin.to_geodetic(e, n, 0.0);
    let post = format!("{lat},{lon}=1");
    let fitted = d.path().join("fitted.geojson");
    ok(&[
        "track",
        s(&bag),
        s(&logs[1]),
        s(&logs[2]),
        "-o",
        s(&fitted),
        "--chainage-at",
        &post,
        "--tolerance",
        "0.5",
    ]);
    let truth: Vec<GroundTruth> = messages(&logs[0], "/truth");
    let rmse = |line: &Path| {
        let out = d.path().join("on.mcap");
        ok(&["refuse", s(&bag), "--track", s(line), "-o", s(&out)]);
        let states: Vec<FusedState> = messages(&out, "/fused/default/state");
        let sq: Vec<f64> = states
            .iter()
            .filter(|st| {
                st.stamp_ns > truth[0].stamp_ns && st.stamp_ns < truth.last().unwrap().stamp_ns
            })
            .map(|st| {
                let i = truth.partition_point(|g| g.stamp_ns < st.stamp_ns);
                let (a, b) = (&truth[i - 1], &truth[i]);
                let f = (st.stamp_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
                let c = a.chainage_m + f * (b.chainage_m - a.chainage_m);
                (st.chainage_m - c).powi(2)
            })
            .collect();
        (sq.iter().sum::<f64>() / sq.len() as f64).sqrt()
    };
    let (on_fitted, on_simulators) = (rmse(&fitted), rmse(&simulators));
    assert!(
        on_fitted < 1.05 * on_simulators,
        "{on_fitted} m on the fitted line, {on_simulators} m on the simulator's"
    );
}

#[test]
fn bad_runs_and_posts_are_one_line_each_before_any_output() {
    let d = tempfile::tempdir().unwrap();
    let run = &runs(d.path(), &["1"])[0];
    let other = d.path().join("maglev.mcap");
    simulate(&["--scenario", "seed001", "--duration", "60"], &other);
    let no_gnss = d.path().join("seed000.mcap");
    simulate(&["--scenario", "seed000", "--duration", "20"], &no_gnss);
    let out = d.path().join("line.geojson");
    let fails = |args: &[&str], says: &str| {
        let mut all = vec!["track"];
        all.extend(args);
        all.extend(["-o", s(&out)]);
        let r = railfuse(&all);
        let err = stderr(&r);
        assert!(!r.status.success() && err.contains(says), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    };
    fails(
        &[s(run), "--quality", "dgps"],
        "none of its 4808 fixes on /gnss/fix is of the stated quality (dgps)",
    );
    fails(
        &[s(run), s(&other), "--quality", "all", "--tolerance", "10"],
        "maglev.mcap: 0 of its",
    );
    fails(&[s(&no_gnss)], "seed000.mcap: no GNSS fix channel");
    fails(
        &[s(run), "--quality", "all"],
        "m RMS across the track between chainage",
    );
    // A run without its IMU keeps the roof antenna's lean (0.4 m in the canted curves): the
    // fit cannot keep its promise, and says which run is the likely cause.
    let no_imu = d.path().join("no_imu.mcap");
    simulate(&["--seed", "2", "--fault", "imu:dropout:0:100000"], &no_imu);
    fails(
        &[s(run), s(&no_imu)],
        &format!(
            "keep the roof antenna's lean in canted curves (no IMU to take it out: {})",
            no_imu.display()
        ),
    );
    fails(
        &[s(run), "--chainage-at", "45.0,11.0=3"],
        "--chainage-at 45.0,11.0=3 lies",
    );
    fails(
        &[s(run), "--origin", "95,3"],
        "--origin '95,3': a place is LAT,LON",
    );
    assert!(!out.exists());
}

/// The height profile from two runs of the railway scenario: where the runs have fixes the
/// fitted top of rail lies within centimetres of the simulator's (the antenna's height above
/// the rail taken off from the log's vehicle); the gradients a dead reckoning needs come with
/// the line.
#[test]
fn the_height_profile_is_fitted_from_the_fixes_heights() {
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<PathBuf> = ["1", "2"]
        .iter()
        .map(|seed| {
            let p = d.path().join(format!("rail{seed}.mcap"));
            simulate(
                &["--scenario", "default", "--duration", "600", "--seed", seed],
                &p,
            );
            p
        })
        .collect();
    let truth: TrackMap = messages(&logs[0], "/track/map").remove(0);
    let line = d.path().join("line.geojson");
    let report = ok_json(&["track", s(&logs[0]), s(&logs[1]), "-o", s(&line), "--json"]);
    assert_eq!(report["profile"]["outcome"], "fitted", "{report}");
    let steepest = report["profile"]["steepest_gradient"].as_f64().unwrap();
    assert!((0.035..0.045).contains(&steepest.abs()), "{steepest}");
    let fitted = read_track_file(&line).unwrap();
    let gaps = stretches(&report["gaps"]);
    let mut errors = Vec::new();
    for v in &fitted.vertices {
        if gaps
            .iter()
            .any(|&(a, b)| (a - 50.0..=b + 50.0).contains(&v.chainage_m))
        {
            continue;
        }
        let (lat, lon, alt) = fitted
            .origin
            .to_geodetic(v.east_m, v.north_m, v.height_m.unwrap());
        let (te, tn, tu) = truth.origin.to_enu(lat, lon, alt);
        let m = nearest_on(&truth.vertices, 0..truth.vertices.len(), te, tn).unwrap();
        if m.lateral_m.abs() < 1.0 && !m.beyond_end {
            errors.push(tu - truth.height_at(m.chainage_m));
        }
    }
    assert!(errors.len() > 500, "{} vertices compared", errors.len());
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    assert!(
        rms < 0.10,
        "height RMS {rms:.3} m over {} vertices",
        errors.len()
    );
}
