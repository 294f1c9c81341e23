//! A run is whatever set of files holds it: a split run re-fuses to the same fused channels as
//! the whole run, byte for byte, wherever the splits fall (inside a GNSS outage, at a balise
//! passage, through eddy-current windows); and a run that cannot be read as one says why in
//! one line naming the file.

mod common;

use std::path::Path;

use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{BalisePassage, FixType, GnssFix};

/// (topic, log time, publish time, sequence, payload) of every fused record, in file order.
fn fused_records(path: &Path) -> Vec<(String, u64, u64, u32, Vec<u8>)> {
    let mut out = Vec::new();
    let mut r = LogReader::open(path).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec.unwrap() {
            if m.channel.topic.contains("/fused/") {
                out.push((
                    m.channel.topic.clone(),
                    m.log_time_ns,
                    m.publish_time_ns,
                    m.sequence,
                    m.data.to_vec(),
                ));
            }
        }
    }
    out
}

/// Re-fuses `whole` and the parts in `parts` with `config` and asserts the fused records are
/// the same; the number of parts.
fn same_fused(whole: &Path, parts: &Path, config: &str, d: &Path) -> usize {
    let (a, b) = (d.join("whole.fused.mcap"), d.join("parts.fused.mcap"));
    refuse(whole, config, &a);
    let report = ok_json(&[
        "refuse",
        s(parts),
        "-c",
        s(&sample(config)),
        "-o",
        s(&b),
        "--json",
    ]);
    let (fa, fb) = (fused_records(&a), fused_records(&b));
    assert!(fa.len() > 1000, "{} fused records", fa.len());
    assert_eq!(fa.len(), fb.len());
    for (x, y) in fa.iter().zip(&fb) {
        assert!(
            x == y,
            "first difference: {} at {} ns vs {} at {} ns",
            x.0,
            x.1,
            y.0,
            y.1
        );
    }
    assert_eq!(
        report["refuse"]["merge"]["duplicates_dropped"], 0,
        "{report}"
    );
    report["refuse"]["merge"]["parts_read"].as_u64().unwrap() as usize
}

/// Seconds from the log's first message (its first truth sample) of a sensor time.
fn secs_from_start(log: &Path, stamp_ns: u64) -> f64 {
    let t0 = ok_json(&["info", s(log), "--json"])["first_log_time_ns"]
        .as_u64()
        .unwrap();
    (stamp_ns - t0) as f64 / 1e9
}

