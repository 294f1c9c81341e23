//! railfuse's CAN reading checked against the CAN ecosystem's own tools: a candump log and a
//! Vector ASC log read frame for frame as python-can reads them, and every frame decoded
//! signal for signal as cantools decodes it, on samples/vehicle.dbc (Intel and Motorola, signed, scaled, IEEE
//! float and double, multiplexed signals, value tables).

mod common;

use std::path::Path;

use common::*;
use std::fs::File;
use std::io::BufReader;

use railfuse_can::asc;
use railfuse_can::candump::Reader;
use railfuse_can::dbc::Database;
use railfuse_can::decode::Decoded;
use railfuse_can::frame::{Frame, FD_LENGTHS};

/// A seeded stream of bytes (SplitMix64): the frames' data.
struct Bytes(u64);

impl Bytes {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn hex(&mut self, n: usize) -> String {
        (0..n)
            .map(|_| format!("{:02X}", self.next() as u8))
            .collect()
    }
}

/// 600 frames of every message in the DBC, ids it does not have, a remote request, an error
/// frame and FD frames, as `candump -l` writes them.
fn candump_log() -> String {
    let mut b = Bytes(48);
    let ids = ["100", "101", "120", "19000000", "200", "321", "01ABCDEF"];
    let mut log = String::new();
    for i in 0..600u64 {
        let stamp = format!(
            "({}.{:06})",
            1_700_000_000 + i / 100,
            (i % 100) * 10_000 + 7
        );
        let id = ids[(b.next() % ids.len() as u64) as usize];
        let mut data = b.hex(8);
        if id == "19000000" {
            // The multiplexor: one of the three pages the DBC has.
            data.replace_range(0..2, &format!("{:02X}", b.next() % 3));
        }
        log.push_str(&format!("{stamp} can0 {id}#{data}\n"));
    }
    log.push_str("(1700000006.000001) can0 100#R\n");
    // A bus error: python-can takes only that class of error frame as one.
    log.push_str("(1700000006.000002) can0 20000080#0000000000000000\n");
    log.push_str(&format!(
        "(1700000006.000003) can1 321##1{}\n",
        Bytes(7).hex(12)
    ));
    log.push_str(&format!(
        "(1700000006.000004) can1 19000001##0{}\n",
        Bytes(8).hex(64)
    ));
    log
}

#[test]
fn candump_frames_and_dbc_signals_agree_with_python_can_and_cantools() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("frames.log");
    std::fs::write(&log, candump_log()).unwrap();
    let ours: Vec<Frame> = Reader::new(BufReader::new(File::open(&log).unwrap()))
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(ours.len(), 604);
    agrees_with_python_can_and_cantools(d.path(), &log, &ours, |f| f.bus.clone());
}

#[test]
fn vector_asc_frames_agree_with_python_can_and_with_their_candump() {
    let d = tempfile::tempdir().unwrap();
    let frames: Vec<Frame> = Reader::new(candump_log().as_bytes())
        .map(|f| f.unwrap())
        .collect();
    let asc = d.path().join("frames.asc");
    std::fs::write(&asc, asc_log(&frames)).unwrap();
    let ours: Vec<Frame> = asc::Reader::new(BufReader::new(File::open(&asc).unwrap()))
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(ours.len(), frames.len());
    for (a, c) in ours.iter().zip(&frames) {
        let bus = if c.bus == "can0" { "CAN1" } else { "CAN2" };
        assert_eq!(a.bus, bus);
        if c.error {
            // An ASC error frame says nothing of its class.
            assert!(a.error && a.stamp_ns == c.stamp_ns, "{a:?}");
            continue;
        }
        assert_eq!(
            Frame {
                bus: c.bus.clone(),
                ..a.clone()
            },
            *c,
            "{a:?}"
        );
    }
    // python-can numbers an ASC channel from 0.
    agrees_with_python_can_and_cantools(d.path(), &asc, &ours, |f| {
        (f.bus[3..].parse::<u32>().unwrap() - 1).to_string()
    });
}

