//! `railfuse record` over real byte paths: UDP and TCP on loopback, standard input, NMEA and UBX
//! files, garbage on every one of them; clean stop on SIGTERM; SIGKILL then `recover`.

mod common;

use std::io::Write;
use std::net::{TcpStream, UdpSocket};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::live::*;
use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{GnssFix, RadarSpeed};

/// Speeds of every /radar/speed message, in file order, and the recorder's own diagnostics.
fn radar_speeds(path: &std::path::Path) -> (Vec<f64>, usize) {
    let (mut v, mut diags) = (Vec::new(), 0);
    let mut r = LogReader::open(path).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec.unwrap() {
            match m.channel.topic.as_str() {
                "/radar/speed" => v.push(m.decode::<RadarSpeed>(path).unwrap().speed_mps),
                "/recorder/diagnostics" => diags += 1,
                _ => {}
            }
        }
    }
    (v, diags)
}

fn gnss_fixes(path: &std::path::Path) -> Vec<GnssFix> {
    messages(path, "/gnss/fix")
}

#[test]
fn udp_and_tcp_json_lines_arrive_once_in_order_and_garbage_is_counted() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("net.mcap");
    let (udp, tcp) = (free_port(), free_port());
    let child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--udp",
        &udp.to_string(),
        "--tcp",
        &tcp.to_string(),
        "--json",
    ]);
    wait_listening(tcp);
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut conn = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
    for k in 0..2000 {
        sock.send_to(radar_line(k).as_bytes(), ("127.0.0.1", udp))
            .unwrap();
        if k % 200 == 0 {
            sock.send_to(b"\x00\x01 binary noise \xff", ("127.0.0.1", udp))
                .unwrap();
            conn.write_all(b"{\"topic\": 42}\n").unwrap();
            conn.write_all(&vec![b'x'; 70_000]).unwrap();
            conn.write_all(b"\n").unwrap();
        }
        conn.write_all(format!("{}\n", radar_line(10_000 + k)).as_bytes())
            .unwrap();
        if k % 100 == 0 {
            std::thread::sleep(Duration::from_millis(2)); // a UDP sender paces itself
        }
    }
    drop(conn);
    std::thread::sleep(Duration::from_millis(500));
    let r = stop(child);
    assert_eq!(r["stopped_by"], "signal");
    let (v, diags) = radar_speeds(&out);
    let udp_got: Vec<f64> = v.iter().copied().filter(|x| *x < 10_000.0).collect();
    let tcp_got: Vec<f64> = v.iter().copied().filter(|x| *x >= 10_000.0).collect();
    assert_eq!(
        tcp_got,
        (0..2000).map(|k| (10_000 + k) as f64).collect::<Vec<_>>(),
        "TCP: every line once, in order"
    );
    assert_eq!(
        udp_got,
        (0..2000).map(|k| k as f64).collect::<Vec<_>>(),
        "UDP on loopback: every datagram once, in order"
    );
    let src = r["sources"].as_array().unwrap();
    assert_eq!(src[0]["malformed"], 10, "{r}");
    assert_eq!(
        (src[1]["malformed"].as_u64(), src[1]["oversized"].as_u64()),
        (Some(10), Some(10)),
        "{r}"
    );
    assert!(diags >= 1);
}

#[test]
fn nmea_and_ubx_files_and_stdin_record_their_fixes_and_count_bad_checksums() {
    let d = tempfile::tempdir().unwrap();
    let (nmea, ubx) = captures(d.path());
    let out = d.path().join("files.mcap");
    let mut child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--file",
        &format!("{}:nmea", s(&nmea)),
        "--file",
        s(&ubx),
        "--stdin",
        "json",
        "--json",
    ]);
    let mut stdin = child.stdin.take().unwrap();
    for k in 0..100 {
        writeln!(stdin, "{}", radar_line(k)).unwrap();
    }
    drop(stdin); // end of input: with the files read too, every source has ended
    let out_json = child.wait_with_output().unwrap();
    assert!(
        out_json.status.success(),
        "{}",
        String::from_utf8_lossy(&out_json.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out_json.stdout).unwrap();
    assert_eq!(r["stopped_by"], "every source ended", "{r}");
    let src = r["sources"].as_array().unwrap();
    assert_eq!(
        (
            src[0]["written"].as_u64(),
            src[0]["checksum_failures"].as_u64(),
            src[0]["malformed"].as_u64()
        ),
        (Some(50), Some(50), Some(50)),
        "{r}"
    );
    assert_eq!(
        src[1]["written"], 1,
        "one NAV-PVT (+ its NAV-COV) in the sample: {r}"
    );
    assert!(src[1]["checksum_failures"].as_u64().unwrap() >= 1, "{r}");
    assert_eq!(src[2]["written"], 100);
    let fixes = gnss_fixes(&out);
    assert_eq!(fixes.len(), 51);
    // GNSS time is the sensor time: 2022-10-20 08:35 UTC for the NMEA fixes.
    assert!(
        fixes
            .iter()
            .filter(|f| f.satellites == 12)
            .all(|f| f.stamp_ns / 1_000_000_000 / 3600 == 1_666_254_900 / 3600),
        "{:?}",
        fixes[0]
    );
    assert!(fixes
        .iter()
        .any(|f| f.satellites == 29 && (f.latitude_deg.unwrap() - 44.6551106).abs() < 1e-7));
}