#[test]
fn a_split_run_refuses_to_the_fused_channels_of_the_whole_run_byte_for_byte() {
    let d = tempfile::tempdir().unwrap();
    let whole = d.path().join("run.mcap");
    simulate(&["--duration", "300"], &whole);
    // Split where RTK is lost (single fixes), at a balise passage (the telegram opens the
    // next part), and at a time of no note.
    let fixes: Vec<GnssFix> = messages(&whole, "/gnss/fix");
    let single = fixes
        .windows(20)
        .find(|w| w.iter().all(|f| f.fix_type == FixType::Single))
        .expect("the default run loses RTK")[10]
        .stamp_ns;
    let balises: Vec<BalisePassage> = messages(&whole, "/balise");
    let cuts = [
        secs_from_start(&whole, single),
        secs_from_start(&whole, balises[1].stamp_ns),
        211.0,
    ];
    let mut cuts: Vec<String> = cuts.iter().map(|c| format!("{c:.6}")).collect();
    cuts.sort_by(|a, b| a.parse::<f64>().unwrap().total_cmp(&b.parse().unwrap()));
    let parts = d.path().join("parts");
    std::fs::create_dir(&parts).unwrap();
    ok(&[
        "merge",
        s(&whole),
        "-o",
        s(&parts.join("run.mcap")),
        "--split-at",
        &cuts.join(","),
    ]);
    assert_eq!(std::fs::read_dir(&parts).unwrap().count(), 4);
    assert_eq!(same_fused(&whole, &parts, "kalman.toml", d.path()), 4);
    // Fused parts beside the raw parts: split where the input's parts begin, they hold the
    // whole run's fused records between them, each in the part of its time.
    let out = d.path().join("fused-parts");
    std::fs::create_dir(&out).unwrap();
    let report = ok_json(&[
        "refuse",
        s(&parts),
        "-c",
        s(&sample("kalman.toml")),
        "-o",
        s(&out.join("run.fused.mcap")),
        "--split-as-input",
        "--json",
    ]);
    let written: Vec<String> = report["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap().to_owned())
        .collect();
    assert_eq!(written.len(), 4, "{}", report["parts"]);
    assert!(!out.join("run.fused.mcap").exists());
    let mut split_fused = Vec::new();
    for (i, part) in written.iter().enumerate() {
        let raw = parts.join(format!("run-{:03}.mcap", i + 1));
        let first_raw = ok_json(&["info", s(&raw), "--json"])["first_log_time_ns"]
            .as_u64()
            .unwrap();
        let fused = fused_records(Path::new(part));
        assert!(
            fused.iter().all(|r| r.1 >= first_raw || i == 0),
            "{part} holds fused records from before its raw part"
        );
        split_fused.extend(fused);
    }
    assert!(split_fused == fused_records(&d.path().join("whole.fused.mcap")));
    // One part alone is a log too.
    let alone = d.path().join("alone.fused.mcap");
    refuse(&parts.join("run-002.mcap"), "kalman.toml", &alone);
}

/// The middle of the longest stretch without a GNSS position.
fn middle_of_gnss_outage(log: &Path) -> u64 {
    let fixes: Vec<GnssFix> = messages(log, "/gnss/fix");
    let with: Vec<u64> = fixes
        .iter()
        .filter(|f| f.fix_type != FixType::None)
        .map(|f| f.stamp_ns)
        .collect();
    let (a, b) = with
        .windows(2)
        .map(|w| (w[0], w[1]))
        .max_by_key(|(a, b)| b - a)
        .unwrap();
    assert!(
        b - a > 10_000_000_000,
        "an outage of {} s",
        (b - a) as f64 / 1e9
    );
    a + (b - a) / 2
}

#[test]
fn a_split_inside_a_gnss_outage_is_invisible_too() {
    let d = tempfile::tempdir().unwrap();
    let whole = d.path().join("seed003.mcap");
    simulate(&["--scenario", "seed003", "--seed", "2"], &whole);
    let cut = secs_from_start(&whole, middle_of_gnss_outage(&whole));
    let parts = d.path().join("parts");
    std::fs::create_dir(&parts).unwrap();
    let at = format!("{cut:.6}");
    ok(&[
        "merge",
        s(&whole),
        "-o",
        s(&parts.join("run.mcap")),
        "--split-at",
        &at,
    ]);
    assert_eq!(same_fused(&whole, &parts, "seed003.toml", d.path()), 2);
}

#[test]
fn twenty_parts_through_eddy_current_windows_refuse_as_the_whole_run() {
    let d = tempfile::tempdir().unwrap();
    let whole = d.path().join("seed004.mcap");
    simulate(
        &["--scenario", "seed004", "--seed", "3", "--duration", "200"],
        &whole,
    );
    let parts = d.path().join("parts");
    std::fs::create_dir(&parts).unwrap();
    ok(&[
        "merge",
        s(&whole),
        "-o",
        s(&parts.join("run.mcap")),
        "--split-every",
        "9.7",
    ]);
    let n = same_fused(&whole, &parts, "seed004.toml", d.path());
    assert!(n >= 20, "{n} parts");
}

#[test]
fn info_on_a_run_gives_a_line_per_file_and_names_the_gap_between_files() {
    let d = tempfile::tempdir().unwrap();
    let whole = d.path().join("run.mcap");
    simulate(&["--duration", "60"], &whole);
    let parts = d.path().join("parts");
    std::fs::create_dir(&parts).unwrap();
    ok(&[
        "merge",
        s(&whole),
        "-o",
        s(&parts.join("run.mcap")),
        "--split-at",
        "20,40",
    ]);
    std::fs::remove_file(parts.join("run-002.mcap")).unwrap();
    let text = String::from_utf8(ok(&["info", s(&parts)]).stdout).unwrap();
    assert!(
        text.contains("run-001.mcap") && text.contains("run-003.mcap"),
        "{text}"
    );
    let gap = text
        .lines()
        .find(|l| l.starts_with("gap between files:"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        gap.contains("end of") && gap.contains("run-001.mcap"),
        "{gap}"
    );
    let info = ok_json(&["info", s(&parts), "--json"]);
    assert_eq!(info["files"].as_array().unwrap().len(), 2);
    let g = &info["gaps_between_files"][0];
    let len_s = (g["end_ns"].as_u64().unwrap() - g["start_ns"].as_u64().unwrap()) as f64 / 1e9;
    assert!((19.9..20.1).contains(&len_s), "{g}");
    // Merged back into one file, every message of both parts is there.
    let one = d.path().join("one.mcap");
    let r = ok_json(&[
        "merge",
        s(&parts.join("run-001.mcap")),
        s(&parts.join("run-003.mcap")),
        "-o",
        s(&one),
        "--json",
    ]);
    let sum: u64 = info["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["messages"].as_u64().unwrap())
        .sum();
    assert_eq!(r["messages"].as_u64(), Some(sum));
}

/// `railfuse ARGS` fails with one line on stderr containing each of `want`.
fn fails_saying(args: &[&str], want: &[&str]) {
    let out = railfuse(args);
    let err = stderr(&out);
    assert!(!out.status.success(), "{args:?} succeeded");
    assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: {err}");
    }
}

#[test]
fn a_run_that_cannot_be_read_as_one_says_why_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a.mcap"), d.path().join("b.mcap"));
    simulate(&["--duration", "20", "--seed", "1"], &a);
    simulate(&["--duration", "20", "--seed", "2"], &b);
    let out = d.path().join("out.mcap");
    let config = sample("kalman.toml");
    // A file of another run (its run metadata says so).
    fails_saying(
        &["refuse", s(&a), s(&b), "-c", s(&config), "-o", s(&out)],
        &[
            "b.mcap",
            "of run 'sim-default-seed2'",
            "a file of another run",
        ],
    );
    assert!(!out.exists());
    // Two recorders of one run both claiming /imu over the same time: the same samples
    // until 5 s are the same messages, read once; from there they differ.
    let c = d.path().join("c.mcap");
    simulate(
        &[
            "--duration",
            "20",
            "--seed",
            "1",
            "--fault",
            "imu:bias=1:5:10",
        ],
        &c,
    );
    fails_saying(
        &["refuse", s(&a), s(&c), "-c", s(&config), "-o", s(&out)],
        &["c.mcap", "is also in", "two sources on one topic"],
    );
    assert!(!out.exists());
    let empty = d.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    fails_saying(&["info", s(&empty)], &["empty", "not a run"]);
    let bag = d.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    std::fs::copy(&a, bag.join("bag_0.mcap")).unwrap();
    let yaml = "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  relative_file_paths:\n    - bag_0.mcap\n    - bag_1.mcap\n";
    std::fs::write(bag.join("metadata.yaml"), yaml).unwrap();
    fails_saying(
        &["info", s(&bag)],
        &["bag_1.mcap", "listed in", "--allow-missing-parts"],
    );
    let text = String::from_utf8(ok(&["info", s(&bag), "--allow-missing-parts"]).stdout).unwrap();
    assert!(
        text.contains("bag_0.mcap") && text.contains("bag_1.mcap (missing)"),
        "{text}"
    );
    // Where the bag says when the missing part ran, eval names the gap among its windows.
    let first = ok_json(&["info", s(&a), "--json"])["first_log_time_ns"]
        .as_u64()
        .unwrap();
    let listed = format!(
        "{yaml}  files:\n    - path: bag_1.mcap\n      starting_time:\n        nanoseconds_since_epoch: {}\n      duration:\n        nanoseconds: 5000000000\n      message_count: 10\n",
        first + 30_000_000_000
    );
    std::fs::write(bag.join("metadata.yaml"), listed).unwrap();
    let fused = d.path().join("bag.fused.mcap");
    let report = ok_json(&[
        "refuse",
        s(&bag),
        "--allow-missing-parts",
        "-c",
        s(&config),
        "-o",
        s(&fused),
        "--json",
    ]);
    let windows = report["eval"]["windows"].to_string();
    assert!(
        windows.contains("missing part")
            && windows.contains("bag_1.mcap")
            && windows.contains("35"),
        "{windows}"
    );
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information: {version: 9",
    )
    .unwrap();
    fails_saying(
        &["eval", s(&bag)],
        &["metadata.yaml", "not a rosbag2 metadata.yaml"],
    );
    // A damaged part: the run is read up to the damage, which is named with the remedy.
    let split = d.path().join("split");
    std::fs::create_dir(&split).unwrap();
    ok(&[
        "merge",
        s(&a),
        "--split-every",
        "10",
        "-o",
        s(&split.join("run.mcap")),
    ]);
    let second = split.join("run-002.mcap");
    let mut bytes = std::fs::read(&second).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&second, bytes).unwrap();
    fails_saying(
        &["refuse", s(&split), "-c", s(&config), "-o", s(&out)],
        &["run-002.mcap", "damaged at byte", "railfuse recover"],
    );
    assert!(!out.exists());
    // A usage error, as clap gives it (with the usage line below).
    let out = railfuse(&["info", s(&a), "--clock-offset", "a.mcap=soon"]);
    assert!(!out.status.success() && stderr(&out).contains("offset 'soon' is not a number"));
    fails_saying(&["info", s(&a), s(&a)], &["given twice"]);
}

