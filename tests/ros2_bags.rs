//! Re-fusing a ROS 2 bag: a simulated seed001 run rewritten by rosbags (a library not written
//! here) as `ros2 bag record` would log the same sensors (NavSatFix, Imu, a radar's
//! TwistWithCovarianceStamped), refused with samples/seed001.toml with only the topics
//! changed, a role added and the track named: the same accuracy as on the native log. And a
//! Foxglove log's `foxglove.LocationFix` (JSON, and protobuf with the file's own descriptors,
//! written by the official Python writers) feeding the GNSS sensor of the same config.

mod common;

use std::path::Path;

use common::*;
use railfuse_catalog::messages::{FusedState, GroundTruth, RadarSpeed};

/// A simulated seed001 run of `secs` seconds in `dir`.
fn seed001(dir: &Path, secs: u32) -> std::path::PathBuf {
    let native = dir.join("seed001.mcap");
    let secs = secs.to_string();
    let args = [
        "simulate",
        "--scenario",
        "seed001",
        "--seed",
        "1",
        "--duration",
        &secs,
    ];
    ok(&[&args[..], &["-o", s(&native)]].concat());
    native
}

/// The bag and its track written from `native` into `dir` (`storage`: none for MCAP, or
/// `sqlite3`); the ROS topics' counts.
fn ros2_bag_in(native: &Path, dir: &Path, storage: &[&str]) -> serde_json::Value {
    let py = python("ros2_bag.py", &[&[s(native), s(dir)][..], storage].concat());
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    serde_json::from_slice(&py.stdout).unwrap()
}

fn ros2_bag(native: &Path, dir: &Path) -> serde_json::Value {
    ros2_bag_in(native, dir, &[])
}

/// samples/seed001.toml for the bag's topics: `/fix` for the GNSS position and, since ROS
/// sends a receiver's velocity on a topic of its own, a sensor table for `/fix_velocity`
/// beside it with the GNSS speed's variance; `/radar` (a radar's twist); the track from
/// `line.geojson` beside it. `edit` changes the text further.
fn bag_config(dir: &Path, edit: impl Fn(String) -> String) -> std::path::PathBuf {
    let text = std::fs::read_to_string(sample("seed001.toml")).unwrap();
    let mut out = String::new();
    for (k, block) in text.split("[[pipeline.sensor]]").enumerate() {
        if k > 0 {
            out += "[[pipeline.sensor]]";
        }
        let Some(rest) = block.strip_prefix("\ntopic = \"/gnss/fix\"") else {
            out += block;
            continue;
        };
        // The same table for the position, and its speed from the velocity topic.
        let speed_only: String = rest
            .replace("chainage = \"message\", ", "")
            .lines()
            .filter(|l| !l.starts_with("chainage_bias"))
            .map(|l| format!("{l}\n"))
            .collect();
        out += &format!("\ntopic = \"/fix\"\nfields = [\"chainage\"]{rest}");
        out += "[[pipeline.sensor]]\ntopic = \"/fix_velocity\"\nrole = \"gnss\"\n";
        out += &format!("fields = [\"speed\"]{speed_only}");
    }
    let text = out.replace(
        "topic = \"/radar/speed\"",
        "topic = \"/radar\"\nrole = \"radar\"",
    );
    let path = dir.join("ros.toml");
    std::fs::write(&path, edit(format!("track = \"line.geojson\"\n{text}"))).unwrap();
    path
}

/// Max |position error| and max |speed error| of each pipeline's states against the truth.
fn worst_errors(fused: &Path, truth: &[GroundTruth], names: &[&str]) -> Vec<(f64, f64)> {
    names
        .iter()
        .map(|name| {
            let states: Vec<FusedState> = messages(fused, &format!("/fused/{name}/state"));
            assert!(states.len() > 1000, "{name}: {} states", states.len());
            states.iter().fold((0.0f64, 0.0f64), |(p, v), st| {
                let g = truth_at(truth, st.stamp_ns);
                (
                    p.max((st.chainage_m - g.chainage_m).abs()),
                    v.max((st.speed_mps - g.speed_mps).abs()),
                )
            })
        })
        .collect()
}