/// The frames as Vector's ASC logging writes them, the trigger block starting at the first
/// one's whole second.
fn asc_log(frames: &[Frame]) -> String {
    let start = frames[0].stamp_ns / 1_000_000_000 * 1_000_000_000;
    // 1700000000 s: Tue Nov 14 22:13:20 2023 UTC.
    assert_eq!(start, 1_700_000_000_000_000_000);
    let date = "Tue Nov 14 10:13:20.000 pm 2023";
    let mut out = format!("date {date}\nbase hex  timestamps absolute\ninternal events logged\n");
    out.push_str(&format!(
        "Begin Triggerblock {date}\n   0.000000 Start of measurement\n"
    ));
    for f in frames {
        let t = format!("{:.6}", (f.stamp_ns - start) as f64 / 1e9);
        let ch = if f.bus == "can0" { 1 } else { 2 };
        let id = format!("{:X}{}", f.id, if f.extended { "x" } else { "" });
        let data: Vec<String> = f.data.iter().map(|b| format!("{b:02X}")).collect();
        let line = match (f.error, f.fd, f.rtr) {
            (true, _, _) => format!("{t} {ch}  ErrorFrame"),
            (_, true, _) => {
                let dlc = FD_LENGTHS.iter().position(|&n| n == f.data.len()).unwrap();
                format!(
                    "{t} CANFD {ch:>3} Rx {id:>8}  {:>32} {} {} {dlc:x} {} {}",
                    "",
                    u8::from(f.brs),
                    u8::from(f.esi),
                    f.data.len(),
                    data.join(" ")
                )
            }
            (_, _, true) => format!("{t} {ch}  {id:<15} Rx   r"),
            _ => format!(
                "{t} {ch}  {id:<15} Rx   d {} {}",
                f.data.len(),
                data.join(" ")
            ),
        };
        out.push_str(&line);
        out.push('\n');
    }
    out.push_str("End TriggerBlock\n");
    out
}

/// `ours` (read from `log`) against python-can's reading of the same file and cantools'
/// decoding of each frame; `bus` gives a frame's bus as python-can names it.
fn agrees_with_python_can_and_cantools(
    dir: &Path,
    log: &Path,
    ours: &[Frame],
    bus: impl Fn(&Frame) -> String,
) {
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/vehicle.dbc");
    let out = dir.join("theirs.json");
    let py = python("can_check.py", &[s(&dbc), s(log), s(&out)]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let theirs: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let db = Database::open(&dbc).unwrap();
    assert_eq!(ours.len(), theirs.len());
    let (mut decoded, mut signals, mut labels) = (0, 0, 0);
    for (f, t) in ours.iter().zip(&theirs) {
        let at = format!("frame at {} id {:#x}", f.stamp_ns, f.id);
        assert!(
            (f.stamp_ns as f64 / 1e9 - t["stamp"].as_f64().unwrap()).abs() < 1e-6,
            "{at}"
        );
        // python-can keeps an error frame's time and nothing else of it.
        assert_eq!(t["error"], f.error, "{at}: error");
        if f.error {
            continue;
        }
        assert_eq!(t["bus"].to_string().trim_matches('"'), bus(f), "{at}");
        assert_eq!(t["id"], f.id, "{at}");
        for (flag, ours) in [
            ("extended", f.extended),
            ("rtr", f.rtr),
            ("fd", f.fd),
            ("brs", f.brs),
            ("esi", f.esi),
        ] {
            assert_eq!(t[flag], ours, "{at}: {flag}");
        }
        let hex: String = f.data.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(t["data"], hex.as_str(), "{at}");
        match (db.decode(f), t["signals"].as_object()) {
            (Decoded::Signals { values, .. }, Some(theirs)) => {
                decoded += 1;
                assert_eq!(values.len(), theirs.len(), "{at}: {values:?} {theirs:?}");
                for v in &values {
                    let Some(their) = theirs[&v.name].as_f64() else {
                        // NaN or an infinity, by name.
                        let name = theirs[&v.name].as_str().unwrap();
                        assert_eq!(format!("{}", v.value).to_lowercase(), name, "{at}");
                        signals += 1;
                        continue;
                    };
                    assert!(
                        (v.value - their).abs() <= 1e-9 * their.abs().max(1.0),
                        "{at}: {} = {} here, {their} by cantools",
                        v.name,
                        v.value
                    );
                    signals += 1;
                    let their_label = t["labels"].get(&v.name).and_then(|l| l.as_str());
                    assert_eq!(v.label.as_deref(), their_label, "{at}: {}", v.name);
                    labels += usize::from(their_label.is_some());
                }
            }
            (Decoded::Unknown, None) => {}
            (ours, theirs) => panic!("{at}: {ours:?} here, {theirs:?} by cantools"),
        }
    }
    // Every message of the DBC came up, with its value tables.
    assert!(
        decoded > 400 && signals > 1200 && labels > 100,
        "{decoded} {signals} {labels}"
    );
}

/// The messages of each topic in a log, by `info --json`.
fn topic_counts(path: &Path) -> std::collections::BTreeMap<String, u64> {
    ok_json(&["info", s(path), "--json"])["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["topic"].as_str().unwrap().to_owned(),
                c["messages"].as_u64().unwrap(),
            )
        })
        .collect()
}