#[test]
fn a_recorder_killed_with_sigkill_loses_at_most_its_last_second_and_recover_gets_the_rest() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("killed.mcap");
    let partial = killed_recording(&out, 3000);
    let fixed = d.path().join("fixed.mcap");
    let r: serde_json::Value = ok_json(&["recover", s(&partial), "-o", s(&fixed), "--json"]);
    let (v, _) = radar_speeds(&fixed);
    assert_eq!(
        v,
        (0..3000).map(|k| k as f64).collect::<Vec<_>>(),
        "everything sent before the last closed chunk: {r}"
    );
    // The official Python reader reads the salvage and validates every message.
    let py = python_ok("check_mcap.py", &[s(&fixed)]);
    assert_eq!(py["topics"]["/radar/speed"], 3000, "{py}");
}

#[test]
fn nmea_and_ubx_over_pseudo_terminals_at_set_bauds_arrive_with_their_values() {
    let (mut m, slave, tty) = pty();
    let (mut mu, slave_u, tty_u) = pty();
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("serial.mcap");
    let (_, ubx) = captures(d.path());
    let child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--serial",
        &format!("{tty}:115200:nmea"),
        "--serial",
        &format!("{tty_u}:460800:ubx=/gnss/rx2"),
        "--json",
    ]);
    std::thread::sleep(Duration::from_millis(500));
    for chunk in std::fs::read(&ubx).unwrap().chunks(7) {
        mu.write_all(chunk).unwrap();
    }
    for k in 0..20 {
        for body in [
            format!("GNRMC,0900{k:02}.00,A,4439.30664,N,01055.78382,E,20.0,45.0,201022,,,R,V"),
            format!(
                "GNGGA,0900{k:02}.00,4439.30664,N,01055.78382,E,4,1{},0.58,35.2,M,44.1,M,1.0,0000",
                k % 10
            ),
        ] {
            let cs = body.bytes().fold(0u8, |a, x| a ^ x);
            m.write_all(format!("${body}*{cs:02X}\r\n").as_bytes())
                .unwrap();
        }
        m.write_all(b"$GNGGA,bad*00\r\n").unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    let r = stop(child);
    drop((slave, slave_u));
    let src = &r["sources"][0];
    assert_eq!(
        (src["written"].as_u64(), src["checksum_failures"].as_u64()),
        (Some(20), Some(20)),
        "{r}"
    );
    // The UBX receiver, mapped to its own channel: the sample's NAV-PVT with 29 satellites.
    assert_eq!(r["sources"][1]["written"], 1, "{r}");
    assert_eq!(r["per_topic"]["/gnss/rx2"], 1, "{r}");
    let fixes = gnss_fixes(&out);
    let sats: Vec<u8> = fixes.iter().map(|f| f.satellites).collect();
    assert_eq!(
        sats,
        (0..20).map(|k| 10 + (k % 10) as u8).collect::<Vec<_>>(),
        "in order, once each"
    );
    assert!((fixes[0].speed_mps.unwrap() - 20.0 * 1852.0 / 3600.0).abs() < 1e-9);
}

