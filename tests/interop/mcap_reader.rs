//! The files railfuse writes, salvages and twins, read by the official Python `mcap` reader with
//! `jsonschema` and by `rerun mcap check`.

use super::*;

#[test]
fn python_mcap_reads_and_validates_every_message_and_rerun_accepts_the_files() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "11", "--duration", "200"], &raw);
    refuse(&raw, "kalman.toml", &fused);
    let info: serde_json::Value = ok_json(&["info", s(&raw), "--json"]);

    let r = python_ok("check_mcap.py", &[s(&raw)]);
    assert_eq!(r["messages"], info["messages"]);
    for t in [
        "/gnss/fix",
        "/imu",
        "/radar/speed",
        "/odometer/1",
        "/odometer/2",
        "/loop/position",
        "/balise",
        "/truth",
        "/events",
        "/track/map",
    ] {
        assert!(r["topics"][t].as_u64().unwrap_or(0) > 0, "no {t} read: {r}");
    }
    assert_eq!(r["compression"], serde_json::json!(["zstd"]));
    assert!(r["chunks"].as_u64().unwrap() > 1);
    assert_eq!(r["metadata"], serde_json::json!(["railfuse.run"]));

    let f = python_ok("check_mcap.py", &[s(&fused)]);
    assert!(f["topics"]["/fused/kalman/state"].as_u64().unwrap() > 1000);
    assert_eq!(
        f["metadata"],
        serde_json::json!(["railfuse.pipeline", "railfuse.run"])
    );

    for file in [&raw, &fused] {
        let text = rerun_ok(&["mcap", "check", s(file)]);
        assert!(!text.contains("PROBLEM"), "rerun mcap check: {text}");
        assert!(text.contains("/imu"), "{text}");
    }
}

/// The Foxglove twins, in protobuf (the default: decoded by Foxglove's own generated classes,
/// read the same through the file's descriptors) and in JSON (`--encoding json`), validate
/// against Foxglove's published schemas, and there is one for every fix with a position, every
/// event, the map, and each pipeline's position at most 10 times a second.
#[test]
fn foxglove_twins_validate_against_foxglove_s_published_schemas() {
    let schemas = std::env::var("RAILFUSE_FOXGLOVE_SCHEMAS")
        .expect("RAILFUSE_FOXGLOVE_SCHEMAS: run the tests with tests/run, which fetches them");
    let d = tempfile::tempdir().unwrap();
    for encoding in ["protobuf", "json"] {
        let (raw, fused) = (
            d.path().join(format!("raw-{encoding}.mcap")),
            d.path().join(format!("fused-{encoding}.mcap")),
        );
        let e = ["--encoding", encoding];
        ok(&[
            &e[..],
            &[
                "simulate",
                "--duration",
                "120",
                "--seed",
                "3",
                "-o",
                s(&raw),
            ],
        ]
        .concat());
        let cfg = sample("kalman.toml");
        ok(&[&e[..], &["refuse", s(&raw), "-c", s(&cfg), "-o", s(&fused)]].concat());
        let r = python_ok("check_foxglove.py", &[s(&fused), &schemas]);
        let all = r["encodings"].as_object().unwrap();
        assert!(all.len() == 4 && all.values().all(|v| v == encoding), "{r}");
        let counts = python_ok("check_mcap.py", &[s(&fused)]);
        let n = |topic: &str| counts["topics"][topic].as_u64().unwrap_or(0);
        let twins = |topic: &str| r["topics"][topic].as_u64().unwrap_or(0);
        assert!(
            twins("/foxglove/gnss/fix") > 0 && twins("/foxglove/gnss/fix") <= n("/gnss/fix"),
            "{r}"
        );
        assert_eq!(twins("/foxglove/events"), n("/events"), "{r}");
        assert_eq!(twins("/foxglove/track/map"), 1, "{r}");
        // Positions at 10 a second at most (the states come at about 70): a 120 s run holds
        // at most 1 201 of them.
        let fused = twins("/foxglove/fused/kalman/state");
        assert!(
            fused > 500 && fused <= 1201 && fused < n("/fused/kalman/state"),
            "{r}"
        );
        assert_eq!(r["geojson_type"], "FeatureCollection", "{r}");
        assert!(r["track_points"].as_u64().unwrap() > 10, "{r}");
        assert_eq!(
            r["geometries"],
            serde_json::json!(["LineString", "Point"]),
            "{r}"
        );
    }
}