#[test]
fn a_ros2_bag_of_the_same_sensors_refuses_as_well_as_the_native_log() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 300);
    let counts = ros2_bag(&native, d.path());
    let bag = d.path().join("bag/bag.mcap");
    let info =
        stderr(&ok(&["info", s(&bag)])) + &String::from_utf8_lossy(&ok(&["info", s(&bag)]).stdout);
    assert!(info.contains("sensor_msgs/msg/NavSatFix"), "{info}");

    let config = bag_config(d.path(), |t| t);
    let (fused_native, fused_bag) = (
        d.path().join("native.fused.mcap"),
        d.path().join("bag.fused.mcap"),
    );
    refuse(&native, "seed001.toml", &fused_native);
    let out = ok(&[
        "refuse",
        s(&bag),
        "-c",
        s(&config),
        "-o",
        s(&fused_bag),
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let inputs = counts
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum::<u64>();
    assert_eq!(
        report["refuse"]["input_messages"].as_u64(),
        Some(inputs),
        "{report}"
    );

    ros_twins_match_the_states(&fused_bag);
    the_viewer_shows_at_least_rerun_s_own_rows(&fused_bag, &bag, d.path());
    bag_as_accurate_as_native(&native, &fused_native, &fused_bag);
}

#[test]
fn a_bag_needs_its_radars_role_and_a_track_each_said_in_one_line() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 30);
    ros2_bag(&native, d.path());
    let bag = d.path().join("bag/bag.mcap");
    let out = d.path().join("x.mcap");
    for (edit, says) in [
        (
            Box::new(|t: String| t.replace("role = \"radar\"\n", ""))
                as Box<dyn Fn(String) -> String>,
            "role = \"radar\"",
        ),
        (
            Box::new(|t: String| t.replace("track = \"line.geojson\"\n", "")),
            "track = \"line.geojson\"",
        ),
        (
            Box::new(|t: String| t.replace("role = \"radar\"", "role = \"imu\"")),
            "not Imu",
        ),
    ] {
        let config = bag_config(d.path(), edit);
        let o = railfuse(&["refuse", s(&bag), "-c", s(&config), "-o", s(&out)]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{err}");
        assert_eq!(
            err.lines().filter(|l| l.contains("error")).count(),
            1,
            "{err}"
        );
        assert!(err.contains(says), "{err}");
    }
}

/// A Foxglove log of the seed001 run in `dir` (`args`: none for JSON, `--protobuf`), refused
/// with samples/seed001.toml bound to `/gps`: the log, the fused log, the refuse run and how
/// many LocationFix messages the writer wrote.
fn foxglove_refused(
    dir: &Path,
    native: &Path,
    args: &[&str],
) -> (
    std::path::PathBuf,
    std::path::PathBuf,
    std::process::Output,
    u64,
) {
    let name = args.first().map_or("json", |a| a.trim_start_matches('-'));
    let log = dir.join(format!("foxglove-{name}.mcap"));
    let py = python(
        "foxglove_log.py",
        &[&[s(native), s(&log)][..], args].concat(),
    );
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let written: serde_json::Value = serde_json::from_slice(&py.stdout).unwrap();
    let text = std::fs::read_to_string(sample("seed001.toml")).unwrap();
    let config = dir.join("foxglove.toml");
    std::fs::write(
        &config,
        text.replace("topic = \"/gnss/fix\"", "topic = \"/gps\""),
    )
    .unwrap();
    let fused = dir.join(format!("foxglove-{name}.fused.mcap"));
    let run = railfuse(&["refuse", s(&log), "-c", s(&config), "-o", s(&fused)]);
    (log, fused, run, written["location_fixes"].as_u64().unwrap())
}

/// Fixes from `/gps` that reached the filter as GNSS chainage measurements: one diagnostics
/// record per measurement, the chainage with a value (a LocationFix has no speed).
fn chainage_from_gps(fused: &Path) -> u64 {
    let diagnostics: Vec<railfuse_catalog::messages::FusedDiagnostics> =
        messages(fused, "/fused/kf/diagnostics");
    diagnostics
        .iter()
        .filter(|d| d.source == "/gps" && d.measurement.is_some())
        .count() as u64
}