#[test]
fn nmea_and_ubx_captures_import_with_their_bad_sentences_counted() {
    let d = tempfile::tempdir().unwrap();
    let (nmea, ubx) = captures(d.path());
    let (a, b) = (d.path().join("a.mcap"), d.path().join("b.mcap"));
    let r: serde_json::Value = ok_json(&[
        "import",
        "--format",
        "nmea",
        s(&nmea),
        "-o",
        s(&a),
        "--json",
    ]);
    assert_eq!(
        (
            r["messages"].as_u64(),
            r["skipped"]["NMEA checksum failure"].as_u64(),
            r["skipped"]["not an NMEA sentence"].as_u64()
        ),
        (Some(50), Some(50), Some(50)),
        "{r}"
    );
    let fixes = gnss_fixes(&a);
    assert!(fixes.iter().all(
        |f| f.fix_type == railfuse_catalog::messages::FixType::RtkFixed && f.satellites == 12
    ));
    let r: serde_json::Value =
        ok_json(&["import", "--format", "ubx", s(&ubx), "-o", s(&b), "--json"]);
    assert_eq!(r["messages"], 1, "{r}");
    assert_eq!(gnss_fixes(&b)[0].satellites, 29);
}

#[test]
fn nmea_fixes_before_the_date_wait_for_it_or_take_date_and_are_never_stamped_1970() {
    let d = tempfile::tempdir().unwrap();
    let gga = |s: u32| {
        format!("GNGGA,0835{s:02}.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000")
    };
    let rmc =
        |s: u32| format!("GNRMC,0835{s:02}.00,A,4439.30664,N,01055.78382,E,10.0,90.0,201022,,,R,V");
    // 2022-10-20 08:35:00 UTC
    let t0 = 1_666_254_900u64 * 1_000_000_000;
    let stamps = |path: &std::path::Path| -> Vec<u64> {
        gnss_fixes(path).iter().map(|f| f.stamp_ns).collect()
    };
    // Each second a GGA, then the RMC: the first GGA has no date when it arrives.
    let first_gga = d.path().join("gga-first.nmea");
    let bodies: Vec<String> = (0..10).flat_map(|s| [gga(s), rmc(s)]).collect();
    std::fs::write(&first_gga, nmea_text(&bodies)).unwrap();
    let out = d.path().join("a.mcap");
    ok(&["import", "--format", "nmea", s(&first_gga), "-o", s(&out)]);
    let want: Vec<u64> = (0..10).map(|s| t0 + s * 1_000_000_000).collect();
    assert_eq!(stamps(&out), want);
    // No RMC or ZDA at all: nothing can be dated, so nothing is stamped 1970; --date dates it.
    let no_date = d.path().join("gga-only.nmea");
    std::fs::write(&no_date, nmea_text(&(0..10).map(gga).collect::<Vec<_>>())).unwrap();
    let o = railfuse(&["import", "--format", "nmea", s(&no_date), "-o", s(&out)]);
    assert!(!o.status.success());
    let undated = "10 × NMEA fixes with no date (no RMC/ZDA after them; give --date)";
    assert!(stderr(&o).contains(undated), "{}", stderr(&o));
    let args = [
        "import",
        "--format",
        "nmea",
        "--date",
        "2022-10-20",
        s(&no_date),
        "-o",
        s(&out),
    ];
    ok(&args);
    assert_eq!(stamps(&out), want);
    let bad = railfuse(&[
        "import",
        "--format",
        "nmea",
        "--date",
        "20.10.2022",
        s(&no_date),
        "-o",
        s(&out),
    ]);
    assert!(!bad.status.success() && stderr(&bad).contains("is not a date YYYY-MM-DD"));
}

#[test]
fn a_recording_splits_into_numbered_complete_files_carrying_the_run_metadata() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("run.mcap");
    let meta = d.path().join("run.toml");
    std::fs::write(
        &meta,
        "train = \"ETR103\"\noperator = \"test bench\"\nnotes = \"split test\"\n",
    )
    .unwrap();
    let o = ok(&[
        "record",
        "-o",
        s(&out),
        "--speed",
        "40",
        "--duration",
        "3.5",
        "--split-every",
        "1",
        "--meta-file",
        s(&meta),
        "--meta",
        "operator=override",
        "--json",
    ]);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let files: Vec<std::path::PathBuf> = r["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().into())
        .collect();
    assert!(files.len() >= 3, "{r}");
    assert_eq!(files[0].file_name().unwrap(), "run-001.mcap");
    for f in &files {
        let info: serde_json::Value = ok_json(&["info", s(f), "--json"]);
        let run = info["metadata"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m[0] == "railfuse.run")
            .unwrap()
            .clone();
        let text = run.to_string();
        assert!(
            text.contains("ETR103") && text.contains("override") && text.contains("\"part\""),
            "{text}"
        );
    }
    // The folder is the run (its manifest, metadata.yaml): every message once, the state
    // each part repeats read as the repeats they are.
    let info = ok_json(&["info", s(d.path()), "--json"]);
    assert_eq!(info["files"].as_array().unwrap().len(), files.len());
    assert_eq!(
        received(&info),
        r["messages"].as_u64().unwrap(),
        "every message once"
    );
}

