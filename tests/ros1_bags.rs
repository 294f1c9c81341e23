//! ROS 1 bags written by rosbags (a library not written here) as `rosbag record` would log
//! the sensors of a simulated run, uncompressed and in bz2 and lz4 chunks: read message for
//! message as rosbags reads them, by every command that takes a run; a bag whose recording did
//! not finish (no index) read by scanning; a cut-off bag keeping what came before; its
//! `/tf_static` reported; and its import, an MCAP of `ros1msg` channels, read by
//! mcap-ros1-support's decoder and refused like the bag.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use railfuse_catalog::foreign::{Role, Translated, Translator};
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::AnyMessage;
use railfuse_catalog::run::{Run, RunOptions};

/// A bag of samples/short-run.mcap's sensors in `dir`, chunks compressed as `compression`.
fn bag(dir: &Path, compression: &str) -> PathBuf {
    bag_with_tf(dir, compression, "point")
}

/// [`bag`] with the `/tf_static` variant `tf` of ros1_bag.py (`point`: every sensor frame at
/// the front end, as the data has it).
fn bag_with_tf(dir: &Path, compression: &str, tf: &str) -> PathBuf {
    let out = dir.join(format!("run-{compression}-{tf}.bag"));
    let counts = python_ok(
        "ros1_bag.py",
        &[
            "write",
            s(&sample("short-run.mcap")),
            s(&out),
            compression,
            tf,
        ],
    );
    assert_eq!(counts["/fix"], 901, "{counts}");
    out
}

/// Every message of a run as railfuse reads it: (topic, log time, translated message).
fn translated(path: &Path) -> Vec<(String, u64, Option<AnyMessage>)> {
    translated_with(path, &RunOptions::default())
}

fn translated_with(path: &Path, options: &RunOptions) -> Vec<(String, u64, Option<AnyMessage>)> {
    let run = Run::open(&[path.to_owned()], options).unwrap();
    let mut reader = run.reader().unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        let LogRecord::Message(m) = r.unwrap() else {
            continue;
        };
        let role = match m.channel.topic.as_str() {
            "/radar" => Some(Role::Radar),
            t if t.starts_with("/odom/") => Some(Role::Odometer),
            _ => None,
        };
        let message = Translator::for_channel(m.channel, role).unwrap().map(|t| {
            match t.translate(m.data, m.log_time_ns).unwrap() {
                Translated::Message { message, .. } => message,
                Translated::Skipped(why) => panic!("{why}"),
            }
        });
        out.push((m.channel.topic.clone(), m.log_time_ns, message));
    }
    out
}

/// Railfuse's reading of a bag against rosbags': the same messages per topic, in order, at
/// the same times, with the same values.
fn same_as_rosbags(path: &Path) {
    same_as_rosbags_of(path, path)
}

/// Railfuse's reading of `path` against rosbags' of `theirs` (the same bag with its index:
/// rosbags reads no bag without one).
fn same_as_rosbags_of(path: &Path, theirs: &Path) {
    let theirs = python_ok("ros1_bag.py", &["read", s(theirs)]);
    let ours = translated(path);
    for (topic, want) in theirs.as_object().unwrap() {
        let want = want.as_array().unwrap();
        let got: Vec<&(String, u64, Option<AnyMessage>)> =
            ours.iter().filter(|(t, _, _)| t == topic).collect();
        assert_eq!(got.len(), want.len(), "{topic}");
        for ((_, time, message), w) in got.iter().zip(want) {
            assert_eq!(*time, w["time_ns"].as_u64().unwrap(), "{topic}");
            let stamp = w["stamp_ns"].as_u64();
            let f = |k: &str| w[k].as_f64().unwrap();
            match message {
                Some(AnyMessage::GnssFix(m)) => {
                    assert_eq!(Some(m.stamp_ns), stamp);
                    assert_eq!(
                        (m.latitude_deg, m.longitude_deg),
                        (Some(f("latitude")), Some(f("longitude")))
                    );
                    assert_eq!(m.altitude_m, Some(f("altitude")));
                }
                Some(AnyMessage::Imu(m)) => {
                    assert_eq!(Some(m.stamp_ns), stamp);
                    assert_eq!(m.sensor_id, "imu_link");
                    for a in 0..3 {
                        assert_eq!(m.specific_force_mps2[a], w["accel"][a].as_f64().unwrap());
                        assert_eq!(m.angular_rate_radps[a], w["gyro"][a].as_f64().unwrap());
                    }
                }
                Some(AnyMessage::RadarSpeed(m)) => {
                    assert_eq!((Some(m.stamp_ns), m.speed_mps), (stamp, f("speed").abs()));
                }
                Some(AnyMessage::Odometer(m)) => {
                    assert_eq!((Some(m.stamp_ns), m.speed_mps), (stamp, f("speed")));
                }
                None => assert!(topic == "/tf_static" || topic == "/rosout_text", "{topic}"),
                Some(other) => panic!("{topic}: {other:?}"),
            }
        }
    }
    assert_eq!(ours.len(), 25_207);
}