#[test]
fn a_foxglove_logs_location_fixes_feed_the_gnss_sensor_in_json_and_protobuf() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 60);
    for args in [&[][..], &["--protobuf"]] {
        let (_, fused, run, written) = foxglove_refused(d.path(), &native, args);
        assert!(run.status.success(), "{args:?}: {}", stderr(&run));
        // Every LocationFix reached the filter as a GNSS chainage measurement.
        assert_eq!(chainage_from_gps(&fused), written, "{args:?}");
        // The viewer draws them on the map, beside the fused track.
        let rrd = d.path().join("foxglove.rrd");
        let viz: serde_json::Value = ok_json(&["viz", s(&fused), "--save", s(&rrd), "--json"]);
        let entities = viz["entities"].as_array().unwrap();
        assert!(
            entities.iter().any(|e| e == "map/gnss/single"),
            "{args:?}: {viz}"
        );
        assert!(viz["not_shown"].get("/gps").is_none(), "{args:?}: {viz}");
    }
}

#[test]
fn a_protobuf_schema_that_does_not_parse_rejects_its_messages_in_one_line_and_loses_nothing_else() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 30);
    let (_, fused, run, written) =
        foxglove_refused(d.path(), &native, &["--protobuf", "--bad-schema"]);
    let err = stderr(&run);
    assert!(run.status.success(), "{err}");
    let warning: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("did not decode"))
        .collect();
    assert_eq!(warning.len(), 1, "{err}");
    assert!(
        warning[0].contains(&format!("warning: {written} sensor messages"))
            && warning[0].contains("/gps: log time")
            && warning[0].contains("does not parse as a FileDescriptorSet"),
        "{err}"
    );
    // The other sensors fused as before: IMU and radar measurements all reached the filter.
    assert_eq!(chainage_from_gps(&fused), 0);
    let diagnostics: Vec<railfuse_catalog::messages::FusedDiagnostics> =
        messages(&fused, "/fused/kf/diagnostics");
    assert!(diagnostics.iter().any(|d| d.source == "/radar/speed"));
    let copied: Vec<RadarSpeed> = messages(&fused, "/radar/speed");
    let original: Vec<RadarSpeed> = messages(&native, "/radar/speed");
    assert_eq!(copied.len(), original.len());
}

#[test]
fn a_sqlite3_bag_imports_to_mcap_keeping_topics_types_qos_and_times_and_refuses_the_same() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 60);
    let counts = ros2_bag(&native, d.path());
    assert_eq!(ros2_bag_in(&native, d.path(), &["sqlite3"]), counts);
    let imported = d.path().join("imported.mcap");
    let sqlite = d.path().join("bag-sqlite3");
    let r: serde_json::Value = ok_json(&[
        "import",
        "--format",
        "rosbag2",
        s(&sqlite),
        "-o",
        s(&imported),
        "--json",
    ]);
    assert_eq!(&r["per_topic"], &counts, "{r}");
    // Topics, types, encodings, QoS and times as rosbags' own MCAP storage has them.
    let bag = d.path().join("bag/bag.mcap");
    let channels = |p: &Path| {
        let mut c: Vec<_> = railfuse_catalog::log::read_channels(p)
            .unwrap()
            .unwrap()
            .iter()
            .map(|c| {
                let qos = c.metadata.get("offered_qos_profiles").cloned();
                let schema = c.schema_name().to_owned();
                (c.topic.clone(), schema, c.message_encoding.clone(), qos)
            })
            .collect();
        c.sort();
        c
    };
    assert_eq!(channels(&imported), channels(&bag));
    let times = |p: &Path| {
        let mut t = Vec::new();
        let mut r = railfuse_catalog::log::LogReader::open(p).unwrap();
        while let Some(rec) = r.next() {
            if let railfuse_catalog::log::LogRecord::Message(m) = rec.unwrap() {
                t.push((m.channel.topic.clone(), m.log_time_ns));
            }
        }
        t.sort();
        t
    };
    assert_eq!(times(&imported), times(&bag));
    // And it refuses exactly as the MCAP bag does.
    let config = bag_config(d.path(), |t| t);
    let (a, b) = (d.path().join("a.mcap"), d.path().join("b.mcap"));
    ok(&["refuse", s(&bag), "-c", s(&config), "-o", s(&a)]);
    ok(&["refuse", s(&imported), "-c", s(&config), "-o", s(&b)]);
    let states = |p: &Path| messages::<FusedState>(p, "/fused/kf_cal/state");
    assert_eq!(states(&a), states(&b));
    // The sqlite3 bag directory is a run as it is: read in place, it refuses the same.
    let c = d.path().join("c.mcap");
    ok(&["refuse", s(&sqlite), "-c", s(&config), "-o", s(&c)]);
    assert_eq!(states(&a), states(&c));
    let info = ok_json(&["info", s(&sqlite), "--json"]);
    assert_eq!(info["messages"], r["messages"], "{info}");
}

