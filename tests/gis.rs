//! GPX in and GIS files out, checked by the ecosystem's own libraries: a ride gpxpy wrote is
//! read point for point as gpxpy reads it, by `import` and by every command that takes a run;
//! a fused run's export is read back by gpxpy, fastkml, the geojson package and pandas.

mod common;

use std::path::Path;

use common::*;
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::{FixType, GnssFix};
use railfuse_catalog::run::{Run, RunOptions};

/// Every /gnss/fix of a run (of any format the run reader takes).
fn fixes(path: &Path, options: &RunOptions) -> Vec<GnssFix> {
    let run = Run::open(&[path.to_owned()], options).unwrap();
    let mut reader = run.reader().unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        if let LogRecord::Message(m) = r.unwrap() {
            if m.channel.topic == "/gnss/fix" {
                out.push(m.decode(path).unwrap());
            }
        }
    }
    out
}

#[test]
fn a_ride_gpxpy_wrote_reads_point_for_point_as_gpxpy_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let gpx = dir.path().join("ride.gpx");
    let theirs = python_ok("gpx_gis.py", &["ride", s(&gpx)]);
    assert_eq!(theirs["version"], "1.0");
    let points = theirs["points"].as_array().unwrap();
    let timed: Vec<&serde_json::Value> =
        points.iter().filter(|p| !p["time_ns"].is_null()).collect();
    assert_eq!((points.len(), timed.len()), (120, 119));

    // The run reader reads the GPX itself: every timed point, in order, as gpxpy has it.
    let ours = fixes(&gpx, &RunOptions::default());
    assert_eq!(ours.len(), timed.len());
    for (f, p) in ours.iter().zip(&timed) {
        assert_eq!(f.stamp_ns as i64, p["time_ns"].as_i64().unwrap());
        assert_eq!(f.latitude_deg, p["lat"].as_f64());
        assert_eq!(f.longitude_deg, p["lon"].as_f64());
        assert_eq!(f.altitude_msl_m, p["ele"].as_f64());
        assert_eq!(f.speed_mps, p["speed"].as_f64());
        let course = p["course"].as_f64().unwrap().to_radians();
        assert!((f.course_rad.unwrap() - course).abs() < 1e-12);
        assert_eq!(f.hdop, p["hdop"].as_f64());
        assert_eq!(f.satellites as u64, p["sat"].as_u64().unwrap());
        let want = match p["fix"].as_str().unwrap() {
            "dgps" => FixType::Dgps,
            _ => FixType::Single,
        };
        assert_eq!(f.fix_type, want);
        assert_eq!(f.position_covariance_enu_m2, None);
    }

    // import writes the same conversion, and says what it did not use.
    let mcap = dir.path().join("ride.mcap");
    let report = ok_json(&["import", s(&gpx), "-o", s(&mcap), "--json"]);
    assert_eq!(report["format"], "GPX");
    assert_eq!(report["messages"], 119);
    assert_eq!(report["skipped"]["a point without <time>"], 1);
    assert_eq!(report["warnings"]["segment breaks (gaps in the track)"], 2);
    assert_eq!(fixes(&mcap, &RunOptions::default()), ours);

    // Any command takes it as a run: info names the channel and the conversion.
    let info = ok(&["info", s(&gpx)]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("/gnss/fix"), "{text}");
    assert!(
        stderr(&info).contains("120 records read, 119 messages, 2 segment breaks"),
        "{}",
        stderr(&info)
    );

    // A phone's hdop in metres: the option makes it each fix's σ (a 68 % radius).
    let metres = ok_json(&[
        "import",
        s(&gpx),
        "-o",
        s(&dir.path().join("m.mcap")),
        "--json",
        "--gpx-hdop",
        "metres",
    ]);
    assert_eq!(metres["messages"], 119);
    let options = RunOptions {
        formats: railfuse_catalog::formats::FormatOptions {
            gpx: railfuse_catalog::formats::gpx::GpxOptions {
                hdop: "metres".parse().unwrap(),
                ..Default::default()
            },
            ..Default::default()
        },
        ..Default::default()
    };
    let m = fixes(&gpx, &options);
    let sigma = m[0].position_covariance_enu_m2.unwrap()[0].sqrt();
    assert!(
        (sigma - 0.8 / (-2.0 * 0.32f64.ln()).sqrt()).abs() < 1e-9,
        "{sigma}"
    );
}