#[test]
fn a_ros1_bag_reads_message_for_message_as_rosbags_reads_it_in_every_compression() {
    let dir = tempfile::tempdir().unwrap();
    for compression in ["none", "bz2", "lz4"] {
        same_as_rosbags(&bag(dir.path(), compression));
    }
}

#[test]
fn a_bag_without_its_index_is_scanned_and_a_cut_one_keeps_what_came_before() {
    let dir = tempfile::tempdir().unwrap();
    let full = bag(dir.path(), "lz4");
    let unindexed = dir.path().join("unindexed.bag");
    python_ok("ros1_bag.py", &["unindex", s(&full), s(&unindexed)]);
    same_as_rosbags_of(&unindexed, &full);
    let info = railfuse(&["info", s(&unindexed)]);
    assert!(
        stderr(&info).contains("no index (the recording did not finish): read by scanning"),
        "{}",
        stderr(&info)
    );

    // Cut in the middle of a chunk: the chunks before it are read, the cut said once.
    let bytes = std::fs::read(&unindexed).unwrap();
    let cut = dir.path().join("cut.bag");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = dir.path().join("cut.mcap");
    let r = ok_json(&["import", s(&cut), "-o", s(&out), "--json"]);
    let messages = r["messages"].as_u64().unwrap();
    assert!((10_000..25_207).contains(&messages), "{r}");
    let warnings = r["warnings"].to_string();
    assert!(warnings.contains("cut off"), "{warnings}");
    assert_eq!(
        ok_json(&["info", s(&out), "--json"])["messages"].as_u64(),
        Some(messages)
    );
}

#[test]
fn tf_static_is_reported_and_unknown_types_are_kept_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let bag = bag(dir.path(), "bz2");
    let info = railfuse(&["info", s(&bag)]);
    let text = format!("{}{}", String::from_utf8_lossy(&info.stdout), stderr(&info));
    assert!(
        text.contains("frame gps in base_link at (10.000, 0.000, -0.500) m"),
        "{text}"
    );
    // The train the transforms place: every sensor at its frame, the front end's frame the
    // body's origin, the rear end's giving the length.
    assert!(
        text.contains("vehicle 'from /tf_static': 20 m from front end to rear end"),
        "{text}"
    );
    assert!(
        text.contains("/odom/1    wheel1  +0.000 +0.000 +0.000"),
        "{text}"
    );
    assert!(
        text.contains("kept as they are, of types railfuse does not read: 1 std_msgs/String"),
        "{text}"
    );
    let out = dir.path().join("bag.mcap");
    let r = ok_json(&["import", s(&bag), "-o", s(&out), "--json"]);
    assert_eq!(r["frames"][2]["child"], "gps", "{r}");
    assert_eq!(r["per_topic"]["/rosout_text"], 1, "{r}");
}