#[test]
fn a_csv_track_of_latitude_and_longitude_serves_as_the_geojson_one_does() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 30);
    ros2_bag(&native, d.path());
    // The same line as a CSV table: one vertex a row.
    let geojson: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("line.geojson")).unwrap())
            .unwrap();
    let line = &geojson["features"][0];
    let mut csv = "latitude,longitude,altitude_m,chainage_m\n".to_owned();
    for (p, c) in line["geometry"]["coordinates"]
        .as_array()
        .unwrap()
        .iter()
        .zip(line["properties"]["chainage_m"].as_array().unwrap())
    {
        csv += &format!("{},{},{},{}\n", p[1], p[0], p[2], c);
    }
    std::fs::write(d.path().join("line.csv"), csv).unwrap();
    let bag = d.path().join("bag/bag.mcap");
    let (a, b) = (d.path().join("a.mcap"), d.path().join("b.mcap"));
    ok(&[
        "refuse",
        s(&bag),
        "-c",
        s(&bag_config(d.path(), |t| t)),
        "-o",
        s(&a),
    ]);
    let csv_config = bag_config(d.path(), |t| t.replace("line.geojson", "line.csv"));
    ok(&["refuse", s(&bag), "-c", s(&csv_config), "-o", s(&b)]);
    let states = |p: &Path| messages::<FusedState>(p, "/fused/kf/state");
    assert_eq!(states(&a), states(&b));
    // A table without the columns: one line that says which it has.
    std::fs::write(d.path().join("line.csv"), "x,y\n1,2\n3,4\n").unwrap();
    let o = railfuse(&["refuse", s(&bag), "-c", s(&csv_config), "-o", s(&b)]);
    let err = stderr(&o);
    assert!(
        !o.status.success() && err.contains("latitude and longitude columns (it has x, y)"),
        "{err}"
    );
}