/// Messages the recorder received in an `info --json`: not its diagnostics, nor the Foxglove
/// twins it adds.
fn received(info: &serde_json::Value) -> u64 {
    info["channels"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| {
            let topic = c["topic"].as_str().unwrap();
            topic != "/recorder/diagnostics" && !topic.starts_with("/foxglove/")
        })
        .map(|c| c["messages"].as_u64().unwrap())
        .sum::<u64>()
}

#[test]
fn every_part_of_a_split_recording_opens_with_the_run_s_state_and_a_manifest() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("run.mcap");
    let o = ok(&[
        "record",
        "-o",
        s(&out),
        "--speed",
        "40",
        "--duration",
        "4",
        "--split-every",
        "1",
        "--json",
    ]);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let files: Vec<String> = r["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_owned())
        .collect();
    assert!(files.len() >= 3, "{r}");
    // Each part after the first opens with the track map and the last of every channel.
    for f in &files[1..] {
        let maps: Vec<railfuse_catalog::messages::TrackMap> =
            messages(std::path::Path::new(f), "/track/map");
        assert_eq!(maps.len(), 1, "{f}: the track map repeated");
        let first = ok_json(&["info", f, "--json"]);
        let topics = first["channels"].as_array().unwrap().len();
        assert!(topics >= 8, "{f}: {topics} channels");
    }
    // The manifest lists every part with the times of its own messages.
    let manifest = std::fs::read_to_string(d.path().join("metadata.yaml")).unwrap();
    for f in &files {
        let name = std::path::Path::new(f)
            .file_name()
            .unwrap()
            .to_str()
            .unwrap();
        assert!(manifest.contains(&format!("\"{name}\"")), "{manifest}");
    }
    let run = ok_json(&["info", s(d.path()), "--json"]);
    assert_eq!(received(&run), r["messages"].as_u64().unwrap());
    // A part re-fused alone starts from the state it repeats: its default pipeline finds
    // the track map and so takes chainage from the GNSS fixes from its first one.
    let alone = ok(&[
        "refuse",
        &files[1],
        "-o",
        s(&d.path().join("alone.fused.mcap")),
    ]);
    let said = stderr(&alone);
    assert!(
        said.contains("uses /gnss/fix: railfuse.GnssFix: GNSS fixes, their chainage on the track"),
        "{said}"
    );
}