#[test]
fn an_imported_bag_is_ros1msg_mcap_that_mcap_ros1_reads_and_refuses_like_the_bag() {
    let dir = tempfile::tempdir().unwrap();
    let bag = bag(dir.path(), "none");
    let out = dir.path().join("bag.mcap");
    ok(&["import", s(&bag), "-o", s(&out)]);
    let theirs = python_ok("ros1_bag.py", &["read", s(&bag)]);
    let mcap = python_ok("ros1_bag.py", &["read-mcap", s(&out)]);
    for topic in ["/fix", "/imu", "/radar", "/odom/1", "/tf_static"] {
        let (a, b) = (
            theirs[topic].as_array().unwrap(),
            mcap[topic].as_array().unwrap(),
        );
        assert_eq!(a.len(), b.len(), "{topic}");
        for (x, y) in a.iter().zip(b) {
            assert_eq!(x["time_ns"], y["time_ns"], "{topic}");
            assert_eq!(x["stamp_ns"], y["stamp_ns"], "{topic}");
            assert_eq!(x["latitude"], y["latitude"], "{topic}");
        }
    }
    assert!(mcap["/fix"][0]["type"] == "sensor_msgs/NavSatFix");
    // The MCAP's ros1msg channels read as the bag's.
    assert_eq!(translated(&bag), translated(&out));
    // And a run of either refuses to the same fused states.
    let line = dir.path().join("line.geojson");
    ok(&["track", s(&sample("short-run.mcap")), "-o", s(&line)]);
    let fused = |input: &Path, name: &str| {
        let f = dir.path().join(name);
        ok(&["refuse", s(input), "--track", s(&line), "-o", s(&f)]);
        messages::<railfuse_catalog::messages::FusedState>(&f, "/fused/default/state")
    };
    let (a, b) = (fused(&bag, "a.fused.mcap"), fused(&out, "b.fused.mcap"));
    assert!(a.len() > 800 && a == b, "{} {}", a.len(), b.len());
    // The fused log keeps the bag's channels as they were (ros1, their definitions): its
    // NavSatFix scores the fused states.
    let fused_log = dir.path().join("a.fused.mcap");
    let eval = ok_json(&[
        "eval",
        s(&fused_log),
        "--reference",
        "/fix",
        "--reference-quality",
        "all",
        "--json",
    ]);
    let scored = &eval["pipelines"][0]["position_error_m"];
    assert_eq!(scored["samples"], 901, "{eval}");
    assert!(scored["rmse"].as_f64().unwrap() < 2.0, "{eval}");
}

/// An MCAP of ROS 1 channels written by the official mcap writer (ROS 1 definitions and
/// serialisation by rosbags), as `mcap convert` makes of a bag: read as the same bag is.
#[test]
fn an_mcap_of_ros1_channels_another_tool_wrote_reads_as_the_bag() {
    let dir = tempfile::tempdir().unwrap();
    let bag = bag(dir.path(), "lz4");
    let mcap = dir.path().join("ros1.mcap");
    python_ok(
        "ros1_bag.py",
        &["write-mcap", s(&sample("short-run.mcap")), s(&mcap)],
    );
    let (ours, theirs) = (translated(&mcap), translated(&bag));
    assert_eq!(ours.len(), 25_207);
    assert_eq!(ours, theirs);
}

/// A bag recorded on a clock 1.5 s ahead: `--clock-offset` moves its log times and the
/// sensors' `header.stamp` alike (ROS 1's header, after its sequence number).
#[test]
fn a_clock_offset_moves_a_ros1_header_stamp_with_the_log_time() {
    let dir = tempfile::tempdir().unwrap();
    let bag = bag(dir.path(), "bz2");
    let offset: railfuse_catalog::run::ClockOffset = format!("{}=-1.5", s(&bag)).parse().unwrap();
    let options = RunOptions {
        clock_offsets: vec![offset],
        ..Default::default()
    };
    let fix = |v: Vec<(String, u64, Option<AnyMessage>)>| {
        v.into_iter()
            .find_map(|(t, log, m)| match (t.as_str(), m) {
                ("/fix", Some(AnyMessage::GnssFix(f))) => Some((log, f.stamp_ns)),
                _ => None,
            })
            .unwrap()
    };
    let ((log, stamp), (moved_log, moved_stamp)) =
        (fix(translated(&bag)), fix(translated_with(&bag, &options)));
    let d = |a: u64, b: u64| b as i128 - a as i128;
    assert_eq!(d(log, moved_log).abs(), 1_500_000_000);
    assert_eq!(d(stamp, moved_stamp), d(log, moved_log));
}