#[test]
fn a_can_only_run_re_fuses_as_its_own_channels_do_and_agrees_with_cantools() {
    let d = tempfile::tempdir().unwrap();
    let (bus, plain) = (d.path().join("bus.mcap"), d.path().join("plain.mcap"));
    simulate(&["--can-bus", "--seed", "3", "--duration", "200"], &bus);
    simulate(&["--seed", "3", "--duration", "200"], &plain);
    let counts = topic_counts(&bus);
    assert!(
        !counts.contains_key("/odometer/1") && !counts.contains_key("/radar/speed"),
        "the sensors are on the bus only: {counts:?}"
    );
    let (bus_fused, plain_fused) = (
        d.path().join("bus.fused.mcap"),
        d.path().join("plain.fused.mcap"),
    );
    let on_bus = refuse_json(&bus, "can.toml", &bus_fused);
    let own = refuse_json(&plain, "kalman.toml", &plain_fused);
    // Every reading of the sensors came back from the bus.
    let plain_counts = topic_counts(&plain);
    let made = &on_bus["refuse"]["can"]["made"];
    for topic in ["/odometer/1", "/odometer/2", "/radar/speed"] {
        assert_eq!(
            made[topic].as_u64(),
            plain_counts.get(topic).copied(),
            "{topic}: {on_bus}"
        );
    }
    assert_eq!(
        topic_counts(&bus_fused)["/odometer/1"],
        plain_counts["/odometer/1"]
    );
    // The same accuracy as from the sensors' own channels: the bus adds 0.01 m/s steps and
    // each sensor's 2 ms latency (a frame's time is when it was on the bus).
    let rmse = |r: &serde_json::Value| {
        pipeline_eval(r, "kalman")["position_error_m"]["rmse"]
            .as_f64()
            .unwrap()
    };
    let (a, b) = (rmse(&on_bus), rmse(&own));
    assert!(
        (a - b).abs() <= 0.1 * b,
        "position RMSE {a} m from the bus, {b} m from the channels"
    );
    // cantools reads the frames (through mcap-protobuf-support, from the file's own schema)
    // to the very values railfuse made its sensors of.
    let out = d.path().join("theirs.json");
    let dbc = sample("vehicle.dbc");
    let py = python("can_mcap.py", &[s(&dbc), s(&bus), s(&bus_fused), s(&out)]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let theirs: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        theirs["frames"].as_u64(),
        counts.get("/can/can0/frames").copied()
    );
    for (topic, t) in theirs["topics"].as_object().unwrap() {
        assert!(t["both"].as_u64().unwrap() > 1000, "{topic}: {t}");
        assert_eq!(t["both"], t["cantools"], "{topic}: {t}");
        assert_eq!(t["both"], t["railfuse"], "{topic}: {t}");
        assert!(t["max_difference"].as_f64().unwrap() < 1e-9, "{topic}: {t}");
    }
}

