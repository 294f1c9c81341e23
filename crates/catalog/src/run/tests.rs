use std::path::{Path, PathBuf};

use super::*;
use crate::log::{LogRecord, LogWriter};
use crate::messages::RadarSpeed;

fn radar(k: u64) -> RadarSpeed {
    RadarSpeed {
        stamp_ns: k,
        speed_mps: k as f64 * 1e-9,
        quality: 1.0,
        valid: true,
        speed_variance_m2ps2: None,
    }
}

/// A file of radar messages at `times` (then, on a second topic, at `imu`), in that order.
fn write(path: &Path, times: &[u64], imu: &[u64]) {
    let mut w = LogWriter::create(path).unwrap();
    let ch = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
    let imu_ch = w.add_channel::<RadarSpeed>("/imu").unwrap();
    for &t in times {
        w.write(ch, t, &radar(t)).unwrap();
    }
    for &t in imu {
        w.write(imu_ch, t, &radar(t)).unwrap();
    }
    w.finish().unwrap();
}

/// (topic, log time) of every message of the run, in the order read.
fn read(run: &Run) -> Result<Vec<(String, u64)>> {
    let mut r = run.reader()?;
    let mut out = Vec::new();
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec? {
            out.push((m.channel.topic.clone(), m.log_time_ns));
        }
    }
    Ok(out)
}

fn paths(d: &Path, names: &[&str]) -> Vec<PathBuf> {
    names.iter().map(|n| d.join(n)).collect()
}

#[test]
fn parts_merge_by_time_ties_in_input_order_and_one_file_reads_as_itself() {
    let d = tempfile::tempdir().unwrap();
    let p = paths(d.path(), &["a.mcap", "b.mcap"]);
    write(&p[0], &[10, 30, 30, 50], &[]);
    write(&p[1], &[], &[20, 30, 40]);
    let run = Run::open(&p, &RunOptions::default()).unwrap();
    let got = read(&run).unwrap();
    let want = [
        ("/radar/speed", 10),
        ("/imu", 20),
        ("/radar/speed", 30),
        ("/radar/speed", 30),
        ("/imu", 30),
        ("/imu", 40),
        ("/radar/speed", 50),
    ];
    let want: Vec<(String, u64)> = want.iter().map(|(t, n)| (t.to_string(), *n)).collect();
    assert_eq!(got, want);
    // Inputs the other way round: the tie at 30 goes the other way.
    let flipped = Run::open(&[p[1].clone(), p[0].clone()], &RunOptions::default()).unwrap();
    assert_eq!(read(&flipped).unwrap()[2], ("/imu".to_string(), 30));
    // One file out of time order keeps its own order.
    let one = d.path().join("one.mcap");
    write(&one, &[5, 3, 9], &[]);
    let t: Vec<u64> = read(&Run::file(&one))
        .unwrap()
        .iter()
        .map(|m| m.1)
        .collect();
    assert_eq!(t, [5, 3, 9]);
}

#[test]
fn a_split_run_keeps_its_ids_drops_a_repeat_at_the_boundary_and_opens_parts_in_turn() {
    let d = tempfile::tempdir().unwrap();
    let p = paths(d.path(), &["run-001.mcap", "run-002.mcap", "run-003.mcap"]);
    write(&p[0], &[1, 2, 3], &[1]);
    write(&p[1], &[3, 4, 5], &[]); // 3 again: the same message at the boundary
    write(&p[2], &[6, 7], &[7]);
    let run = Run::open(&[d.path().to_owned()], &RunOptions::default()).unwrap();
    assert_eq!(run.parts().len(), 3);
    let mut r = run.reader().unwrap();
    let ids: Vec<u16> = r
        .summary()
        .unwrap()
        .channels
        .as_ref()
        .unwrap()
        .iter()
        .map(|c| c.id)
        .collect();
    let (mut channels, mut messages, mut most_open) = (Vec::new(), 0, 0);
    while let Some(rec) = r.next() {
        match rec.unwrap() {
            LogRecord::Channel(c) => channels.push(c.id),
            LogRecord::Message(_) => messages += 1,
            _ => {}
        }
        most_open = most_open.max(r.parts.iter().filter(|p| p.reader.is_some()).count());
    }
    assert_eq!(channels, ids, "each channel once, under the file's own id");
    assert_eq!(messages, 9);
    assert_eq!(r.counts().duplicates_dropped, 1);
    assert_eq!(r.counts().parts_read, 3);
    assert!(most_open <= 2, "{most_open} parts open at once");
}