#[test]
fn bad_bags_say_what_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let not = dir.path().join("notes.bag");
    std::fs::write(&not, "these are not messages\n").unwrap();
    let e = fails(&["info", s(&not)]);
    assert!(
        e.contains("notes.bag") && e.contains("not a ROS 1 bag") && e.lines().count() == 1,
        "{e}"
    );
    let old = dir.path().join("old.bag");
    std::fs::write(&old, "#ROSBAG V1.2\n").unwrap();
    let e = fails(&["info", s(&old)]);
    assert!(e.contains("format 1.2: only format 2.0 is read"), "{e}");
    // A chunk whose header claims 4 GiB decompressed: counted, never allocated.
    let full = bag(dir.path(), "none");
    let mut bytes = std::fs::read(&full).unwrap();
    let at = bytes.windows(5).position(|w| w == b"size=").unwrap() + 5;
    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let lying = dir.path().join("lying.bag");
    std::fs::write(&lying, &bytes).unwrap();
    let r = ok_json(&[
        "import",
        s(&lying),
        "-o",
        s(&dir.path().join("l.mcap")),
        "--json",
    ]);
    let problems = r["first_problems"].to_string();
    assert!(problems.contains("more than 256 MiB"), "{problems}");
    assert_eq!(r["skipped"]["a chunk that does not decompress"], 1, "{r}");
}

/// The fused front end's chainage (m) at each state's time, of `input` re-fused on `line`.
fn fused_chainage(input: &Path, line: &Path, out: &Path) -> Vec<(u64, f64)> {
    ok(&["refuse", s(input), "--track", s(line), "-o", s(out)]);
    messages::<railfuse_catalog::messages::FusedState>(out, "/fused/default/state")
        .iter()
        .map(|f| (f.stamp_ns, f.chainage_m))
        .collect()
}

#[test]
fn tf_static_places_the_sensors_and_a_cycle_or_a_missing_frame_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let line = dir.path().join("line.geojson");
    ok(&["track", s(&sample("short-run.mcap")), "-o", s(&line)]);
    let point = bag_with_tf(dir.path(), "none", "point");
    let back = bag_with_tf(dir.path(), "none", "antenna_back");
    let a = fused_chainage(&point, &line, &dir.path().join("point.mcap"));
    let b = fused_chainage(&back, &line, &dir.path().join("back.mcap"));
    // The data has the antenna at the front end; a /tf_static that puts it 12 m behind moves
    // each fix 12 m forward to the front end, and the fused front end with it.
    let shifts: Vec<f64> = a
        .iter()
        .zip(&b)
        .skip(a.len() / 4)
        .map(|(x, y)| y.1 - x.1)
        .collect();
    let mean = shifts.iter().sum::<f64>() / shifts.len() as f64;
    assert!(
        (mean - 12.0).abs() < 0.5,
        "the fused front end moved {mean} m"
    );
    for (tf, says) in [
        (
            "cycle",
            "frames base_link → front_end → base_link form a cycle",
        ),
        (
            "missing",
            "topic /radar's frame 'radar' is in no transform (a missing frame)",
        ),
    ] {
        let bag = bag_with_tf(dir.path(), "none", tf);
        let out = dir.path().join(format!("{tf}.mcap"));
        let r = railfuse(&["refuse", s(&bag), "--track", s(&line), "-o", s(&out)]);
        let err = stderr(&r);
        assert!(!r.status.success() && err.contains(says), "{tf}: {err}");
        // One line says it (the others are the bag's conversion report).
        assert_eq!(
            err.lines().filter(|l| l.contains("error")).count(),
            1,
            "{err}"
        );
        assert!(!out.exists(), "{tf}: nothing is written");
    }
}