#[test]
fn time_stamp_orders_a_run_by_each_message_s_own_stamp() {
    let d = tempfile::tempdir().unwrap();
    let whole = d.path().join("run.mcap");
    simulate(&["--duration", "60"], &whole);
    let parts = d.path().join("parts");
    std::fs::create_dir(&parts).unwrap();
    ok(&[
        "merge",
        s(&whole),
        "--split-every",
        "20",
        "-o",
        s(&parts.join("run.mcap")),
    ]);
    let stamped = d.path().join("stamped.mcap");
    ok(&["merge", s(&parts), "--time", "stamp", "-o", s(&stamped)]);
    // Every message once, each at its own stamp, in stamp order.
    let (mut n, mut last, mut out_of_order) = (0, 0u64, 0);
    let mut r = LogReader::open(&stamped).unwrap();
    while let Some(rec) = r.next() {
        let LogRecord::Message(m) = rec.unwrap() else {
            continue;
        };
        if m.channel.topic.starts_with("/foxglove/") {
            continue;
        }
        let any = m.decode_any(&stamped).unwrap().unwrap();
        if any.kind() != railfuse_catalog::messages::MessageKind::TrackMap {
            assert_eq!(m.log_time_ns, any.stamp_ns(), "{}", m.channel.topic);
        }
        out_of_order += usize::from(m.log_time_ns < last);
        last = last.max(m.log_time_ns);
        n += 1;
    }
    let original = ok_json(&["info", s(&whole), "--json"]);
    let foxglove: u64 = original["channels"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["topic"].as_str().unwrap().starts_with("/foxglove/"))
        .map(|c| c["messages"].as_u64().unwrap())
        .sum();
    assert_eq!(n as u64, original["messages"].as_u64().unwrap() - foxglove);
    assert_eq!(out_of_order, 0);
    // In log time the same file is not in stamp order: the sensors' latencies differ.
    let mut stamps_back = 0;
    let mut last = 0u64;
    let mut r = LogReader::open(&whole).unwrap();
    while let Some(rec) = r.next() {
        let LogRecord::Message(m) = rec.unwrap() else {
            continue;
        };
        if let Ok(Some(any)) = m.decode_any(&whole) {
            if any.kind() != railfuse_catalog::messages::MessageKind::TrackMap {
                stamps_back += usize::from(any.stamp_ns() < last);
                last = last.max(any.stamp_ns());
            }
        }
    }
    assert!(stamps_back > 100, "{stamps_back}");
}