#[test]
fn a_candump_log_imports_decoded_and_bad_can_input_is_one_line_naming_its_place() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("bus.mcap");
    let dbc = sample("vehicle.dbc");
    let log = d.path().join("bus.log");
    let mut text = std::fs::read_to_string(sample("vehicle-bus.log")).unwrap();
    text.push_str("(1780300830.5) can0 100#not hex\n");
    std::fs::write(&log, text).unwrap();
    let r = ok_json(&["import", s(&log), "--dbc", s(&dbc), "-o", s(&out), "--json"]);
    assert_eq!(r["format"], "candump");
    assert_eq!(r["per_topic"]["/can/can0/frames"], 702, "{r}");
    assert_eq!(r["per_topic"]["/can/can0/WheelSpeed"], 250, "{r}");
    assert_eq!(r["skipped"]["line that does not parse"], 1, "{r}");
    assert!(
        r["first_problems"][0]
            .as_str()
            .unwrap()
            .starts_with("line 703:"),
        "{r}"
    );
    assert_eq!(r["warnings"]["CAN id not in the DBC (kept raw)"], 1, "{r}");
    assert_eq!(r["warnings"]["CAN error frame"], 1, "{r}");
    // A DBC that does not parse: its file and line, before anything is written.
    let broken = d.path().join("broken.dbc");
    let dbc_text = std::fs::read_to_string(&dbc).unwrap();
    std::fs::write(
        &broken,
        dbc_text.replace("SG_ Quality : 23|8@0+", "SG_ Quality : 23|8@0x"),
    )
    .unwrap();
    let fail = |args: &[&str]| {
        let o = railfuse(args);
        assert!(!o.status.success(), "{args:?}");
        let e = stderr(&o);
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        e
    };
    let e = fail(&[
        "import",
        "--format",
        "candump",
        s(&log),
        "--dbc",
        s(&broken),
        "-o",
        s(&d.path().join("x.mcap")),
    ]);
    assert!(e.contains("broken.dbc:25:"), "{e}");
    assert!(!d.path().join("x.mcap").exists());
    let e = fail(&[
        "record",
        "--can",
        "slcan:/dev/null",
        "--dbc",
        s(&broken),
        "-o",
        s(&d.path().join("r.mcap")),
    ]);
    assert!(e.contains("broken.dbc:25:"), "{e}");
    assert!(!d.path().join("r.mcap").exists() && !d.path().join("r.mcap.partial").exists());
    // Configurations: each fault names the file and the table.
    let config = |name: &str, body: &str| {
        let p = d.path().join(name);
        let base = std::fs::read_to_string(sample("can.toml")).unwrap();
        let pipelines = &base[base.find("[[pipeline]]").unwrap()..];
        std::fs::write(&p, format!("{body}\n{pipelines}")).unwrap();
        std::fs::copy(&dbc, d.path().join("vehicle.dbc")).unwrap();
        p
    };
    for (name, body, says) in [
        ("no-can.toml", "[sensor.\"/odometer/1\"]\nfrom = \"can:WheelSpeed.AxleSpeed1\"", "name the vehicle's DBC in [can]"),
        ("no-signal.toml", "[can]\ndbc = \"vehicle.dbc\"\n[sensor.\"/odometer/1\"]\nfrom = \"can:WheelSpeed.Axle9\"", "message WheelSpeed has no signal Axle9"),
        ("not-speed.toml", "[can]\ndbc = \"vehicle.dbc\"\n[sensor.\"/radar/speed\"]\nfrom = \"can:RadarSpeed.Quality\"", "is in '%': a speed is in m/s, km/h or mph"),
        ("imu.toml", "[can]\ndbc = \"vehicle.dbc\"\n[sensor.\"/imu\"]\nfrom = \"can:RadarSpeed.Acceleration\"", "`from` is an odometer's or a radar's"),
        ("balise.toml", "[can]\ndbc = \"vehicle.dbc\"\n[sensor.\"/balise\"]\nfrom = \"can:RadarSpeed.Speed\"", "is a BalisePassage channel"),
        ("two-dbcs.toml", "[[can]]\ndbc = \"vehicle.dbc\"\n[[can]]\ndbc = \"vehicle.dbc\"\n[sensor.\"/odometer/1\"]\nfrom = \"can:WheelSpeed.AxleSpeed1\"", "two tables for every bus"),
        ("bad-dbc.toml", "[can]\ndbc = \"broken.dbc\"\n[sensor.\"/odometer/1\"]\nfrom = \"can:WheelSpeed.AxleSpeed1\"", "broken.dbc:25:"),
    ] {
        let c = config(name, body);
        let e = fail(&["refuse", s(&out), "-c", s(&c), "-o", s(&d.path().join("f.mcap"))]);
        assert!(e.contains(name) && e.contains(says), "{name}: {e}");
    }
    // A log that has the sensor's own channel and its frames: the sensor would come twice.
    let plain = d.path().join("plain.mcap");
    simulate(&["--duration", "20"], &plain);
    let mixed = d.path().join("mixed.mcap");
    ok(&["merge", s(&plain), s(&out), "-o", s(&mixed)]);
    let e = fail(&[
        "refuse",
        s(&mixed),
        "-c",
        s(&sample("can.toml")),
        "-o",
        s(&d.path().join("f.mcap")),
    ]);
    assert!(
        e.contains("from the CAN bus") && e.contains("has that channel too"),
        "{e}"
    );
}