#[test]
fn a_bag_without_a_config_refuses_with_a_default_pipeline_that_says_what_it_used_and_left_out() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 120);
    ros2_bag_in(&native, d.path(), &["--hostile"]);
    let bag = d.path().join("bag/bag.mcap");
    let out = d.path().join("default.mcap");
    // Without a track, the fixes cannot give chainage: said, and the rest still runs.
    let o = ok(&["refuse", s(&bag), "-o", s(&out)]);
    let err = stderr(&o);
    assert!(
        err.lines().any(|l| l.starts_with("  leaves out /fix: ")
            && l.contains("sensor_msgs/msg/NavSatFix")
            && l.contains("--track")),
        "{err}"
    );
    // With the bag's track, every sensor topic is used, each with what it gives; the topic
    // of a type railfuse does not read is left out with its type.
    let saved = d.path().join("default.toml");
    let line = d.path().join("line.geojson");
    let o = ok(&[
        "refuse",
        s(&bag),
        "-o",
        s(&out),
        "--track",
        s(&line),
        "--save-config",
        s(&saved),
    ]);
    let err = stderr(&o);
    for (topic, says) in [
        ("/fix", "GNSS fixes, their chainage on the track"),
        ("/fix_velocity", "a GNSS receiver's velocity"),
        ("/imu", "the IMU's acceleration"),
        (
            "/radar",
            "a Doppler radar's speed, its role from the topic's name",
        ),
    ] {
        assert!(
            err.lines()
                .any(|l| l.starts_with(&format!("  uses {topic}: ")) && l.contains(says)),
            "{topic}: {err}"
        );
    }
    assert!(
        err.lines().any(|l| l.starts_with(
            "  leaves out /notes: std_msgs/msg/String (cdr): no sensor model reads it"
        )),
        "{err}"
    );
    the_viewer_draws_the_track_under_the_fixes(&out, d.path());
    // What it ran is what it saved: the saved file refuses to the same states.
    let again = d.path().join("again.mcap");
    ok(&["refuse", s(&bag), "-c", s(&saved), "-o", s(&again)]);
    let (a, b): (Vec<FusedState>, Vec<FusedState>) = (
        messages(&out, "/fused/default/state"),
        messages(&again, "/fused/default/state"),
    );
    assert_eq!(a, b);
    // A first look, not a tuned pipeline, and still a train's position: within metres of
    // the truth over the run.
    let truth: Vec<GroundTruth> = messages(&native, "/truth");
    let worst = worst_errors(&out, &truth, &["default"])[0];
    println!(
        "default pipeline on the bag: max |position error| {:.3} m, max |speed error| {:.3} m/s",
        worst.0, worst.1
    );
    assert!(worst.0 < 10.0 && worst.1 < 1.0, "{worst:?}");
    // A bag has no truth: its own receiver's NavSatFix (no speed) is the reference, each fix
    // met by the states interpolated to its time, the speed columns empty with the reason.
    let r: serde_json::Value =
        serde_json::from_slice(&ok(&["eval", s(&out), "--reference", "/fix", "--json"]).stdout)
            .unwrap();
    let p = &r["pipelines"][0];
    let f = &p["reference_fixes"];
    assert!(f["matched"].as_u64().unwrap() > 500, "{p}");
    assert!(p["speed_error_mps"].is_null(), "{p}");
    assert!(
        p["position_error_m"]["rmse"].as_f64().unwrap() < 10.0,
        "{p}"
    );
    let text = String::from_utf8(ok(&["eval", s(&out), "--reference", "/fix"]).stdout).unwrap();
    assert!(
        text.contains("speed not scored: the reference carries no speed"),
        "{text}"
    );
}

#[test]
fn bad_messages_in_a_bag_are_each_said_in_one_line_and_nothing_else_is_lost() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 120);
    let counts = ros2_bag_in(&native, d.path(), &["--hostile"]);
    let bag = d.path().join("bag/bag.mcap");
    let config = bag_config(d.path(), |t| t);
    let out = d.path().join("out.mcap");
    let o = ok(&["refuse", s(&bag), "-c", s(&config), "-o", s(&out)]);
    let err = stderr(&o);
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 2, "{err}");
    let (cut, nan) = (
        counts["truncated"].as_u64().unwrap(),
        counts["nan"].as_u64().unwrap(),
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains(&format!("warning: {cut} sensor messages"))
                && w.contains("/fix: log time")
                && w.contains("CDR payload does not decode as sensor_msgs/msg/NavSatFix")),
        "{err}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains(&format!("warning: {nan} sensor messages"))
                && w.contains("/fix: log time")
                && w.contains("(NaN, ")
                && w.contains("is not on the globe")),
        "{err}"
    );
    // Every input record is in the output, the bad ones and the unread topic too.
    for topic in ["/fix", "/notes", "/radar", "/imu"] {
        let n = railfuse_catalog::inspect::summarise(&railfuse_catalog::run::Run::file(&out))
            .unwrap()
            .channels
            .iter()
            .find(|c| c.topic == topic)
            .map(|c| c.messages);
        assert_eq!(n, counts[topic].as_u64(), "{topic}");
    }
    // Every good fix reached the filter; the bad ones did not.
    let diagnostics: Vec<railfuse_catalog::messages::FusedDiagnostics> =
        messages(&out, "/fused/kf/diagnostics");
    let fixes = diagnostics
        .iter()
        .filter(|d| d.source == "/fix" && d.measurement.is_some())
        .count() as u64;
    let no_fix = counts["/fix"].as_u64().unwrap() - cut - nan;
    assert!(fixes <= no_fix, "{fixes} of {no_fix}");
    // And a sensor bound to the topic of an unknown type is refused in one line, naming
    // the topic, its type and what would fit.
    let config = bag_config(d.path(), |t| {
        t.replace("topic = \"/radar\"", "topic = \"/notes\"")
    });
    let o = railfuse(&["refuse", s(&bag), "-c", s(&config), "-o", s(&out)]);
    let err = stderr(&o);
    assert!(!o.status.success());
    let errors: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(
        errors[0].contains("/notes")
            && errors[0].contains("std_msgs/msg/String")
            && errors[0].contains("TwistWithCovarianceStamped"),
        "{err}"
    );
}