#[test]
fn bad_gpx_is_one_line_and_a_cut_off_one_keeps_its_points() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let kml = write(
        "not.gpx",
        "<?xml version=\"1.0\"?>\n<kml><Document/></kml>\n",
    );
    assert!(fails(&["info", s(&kml)]).contains("not.gpx: line 2: the document is <kml>, not <gpx>"));
    let bomb = write(
        "bomb.gpx",
        "<?xml version=\"1.0\"?>\n<!DOCTYPE gpx [<!ENTITY a \"aaaaaaaaaa\"><!ENTITY b \"&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;\"><!ENTITY c \"&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;\">]>\n<gpx><trk><name>&c;</name></trk></gpx>\n",
    );
    assert!(fails(&["info", s(&bomb)]).contains("declares entities"));
    let untimed = write(
        "untimed.gpx",
        "<gpx version=\"1.1\"><trk><trkseg><trkpt lat=\"1\" lon=\"2\"/><trkpt lat=\"1.1\" lon=\"2\"/></trkseg></trk></gpx>",
    );
    let e = fails(&["import", s(&untimed), "-o", s(&dir.path().join("u.mcap"))]);
    assert!(
        e.contains("none of its 2 points is a fix: 2 a point without <time>"),
        "{e}"
    );
    assert!(!dir.path().join("u.mcap").exists());
    let backwards = write(
        "backwards.gpx",
        "<gpx><trk><trkseg><trkpt lat=\"1\" lon=\"2\"><time>2021-01-01T00:00:02Z</time></trkpt>\
         <trkpt lat=\"1\" lon=\"2\"><time>2021-01-01T00:00:01Z</time></trkpt>\
         <trkpt lat=\"1\" lon=\"2\"><time>2021-01-01T00:00:02Z</time></trkpt>\
         <trkpt lat=\"1\" lon=\"2\"><time>2021-01-01T00:00:03Z</time></trkpt></trkseg></trk></gpx>",
    );
    let r = ok_json(&[
        "import",
        s(&backwards),
        "-o",
        s(&dir.path().join("b.mcap")),
        "--json",
    ]);
    assert_eq!(r["messages"], 2);
    assert_eq!(r["skipped"]["a point earlier than the one before"], 1);
    assert_eq!(r["skipped"]["a point at the time of the one before"], 1);
    let mut cut = String::from("<gpx><trk><trkseg>\n");
    for k in 0..10 {
        cut.push_str(&format!(
            "<trkpt lat=\"1\" lon=\"2\"><time>2021-01-01T00:00:{k:02}Z</time></trkpt>\n"
        ));
    }
    cut.push_str("<trkpt lat=\"1\" lon=\"2\"><ti");
    let cut = write("cut.gpx", &cut);
    let info = ok(&["info", s(&cut)]);
    let err = stderr(&info);
    assert!(
        err.contains("warning: ")
            && err.contains("cut.gpx: line 12")
            && err.contains("the 10 messages before it are read"),
        "{err}"
    );
}

#[test]
fn a_fused_run_exports_to_gpx_kml_geojson_and_csv_that_their_readers_read() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("run.mcap");
    simulate(&["--duration", "60", "--seed", "3"], &raw);
    let fused = dir.path().join("run.fused.mcap");
    ok(&[
        "refuse",
        s(&raw),
        "-c",
        s(&sample("models.toml")),
        "-o",
        s(&fused),
        "--quiet",
    ]);
    let states = |p: &str| -> u64 {
        let e = ok_json(&["eval", s(&fused), "--json"]);
        e["pipelines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|q| q["name"] == p)
            .map(|q| q["states"].as_u64().unwrap())
            .unwrap()
    };
    let (cv, particle) = ("cv", "pf");
    let (n_cv, n_particle) = (states(cv), states(particle));
    assert!(n_cv > 1000, "{n_cv}");
    let mut outputs = Vec::new();
    for ending in ["gpx", "kml", "geojson", "csv"] {
        let out = dir.path().join(format!("run.{ending}"));
        let said = ok(&[
            "export",
            s(&fused),
            "-o",
            s(&out),
            "--pipeline",
            cv,
            "--pipeline",
            particle,
        ]);
        assert!(String::from_utf8_lossy(&said.stdout)
            .contains(&format!("{cv} {n_cv}, {particle} {n_particle}")));
        outputs.push(python_ok("gpx_gis.py", &["read", s(&out)]));
    }
    let [gpx, kml, geo, csv] = &outputs[..] else {
        unreachable!()
    };
    assert_eq!(gpx["tracks"][0]["name"], cv);
    assert_eq!(gpx["tracks"][0]["points"], n_cv);
    assert_eq!(gpx["tracks"][1]["points"], n_particle);
    assert!(
        gpx["tracks"][0]["extensions"]
            .to_string()
            .contains("sigma_east_m"),
        "{gpx}"
    );
    assert_eq!(kml["tracks"][1]["name"], particle);
    assert_eq!(kml["tracks"][0]["points"], n_cv);
    assert_eq!(kml["tracks"][0]["arrays"]["sigma_major_m"], n_cv);
    assert_eq!(geo["valid"], true, "{geo}");
    assert_eq!(geo["pipelines"][cv], n_cv);
    assert_eq!(csv["rows"], n_cv + n_particle);
    assert_eq!(csv["nan"], 0);
    assert!(csv["sigma_east_max"].as_f64().unwrap() > 0.0);
    // One time, one place, whichever reader.
    let t = geo["first"]["stamp_ns"].as_u64().unwrap();
    assert_eq!(
        gpx["tracks"][0]["first_time_ms"].as_u64().unwrap(),
        t / 1_000_000
    );
    // Thinned, and refused where it cannot be.
    let thin = dir.path().join("thin.csv");
    ok(&[
        "export",
        s(&fused),
        "-o",
        s(&thin),
        "--every",
        "1",
        "--pipeline",
        cv,
    ]);
    let rows = python_ok("gpx_gis.py", &["read", s(&thin)])["rows"]
        .as_f64()
        .unwrap();
    // One state a second over the pipeline's span (about 41 s of the 60 s run).
    let span = csv["span_s"].as_f64().unwrap();
    assert!(
        (rows - (span.floor() + 1.0)).abs() <= 1.0,
        "{rows} rows over {span} s"
    );
    assert!(
        fails(&["export", s(&fused), "-o", s(&dir.path().join("x.shp"))])
            .contains("name the output")
    );
    assert!(
        fails(&["export", s(&raw), "-o", s(&dir.path().join("x.csv"))])
            .contains("no /fused/<pipeline>/state channel")
    );
    assert!(fails(&[
        "export",
        s(&fused),
        "-o",
        s(&dir.path().join("y.csv")),
        "--pipeline",
        "nope"
    ])
    .contains("--pipeline nope: not in"));
}