#[test]
fn a_split_recording_cut_off_opens_as_its_parts_and_names_the_one_to_recover() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("run.mcap");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args([
            "record",
            "-o",
            s(&out),
            "--speed",
            "20",
            "--split-every",
            "1",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Killed (no chance to finish) once three parts are done.
    let done = |n: u32| d.path().join(format!("run-{n:03}.mcap")).exists();
    let started = std::time::Instant::now();
    while !done(3) && started.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let manifest = std::fs::read_to_string(d.path().join("metadata.yaml")).unwrap();
    assert!(manifest.contains("run-003.mcap"), "{manifest}");
    let cut = (1..)
        .find(|&n| !done(n))
        .map(|n| format!("run-{n:03}.mcap"))
        .unwrap();
    let whole = railfuse(&["info", s(d.path())]);
    let e = stderr(&whole);
    assert!(!whole.status.success());
    assert!(
        e.contains(&cut) && e.contains("railfuse recover") && e.contains("--allow-missing-parts"),
        "{e}"
    );
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    ok(&["info", s(d.path()), "--allow-missing-parts"]);
    let partial = d.path().join(format!("{cut}.partial"));
    ok(&["recover", s(&partial), "-o", s(&d.path().join(&cut))]);
    ok(&["info", s(d.path())]);
}

#[test]
fn a_full_disk_stops_the_recorder_with_one_line_that_says_so() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("full.mcap");
    // Every write to the recording's file fails as on a full disk.
    std::os::unix::fs::symlink("/dev/full", d.path().join("full.mcap.partial")).unwrap();
    let o = railfuse(&["record", "-o", s(&out), "--speed", "20", "--duration", "2"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("No space left on device") && err.contains("full.mcap.partial"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn a_disk_filling_mid_recording_keeps_every_closed_chunk() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("filling.mcap");
    let partial = d.path().join("filling.mcap.partial");
    let udp = free_port();
    // A file-size limit makes the disk "fill" after 48 KiB: writes then fail (EFBIG) part-way
    // through a chunk, as they do with ENOSPC on a real disk.
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_railfuse"));
    cmd.args([
        "record",
        "-o",
        s(&out),
        "--udp",
        &udp.to_string(),
        "--chunk-interval",
        "0.2",
    ])
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(&mut cmd, || {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let lim = libc::rlimit {
                rlim_cur: 48 * 1024,
                rlim_max: 48 * 1024,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        })
    };
    let mut child = cmd.spawn().unwrap();
    std::thread::sleep(Duration::from_millis(700));
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    let t = Instant::now();
    let mut k = 0;
    while child.try_wait().unwrap().is_none() {
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "the recorder never hit the size limit after {k} messages"
        );
        for _ in 0..50 {
            let _ = sock.send_to(radar_line(k).as_bytes(), ("127.0.0.1", udp));
            k += 1;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("File too large") && err.contains("recover") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!out.exists() && partial.exists());
    let fixed = d.path().join("fixed.mcap");
    let r: serde_json::Value = ok_json(&["recover", s(&partial), "-o", s(&fixed), "--json"]);
    let (v, diags) = radar_speeds(&fixed);
    // What was written before the disk filled is all there, in order, with nothing missing.
    assert!(
        v.len() >= 500 && diags >= 1,
        "{} messages, {diags} diagnostics: {r}",
        v.len()
    );
    assert_eq!(v, (0..v.len()).map(|k| k as f64).collect::<Vec<_>>(), "{r}");
}

#[test]
fn a_source_that_cannot_start_is_said_at_once_and_fails_the_run_but_not_the_others() {
    let d = tempfile::tempdir().unwrap();
    let (nmea, _) = captures(d.path());
    // The port is taken: that UDP source cannot bind.
    let taken = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let out = d.path().join("some.mcap");
    let missing = d.path().join("missing.nmea");
    let o = railfuse(&[
        "record",
        "-o",
        s(&out),
        "--udp",
        &port,
        "--file",
        s(&missing),
        "--file",
        &format!("{}:nmea", s(&nmea)),
        "--json",
    ]);
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("warning: source failed")
            && err.contains("Address already in use")
            && err.contains("missing.nmea: No such file"),
        "{err}"
    );
    assert!(
        err.contains("2 of 3 sources failed") && !err.contains("panicked"),
        "{err}"
    );
    // The healthy source recorded everything, into a finished file.
    assert_eq!(gnss_fixes(&out).len(), 50);
}

#[test]
fn sources_come_from_a_toml_file_too() {
    let d = tempfile::tempdir().unwrap();
    let (nmea, _) = captures(d.path());
    let udp = free_port();
    let cfg = d.path().join("sources.toml");
    std::fs::write(&cfg, format!("[[source]]\nudp = {udp}\n\n[[source]]\nfile = \"{}\"\nformat = \"nmea\"\ntopic = \"/gnss/rx2\"\n", s(&nmea))).unwrap();
    let out = d.path().join("cfg.mcap");
    let child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--sources",
        s(&cfg),
        "--duration",
        "2",
        "--json",
    ]);
    std::thread::sleep(Duration::from_millis(700));
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    for k in 0..10 {
        sock.send_to(radar_line(k).as_bytes(), ("127.0.0.1", udp))
            .unwrap();
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (
            r["per_topic"]["/gnss/rx2"].as_u64(),
            r["per_topic"]["/radar/speed"].as_u64()
        ),
        (Some(50), Some(10)),
        "{r}"
    );
    std::fs::write(&cfg, "[[source]]\nudp = 1\ntcp = 2\n").unwrap();
    let bad = railfuse(&["record", "-o", s(&out), "--sources", s(&cfg)]);
    assert!(
        !bad.status.success() && stderr(&bad).contains("give exactly one of"),
        "{}",
        stderr(&bad)
    );
}