/// The fused state for ROS tools, read by the official ROS 2 decoder for MCAP: as many as
/// the pipeline's states, stamped as they are, on the track and at their speed.
fn ros_twins_match_the_states(fused_bag: &Path) {
    let states: Vec<FusedState> = messages(fused_bag, "/fused/kf/state");
    let ros = python_ok("check_ros2_outputs.py", &[s(fused_bag), "kf"]);
    let (fix, odom) = (&ros["/fused/kf/navsatfix"], &ros["/fused/kf/odometry"]);
    assert_eq!(fix["count"].as_u64(), Some(states.len() as u64), "{ros}");
    assert_eq!(odom["count"].as_u64(), Some(states.len() as u64), "{ros}");
    let last = states.last().unwrap();
    assert_eq!(
        odom["last"]["stamp_ns"].as_u64(),
        Some(last.stamp_ns),
        "{ros}"
    );
    assert!((odom["last"]["speed"].as_f64().unwrap() - last.speed_mps).abs() < 1e-9);
    assert!((odom["last"]["speed_variance"].as_f64().unwrap() - last.covariance[4]).abs() < 1e-12);
    let along = fix["last"]["covariance"][0].as_f64().unwrap()
        + fix["last"]["covariance"][4].as_f64().unwrap();
    assert!(
        (along - last.covariance[0]).abs() < 1e-6 * last.covariance[0].max(1.0),
        "{ros}"
    );
    assert!(
        fix["last"]["latitude"].as_f64().unwrap().abs() <= 90.0,
        "{ros}"
    );
}

/// The viewer draws the bag's sensors, with the fused results beside them: at least as many
/// rows as Rerun's own MCAP loader logs of the bag alone.
fn the_viewer_shows_at_least_rerun_s_own_rows(fused_bag: &Path, bag: &Path, dir: &Path) {
    let rrd = dir.join("bag.rrd");
    let viz: serde_json::Value = ok_json(&["viz", s(fused_bag), "--save", s(&rrd), "--json"]);
    let entities = viz["entities"].as_array().unwrap();
    for shown in ["map/gnss/", "speed/radar", "map/fused/kf/position"] {
        assert!(
            entities
                .iter()
                .any(|e| e.as_str().is_some_and(|e| e.starts_with(shown))),
            "{shown}: {viz}"
        );
    }
    assert!(rerun(&["rrd", "verify", s(&rrd)]).status.success());
    let own = dir.join("rerun-own.rrd");
    assert!(rerun(&["mcap", "convert", s(bag), "-o", s(&own)])
        .status
        .success());
    let stats = String::from_utf8_lossy(&rerun(&["rrd", "stats", s(&own)]).stdout).into_owned();
    let rows: u64 = stats
        .lines()
        .find_map(|l| l.strip_prefix("num_rows = "))
        .map(|n| n.chars().filter(char::is_ascii_digit).collect::<String>())
        .map(|n| n.parse().unwrap())
        .unwrap_or_else(|| panic!("{stats}"));
    assert!(
        viz["rows"].as_u64().unwrap() >= rows,
        "{viz} against Rerun's {rows}"
    );
}