/// A recording killed with SIGKILL mid-write (here the simulator, which writes the same way):
/// `recover` salvages every complete chunk into a valid file that the official Python reader
/// reads and validates, and the salvage is a prefix of what was being written.
#[test]
fn a_log_killed_mid_write_is_recovered_and_the_python_reader_reads_it() {
    let d = tempfile::tempdir().unwrap();
    let (out, fixed) = (d.path().join("long.mcap"), d.path().join("fixed.mcap"));
    let partial = d.path().join("long.mcap.partial");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args([
            "simulate",
            "--seed",
            "9",
            "--duration",
            "36000",
            "-o",
            s(&out),
        ])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    // 8 MiB: past the first minute of the run (the eddy-current blocks are most of the bytes).
    while std::fs::metadata(&partial).map_or(0, |m| m.len()) < 8 << 20 {
        assert!(
            started.elapsed().as_secs() < 120,
            "the simulator wrote nothing"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(
        !out.exists(),
        "a killed run must not leave a file that looks complete"
    );
    let r: serde_json::Value = ok_json(&["recover", s(&partial), "-o", s(&fixed), "--json"]);
    assert!(
        r["stopped_by"].as_str().unwrap().contains("truncated"),
        "{r}"
    );
    let messages = r["messages"].as_u64().unwrap();
    assert!(messages > 40_000, "{r}");
    let py = python_ok("check_mcap.py", &[s(&fixed)]);
    assert_eq!(py["messages"].as_u64().unwrap(), messages);
    assert_eq!(py["topics"]["/imu"], r["messages_per_topic"]["/imu"]);
}

/// Per topic, the messages of the chunks of `path` that hold no damage; the byte range of the
/// chunk nearest the middle.
fn chunks_around_the_middle(
    path: &std::path::Path,
) -> (
    std::ops::Range<usize>,
    std::collections::BTreeMap<String, u64>,
) {
    use railfuse_catalog::log::format::{parse_message, Records};
    use railfuse_catalog::log::scan::{Item, Scanner};
    let size = std::fs::metadata(path).unwrap().len() as usize;
    let topics: std::collections::HashMap<u16, String> = railfuse_catalog::log::read_channels(path)
        .unwrap()
        .unwrap()
        .iter()
        .map(|c| (c.id, c.topic.clone()))
        .collect();
    let mut scanner = Scanner::open(path).unwrap();
    let mut middle = None;
    let mut lost = std::collections::BTreeMap::new();
    while let Some(item) = scanner.next() {
        if let Item::Chunk(c) = item.unwrap() {
            if middle.is_none() && c.offset as usize > size / 2 {
                middle = Some(c.offset as usize..c.offset as usize + c.raw.len());
                for r in Records::new(&c.records).flatten() {
                    if let Some(m) = parse_message(r.body) {
                        *lost
                            .entry(topics[&m.header.channel_id].clone())
                            .or_insert(0) += 1;
                    }
                }
            }
        }
    }
    (middle.unwrap(), lost)
}

#[test]
fn a_corrupt_chunk_in_the_middle_costs_that_chunk_only_and_python_reads_the_rest() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("run.mcap");
    simulate(&["--seed", "2", "--duration", "240"], &raw);
    let original = python_ok("check_mcap.py", &[s(&raw)]);
    let (chunk, lost) = chunks_around_the_middle(&raw);
    let mut bytes = std::fs::read(&raw).unwrap();
    for b in &mut bytes[chunk.start + 100..chunk.start + 164] {
        *b ^= 0xa5; // flipped bits inside the compressed records
    }
    let broken = d.path().join("broken.mcap");
    std::fs::write(&broken, &bytes).unwrap();
    // Every reader says it is damaged, where, and what salvages it: one line, exit 1.
    let cfg = common::sample("kalman.toml");
    let (out, rrd) = (d.path().join("f.mcap"), d.path().join("f.rrd"));
    let mut lines = Vec::new();
    for args in [
        vec!["info", s(&broken)],
        vec!["refuse", s(&broken), "-c", s(&cfg), "-o", s(&out)],
        vec!["viz", s(&broken), "--save", s(&rrd)],
    ] {
        let o = railfuse(&args);
        let err = stderr(&o);
        assert!(
            !o.status.success() && err.lines().count() == 1,
            "{args:?}: {err}"
        );
        assert!(
            err.contains(&format!("damaged at byte {}", chunk.start)),
            "{err}"
        );
        assert!(
            err.contains("railfuse recover") && err.contains(s(&broken)),
            "{err}"
        );
        lines.push(err.trim().to_owned());
    }
    assert!(lines.windows(2).all(|w| w[0] == w[1]), "{lines:?}");
    let fixed = d.path().join("fixed.mcap");
    let r: serde_json::Value = ok_json(&["recover", s(&broken), "-o", s(&fixed), "--json"]);
    assert_eq!(r["skipped"].as_array().unwrap().len(), 1, "{r}");
    assert_eq!(r["skipped"][0]["offset"], chunk.start as u64, "{r}");
    // The official reader reads the salvage: every message of the original but the lost
    // chunk's, topic by topic.
    let py = python_ok("check_mcap.py", &[s(&fixed)]);
    for (topic, n) in original["topics"].as_object().unwrap() {
        let want = n.as_u64().unwrap() - lost.get(topic).copied().unwrap_or(0);
        assert_eq!(py["topics"][topic].as_u64().unwrap_or(0), want, "{topic}");
    }
    assert_eq!(py["messages"], r["messages"]);
    assert!(lost.values().sum::<u64>() < original["messages"].as_u64().unwrap() / 10);
}

#[test]
fn every_message_kind_validates_against_its_schema_in_the_python_reader() {
    use railfuse_catalog::log::LogWriter;
    use railfuse_catalog::messages::MessageKind;
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("kinds.mcap");
    // The catalogue's own kinds only: no Foxglove twins.
    let options = railfuse_catalog::log::WriterOptions {
        foxglove: false,
        ..Default::default()
    };
    let mut w = LogWriter::create_with(&path, &options).unwrap();
    for &kind in MessageKind::ALL {
        let topic = format!("/sample/{}", kind.type_name());
        let channel = w.add_channel_of(kind, &topic).unwrap();
        let m = kind.example();
        w.write_any(channel, m.stamp_ns(), &m).unwrap();
    }
    w.finish().unwrap();
    let py = python_ok("check_mcap.py", &[s(&path)]);
    assert_eq!(py["messages"], MessageKind::ALL.len(), "{py}");
    for &kind in MessageKind::ALL {
        assert_eq!(
            py["topics"][format!("/sample/{}", kind.type_name())],
            1,
            "{kind:?}: {py}"
        );
    }
}

/// The eddy-current blocks are protobuf by default (ADC counts with their step, the file's
/// own descriptors as their schema): mcap-protobuf-support decodes every sample to the float
/// the JSON log of the same run holds, the official reader validates the rest, and both logs
/// re-fuse to the same fused channels. `--encoding json` writes the old form.
#[test]
fn eddy_current_blocks_in_protobuf_decode_elsewhere_to_the_json_samples_and_refuse_alike() {
    let d = tempfile::tempdir().unwrap();
    let (pb, js) = (d.path().join("pb.mcap"), d.path().join("js.mcap"));
    let run = ["--scenario", "seed004", "--seed", "2", "--duration", "30"];
    simulate(&run, &pb);
    let mut args = vec!["--encoding", "json", "simulate"];
    args.extend(run);
    args.extend(["-o", s(&js)]);
    ok(&args);
    let same = python_ok("eddy_protobuf.py", &[s(&pb), s(&js)]);
    assert_eq!(same["blocks"], 300, "{same}");
    let (fpb, fjs) = (
        d.path().join("pb.fused.mcap"),
        d.path().join("js.fused.mcap"),
    );
    refuse(&pb, "seed004.toml", &fpb);
    refuse(&js, "seed004.toml", &fjs);
    let checked = python_ok("check_mcap.py", &[s(&fpb)]);
    assert_eq!(
        checked["protobuf"]["/eddy_current/block"], "railfuse.EddyCurrentBlock",
        "{checked}"
    );
    for pipeline in ["plain", "warped", "warped_kf"] {
        let topic = format!("/fused/{pipeline}/state");
        use railfuse_catalog::messages::FusedState;
        let (a, b): (Vec<FusedState>, Vec<FusedState>) =
            (messages(&fpb, &topic), messages(&fjs, &topic));
        assert!(!a.is_empty() && a == b, "{pipeline}");
    }
    let sizes = [&pb, &js].map(|p| std::fs::metadata(p).unwrap().len());
    assert!(
        sizes[0] < sizes[1],
        "protobuf {} bytes, JSON {}",
        sizes[0],
        sizes[1]
    );
}

/// `--encoding protobuf` writes the fused states and diagnostics in protobuf: mcap-protobuf-support decodes
/// them through the file's descriptors, and railfuse reads them back to the very states, and
/// the same accuracy, as the JSON run's.
#[test]
fn fused_states_and_diagnostics_in_protobuf_decode_elsewhere_and_read_back_as_the_json_run_s() {
    use railfuse_catalog::messages::FusedState;
    let d = tempfile::tempdir().unwrap();
    let (pb, js) = (d.path().join("pb.mcap"), d.path().join("js.mcap"));
    let run = sample("short-run.mcap");
    let config = sample("kalman.toml");
    let args = |out: &std::path::Path| {
        ["refuse", s(&run), "-c", s(&config), "-o", s(out), "--json"].map(str::to_owned)
    };
    let mut with_protobuf = vec!["--encoding".to_owned(), "protobuf".to_owned()];
    with_protobuf.extend(args(&pb));
    let r_pb = ok_json(&with_protobuf.iter().map(String::as_str).collect::<Vec<_>>());
    let r_js = ok_json(&args(&js).iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(r_pb["eval"]["pipelines"], r_js["eval"]["pipelines"]);
    let checked = python_ok("check_mcap.py", &[s(&pb)]);
    assert_eq!(
        checked["protobuf"]["/fused/kalman/state"], "railfuse.FusedState",
        "{checked}"
    );
    let topic = "/fused/kalman/state";
    let (a, b): (Vec<FusedState>, Vec<FusedState>) = (messages(&pb, topic), messages(&js, topic));
    // (serde_json reads a float to within an ulp; protobuf carries its bits.)
    assert!(a.len() > 1000 && a.len() == b.len());
    let close = |x: f64, y: f64| (x - y).abs() <= 4.0 * f64::EPSILON * x.abs().max(y.abs());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!((x.stamp_ns, &x.source), (y.stamp_ns, &y.source));
        let (fx, fy) = (
            [x.chainage_m, x.speed_mps, x.acceleration_mps2],
            [y.chainage_m, y.speed_mps, y.acceleration_mps2],
        );
        for (u, v) in fx
            .iter()
            .chain(&x.covariance)
            .zip(fy.iter().chain(&y.covariance))
        {
            assert!(close(*u, *v), "{x:?} vs {y:?}");
        }
    }
    let e = ok_json(&["eval", s(&pb), "--json"]);
    assert_eq!(
        e["pipelines"][0]["states"],
        r_js["eval"]["pipelines"][0]["states"]
    );
    // The diagnostics too: every measurement's decision, reason and NIS.
    assert_eq!(
        checked["protobuf"]["/fused/kalman/diagnostics"], "railfuse.FusedDiagnostics",
        "{checked}"
    );
    use railfuse_catalog::messages::FusedDiagnostics;
    let topic = "/fused/kalman/diagnostics";
    let (a, b): (Vec<FusedDiagnostics>, Vec<FusedDiagnostics>) =
        (messages(&pb, topic), messages(&js, topic));
    assert!(a.len() > 1000 && a.len() == b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(
            (x.stamp_ns, x.decision, &x.reason),
            (y.stamp_ns, y.decision, &y.reason)
        );
        match (x.nis, y.nis) {
            (Some(u), Some(v)) => assert!(close(u, v), "{x:?} vs {y:?}"),
            (u, v) => assert_eq!(u, v),
        }
    }
}