#[test]
fn one_topic_from_two_files_over_the_same_time_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = paths(d.path(), &["a.mcap", "b.mcap"]);
    write(&p[0], &[10, 20, 30], &[]);
    write(&p[1], &[15, 25], &[]);
    let run = Run::open(&p, &RunOptions::default()).unwrap();
    let e = read(&run).unwrap_err().to_string();
    assert!(
        e.contains("/radar/speed is also in") && e.contains("two sources on one topic"),
        "{e}"
    );
}

#[test]
fn clock_offsets_move_a_file_on_the_run_s_time() {
    let d = tempfile::tempdir().unwrap();
    let p = paths(d.path(), &["a.mcap", "b.mcap"]);
    write(&p[0], &[1_000_000_000, 2_000_000_000], &[]);
    write(&p[1], &[], &[1_500_000_000]);
    let offset: ClockOffset = format!("{}=+0.75", p[1].display()).parse().unwrap();
    let opts = RunOptions {
        clock_offsets: vec![offset],
        ..Default::default()
    };
    let got = read(&Run::open(&p, &opts).unwrap()).unwrap();
    assert_eq!(got[0], ("/imu".to_string(), 750_000_000));
    let drift: ClockOffset = "x.mcap=-1.2,+20ppm".parse().unwrap();
    assert_eq!(
        (drift.clock.offset_ns, drift.clock.drift_ppm),
        (-1_200_000_000, 20.0)
    );
    let map = ClockMap {
        origin_ns: 1_000_000_000_000,
        ..drift.clock
    };
    // 100 s after the origin a 20 ppm clock is 2 ms ahead.
    assert_eq!(
        map.correct(1_100_000_000_000),
        1_100_000_000_000 + 1_200_000_000 - 2_000_000
    );
    for bad in ["x.mcap", "x.mcap=fast", "x.mcap=0.1,20", "x.mcap=1e9"] {
        assert!(bad.parse::<ClockOffset>().is_err(), "{bad}");
    }
    let stray: ClockOffset = "elsewhere.mcap=+1".parse().unwrap();
    let e = Run::open(
        &p,
        &RunOptions {
            clock_offsets: vec![stray],
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("not a file or input of the run"), "{e}");
}

#[test]
fn a_bag_directory_is_read_from_its_metadata_and_a_missing_part_named() {
    let d = tempfile::tempdir().unwrap();
    let bag = d.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    write(&bag.join("bag_0.mcap"), &[1, 2], &[]);
    write(&bag.join("bag_1.mcap"), &[3, 4], &[]);
    let yaml = |files: &[&str]| {
        let list: String = files.iter().map(|f| format!("    - {f}\n")).collect();
        let info: String = files
            .iter()
            .enumerate()
            .map(|(i, f)| {
                format!(
                    "    - path: {f}\n      starting_time:\n        nanoseconds_since_epoch: {}\n      \
                     duration:\n        nanoseconds: 1\n      message_count: 2\n",
                    2 * i + 1
                )
            })
            .collect();
        format!(
            "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  \
             relative_file_paths:\n{list}  files:\n{info}"
        )
    };
    std::fs::write(
        bag.join("metadata.yaml"),
        yaml(&["bag_0.mcap", "bag_1.mcap"]),
    )
    .unwrap();
    let run = Run::open(&[bag.clone()], &RunOptions::default()).unwrap();
    assert_eq!(run.parts()[1].listed_start_ns, Some(3));
    assert_eq!(read(&run).unwrap().len(), 4);

    std::fs::write(
        bag.join("metadata.yaml"),
        yaml(&["bag_0.mcap", "bag_9.mcap", "bag_1.mcap"]),
    )
    .unwrap();
    let e = Run::open(&[bag.clone()], &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bag_9.mcap: listed in") && e.contains("--allow-missing-parts"),
        "{e}"
    );
    let opts = RunOptions {
        allow_missing_parts: true,
        ..Default::default()
    };
    let run = Run::open(&[bag.clone()], &opts).unwrap();
    assert_eq!((run.parts().len(), run.missing().len()), (2, 1));
    assert_eq!(run.missing()[0].start_ns, Some(3));

    std::fs::write(bag.join("metadata.yaml"), "rosbag2_bagfile_information: [").unwrap();
    let e = Run::open(&[bag.clone()], &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("metadata.yaml: not a rosbag2 metadata.yaml"),
        "{e}"
    );
    // Without metadata.yaml, the files in their numbered order.
    std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
    write(&bag.join("bag_10.mcap"), &[9], &[]);
    let run = Run::open(&[bag.clone()], &RunOptions::default()).unwrap();
    let names: Vec<_> = run
        .parts()
        .iter()
        .map(|p| p.path.file_name().unwrap().to_owned())
        .collect();
    assert_eq!(names, ["bag_0.mcap", "bag_1.mcap", "bag_10.mcap"]);
    let empty = d.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let e = Run::open(&[empty], &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a run"), "{e}");
}

#[test]
fn names_sort_in_their_numbered_order() {
    let mut v = vec![
        "run-010.mcap",
        "run-9.mcap",
        "bag_10.mcap",
        "bag_2.mcap",
        "bag_1.mcap",
    ];
    v.sort_by(|a, b| natural_order(a, b));
    assert_eq!(
        v,
        [
            "bag_1.mcap",
            "bag_2.mcap",
            "bag_10.mcap",
            "run-9.mcap",
            "run-010.mcap"
        ]
    );
}

/// Messages (channel id, log time) of `items`, with the file each came from.
fn chunked_messages(items: crate::log::scan::ReadAhead) -> Vec<(usize, u16, u64)> {
    use crate::log::format::{parse_message, Records};
    use crate::log::scan::Item;
    let mut items = items;
    let mut out = Vec::new();
    while let Some(item) = items.next() {
        if let Item::Chunk(chunk) = item.unwrap() {
            for r in Records::new(&chunk.records) {
                let r = r.unwrap();
                if r.opcode == mcap::records::op::MESSAGE {
                    let m = parse_message(r.body).unwrap();
                    out.push((items.file(), m.header.channel_id, m.header.log_time));
                }
            }
        }
    }
    out
}

#[test]
fn parts_that_follow_one_another_read_as_one_file_through_one_read_ahead() {
    use crate::log::scan::{ReadAhead, Scanner, READ_AHEAD_BYTES};
    let d = tempfile::tempdir().unwrap();
    let p = paths(d.path(), &["run-001.mcap", "run-002.mcap", "run-003.mcap"]);
    write(&p[0], &[10, 20], &[15]);
    write(&p[1], &[30, 40], &[35]);
    write(&p[2], &[50], &[55]);
    let run = Run::open(&p, &RunOptions::default()).unwrap();
    let seq = run
        .sequential_files()
        .unwrap()
        .expect("parts in order, the same ids");
    assert_eq!(
        seq.files,
        p.iter().map(PathBuf::as_path).collect::<Vec<_>>()
    );
    assert_eq!(seq.summary.message_span_ns, Some((10, 55)));
    let topics: Vec<&str> = seq
        .summary
        .channels
        .as_ref()
        .unwrap()
        .iter()
        .map(|c| c.topic.as_str())
        .collect();
    assert_eq!(topics, ["/radar/speed", "/imu"]);
    // The chained read hands out every file's messages in turn, each named by its file,
    // and counts bytes over all files.
    let chained = ReadAhead::files(&seq.files, READ_AHEAD_BYTES).unwrap();
    let size: u64 = p.iter().map(|f| std::fs::metadata(f).unwrap().len()).sum();
    assert_eq!(chained.size(), size);
    let got = chunked_messages(chained);
    let mut want = Vec::new();
    for (i, f) in p.iter().enumerate() {
        let one = chunked_messages(ReadAhead::new(Scanner::open(f).unwrap(), READ_AHEAD_BYTES));
        want.extend(one.into_iter().map(|(_, c, t)| (i, c, t)));
    }
    assert_eq!(got.len(), 8, "every message, in chunks: {got:?}");
    assert_eq!(got, want);
    // Overlapping parts are not read in turn; a file missing at its turn is an error item.
    write(&p[2], &[38], &[]);
    let overlapping = Run::open(&p, &RunOptions::default()).unwrap();
    assert!(overlapping.sequential_files().unwrap().is_none());
    let files: Vec<&Path> = vec![&p[0], &p[1]];
    std::fs::remove_file(&p[1]).unwrap_or(());
    assert!(
        ReadAhead::files(&files, READ_AHEAD_BYTES).is_err(),
        "a missing file is named before reading"
    );
}