/// Each pipeline's worst position and speed errors from the bag within 5 % of the native
/// log's.
fn bag_as_accurate_as_native(native: &Path, fused_native: &Path, fused_bag: &Path) {
    let truth: Vec<GroundTruth> = messages(native, "/truth");
    let names = ["fkf", "kf", "fkf_cal", "kf_cal"];
    let (a, b) = (
        worst_errors(fused_native, &truth, &names),
        worst_errors(fused_bag, &truth, &names),
    );
    let mut table =
        vec!["pipeline | native max |pos| m | bag | native max |speed| m/s | bag".to_owned()];
    for ((name, n), r) in names.iter().zip(&a).zip(&b) {
        table.push(format!(
            "{name} | {:.3} | {:.3} | {:.4} | {:.4}",
            n.0, r.0, n.1, r.1
        ));
    }
    println!("{}", table.join("\n"));
    for ((name, n), r) in names.iter().zip(&a).zip(&b) {
        assert!(
            r.0 <= 1.05 * n.0 + 0.01,
            "{name}: position {r:?} against {n:?}\n{}",
            table.join("\n")
        );
        assert!(
            r.1 <= 1.05 * n.1 + 0.005,
            "{name}: speed {r:?} against {n:?}\n{}",
            table.join("\n")
        );
    }
}

/// The output carries the track it was fused on, so the viewer draws it under the fixes; the
/// topic no sensor model reads is said to be not shown.
fn the_viewer_draws_the_track_under_the_fixes(out: &Path, dir: &Path) {
    let maps: Vec<railfuse_catalog::messages::TrackMap> = messages(out, "/track/map");
    assert_eq!(maps.len(), 1);
    let rrd = dir.join("default.rrd");
    let viz: serde_json::Value = ok_json(&["viz", s(out), "--save", s(&rrd), "--json"]);
    let entities = viz["entities"].as_array().unwrap();
    for shown in [
        "map/track",
        "map/gnss/single",
        "map/fused/default/position",
        "speed/radar",
    ] {
        assert!(entities.iter().any(|e| e == shown), "{shown}: {viz}");
    }
    assert!(viz["not_shown"].get("/notes").is_some(), "{viz}");
}

/// (topic, log time, payload) of every fused record of a log, in file order.
fn fused_records(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let mut out = Vec::new();
    let mut r = railfuse_catalog::log::LogReader::open(path).unwrap();
    while let Some(rec) = r.next() {
        if let railfuse_catalog::log::LogRecord::Message(m) = rec.unwrap() {
            if m.channel.topic.contains("/fused/") {
                out.push((m.channel.topic.clone(), m.log_time_ns, m.data.to_vec()));
            }
        }
    }
    out
}

#[test]
fn a_bag_split_in_four_files_by_rosbags_is_one_run() {
    let d = tempfile::tempdir().unwrap();
    let native = seed001(d.path(), 120);
    ros2_bag(&native, d.path());
    let (bag, split) = (d.path().join("bag"), d.path().join("split"));
    // rosbags' own Reader reads the split bag back whole: it is a bag as rosbag2 writes them.
    let py = python_ok("split_bag.py", &[s(&bag), s(&split), "30,61.5,90"]);
    assert_eq!(py["files"].as_array().unwrap().len(), 4, "{py}");
    let info = String::from_utf8(ok(&["info", s(&split)]).stdout).unwrap();
    for f in ["split_0.mcap", "split_3.mcap"] {
        assert!(info.contains(f), "{info}");
    }
    let whole = ok_json(&["info", s(&bag), "--json"]);
    assert_eq!(whole["messages"], py["messages"]);
    let config = bag_config(d.path(), |t| t);
    let (a, b) = (
        d.path().join("whole.fused.mcap"),
        d.path().join("split.fused.mcap"),
    );
    ok(&["refuse", s(&bag), "-c", s(&config), "-o", s(&a)]);
    let report = ok_json(&["refuse", s(&split), "-c", s(&config), "-o", s(&b), "--json"]);
    assert_eq!(report["refuse"]["merge"]["parts_read"], 4, "{report}");
    let (fa, fb) = (fused_records(&a), fused_records(&b));
    assert!(
        fa.len() > 1000 && fa == fb,
        "{} vs {} fused records",
        fa.len(),
        fb.len()
    );
}