#[test]
fn blf_frames_agree_with_python_can_and_a_broken_blf_keeps_what_came_before() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("frames.log");
    std::fs::write(&log, candump_log()).unwrap();
    let frames: Vec<Frame> = Reader::new(candump_log().as_bytes())
        .map(|f| f.unwrap())
        .collect();
    let (blf, out) = (d.path().join("frames.blf"), d.path().join("theirs.json"));
    let py = python("can_blf.py", &[s(&log), s(&blf), s(&out)]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let theirs: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let ours: Vec<Frame> = railfuse_can::blf::Reader::new(File::open(&blf).unwrap())
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(ours.len(), frames.len());
    assert_eq!(theirs.len(), frames.len());
    for ((a, c), t) in ours.iter().zip(&frames).zip(&theirs) {
        let at = format!("{a:?}");
        // python-can numbers a BLF channel from 0; the file from 1.
        assert_eq!(
            a.bus,
            format!("CAN{}", t["channel"].as_u64().unwrap() + 1),
            "{at}"
        );
        assert_eq!(a.bus, if c.bus == "can0" { "CAN1" } else { "CAN2" }, "{at}");
        assert!(
            (a.stamp_ns as f64 / 1e9 - t["stamp"].as_f64().unwrap()).abs() < 2e-6,
            "{at}: {t}"
        );
        assert!(a.stamp_ns.abs_diff(c.stamp_ns) < 2_000, "{at}: {c:?}");
        if c.error {
            // python-can's BLFWriter keeps an error frame's time and nothing of its class.
            assert!(a.error && t["error"] == true, "{at}: {t}");
            continue;
        }
        for (flag, ours) in [
            ("extended", a.extended),
            ("rtr", a.rtr),
            ("error", a.error),
            ("fd", a.fd),
            ("brs", a.brs),
            ("esi", a.esi),
        ] {
            assert_eq!(t[flag], ours, "{at}: {flag}");
        }
        let data: String = a.data.iter().map(|b| format!("{b:02X}")).collect();
        assert_eq!(t["data"], data, "{at}");
        assert_eq!(t["id"], a.id, "{at}");
        assert_eq!(
            (a.id, a.extended, a.rtr, a.error, &a.data),
            (c.id, c.extended, c.rtr, c.error, &c.data),
            "{at}"
        );
    }
    // Cut off mid-file: the frames before the cut, then where it broke.
    let bytes = std::fs::read(&blf).unwrap();
    let cut = d.path().join("cut.blf");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let read: Vec<_> = railfuse_can::blf::Reader::new(File::open(&cut).unwrap())
        .unwrap()
        .collect();
    let last = read.last().unwrap().as_ref().unwrap_err();
    assert!(last.reason.contains("runs past the end"), "{last}");
    assert!(
        read.len() > frames.len() / 2,
        "the frames of the cut container that are whole: {}",
        read.len()
    );
    // An object claiming 4 GiB is refused without being read.
    let mut huge = bytes[..144].to_vec();
    huge.extend(b"LOBJ\x10\x00\x01\x00\xff\xff\xff\xff\x0a\x00\x00\x00");
    let e = railfuse_can::blf::Reader::new(&huge[..])
        .unwrap()
        .next()
        .unwrap()
        .unwrap_err();
    assert!(e.reason.contains("an object of 4294967295 bytes"), "{e}");
    // Imported: the same frames, decoded.
    let mcap = d.path().join("blf.mcap");
    let dbc = sample("vehicle.dbc");
    let r = ok_json(&[
        "import",
        s(&blf),
        "--dbc",
        s(&dbc),
        "-o",
        s(&mcap),
        "--json",
    ]);
    assert_eq!(r["format"], "blf");
    let n: u64 = ["/can/CAN1/frames", "/can/CAN2/frames"]
        .iter()
        .map(|t| r["per_topic"][t].as_u64().unwrap_or(0))
        .sum();
    assert_eq!(n, frames.len() as u64, "{r}");
}

#[test]
fn odometers_read_as_pulse_generators_off_the_bus_feed_source_002_s_safety_checks_as_their_channels_do(
) {
    let d = tempfile::tempdir().unwrap();
    let (bus, plain) = (d.path().join("bus.mcap"), d.path().join("plain.mcap"));
    simulate(
        &[
            "--scenario",
            "seed002",
            "--seed",
            "2",
            "--duration",
            "300",
            "--can-bus",
        ],
        &bus,
    );
    simulate(
        &["--scenario", "seed002", "--seed", "2", "--duration", "300"],
        &plain,
    );
    // seed002.toml's pipelines under can-pulses.toml's [can] and [sensor] tables.
    let pulses = std::fs::read_to_string(sample("can-pulses.toml")).unwrap();
    let tables = &pulses[pulses.find("\n[can]").unwrap()..pulses.find("\n[[pipeline]]").unwrap()];
    let seed002 = std::fs::read_to_string(sample("seed002.toml")).unwrap();
    let config = d.path().join("seed002-can.toml");
    std::fs::write(&config, format!("{tables}\n{seed002}")).unwrap();
    std::fs::copy(sample("vehicle.dbc"), d.path().join("vehicle.dbc")).unwrap();
    let run = |raw: &Path, config: &Path, out: &str| -> serde_json::Value {
        let o = ok(&[
            "refuse",
            s(raw),
            "-c",
            s(config),
            "-o",
            s(&d.path().join(out)),
            "--json",
        ]);
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let on_bus = run(&bus, &config, "bus.fused.mcap");
    let own = run(&plain, &sample("seed002.toml"), "plain.fused.mcap");
    let made = &on_bus["refuse"]["can"]["made"];
    assert!(made["/odometer/1"].as_u64().unwrap() > 5000, "{made}");
    for name in ["ekf_safety", "ekf_safety_cal"] {
        let (a, b) = (pipeline_eval(&on_bus, name), pipeline_eval(&own, name));
        let availability = |p: &serde_json::Value| p["safety"]["availability"].as_f64().unwrap();
        assert!(
            (availability(&a) - availability(&b)).abs() < 0.01,
            "{name}: {} usable from the bus, {} from the channels",
            availability(&a),
            availability(&b)
        );
        // The pulse-count checks see the same slips and slides.
        let failed = |p: &serde_json::Value, check: &str| {
            p["safety"]["checks"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["check"] == check)
                .map_or(0, |c| c["failed_epochs"].as_u64().unwrap())
        };
        for check in ["s1_axle_1", "s1_axle_2", "s5_odometry"] {
            let (x, y) = (failed(&a, check), failed(&b, check));
            assert!(
                x.abs_diff(y) <= y / 10 + 5,
                "{name} {check}: {x} epochs from the bus, {y} from the channels"
            );
        }
    }
}
