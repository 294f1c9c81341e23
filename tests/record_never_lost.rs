//! A recording is never lost: not to one bad line, not to `recover`, not to a restart, not
//! to a stop under load or a listener out of file descriptors; and every GNSS fix carries its
//! own epoch. Each test makes a recording, throws a bad line or a crash at it, and counts the
//! messages afterwards.

mod common;

use std::io::Write;
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::live::*;
use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{FixType, GnssFix, RadarSpeed};

/// The line: a non-ASCII character in a GGA field, with a checksum that is right.
const NON_ASCII_GGA: &str = "$GPGGA,2é5959.00,4807.038,S,01131.000,W,1,08,0.9,545.4,M,46.9,M,,*33";

/// `n` epochs of a receiver (GGA, then its RMC, GSA and GST) one second apart from 08:00:00.
fn epochs(first: u32, n: u32) -> String {
    let mut bodies = Vec::new();
    for k in first..first + n {
        let t = format!("08{:02}{:02}.00", k / 60, k % 60);
        bodies.push(format!(
            "GNGGA,{t},4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000"
        ));
        bodies.push(format!(
            "GNRMC,{t},A,4439.30664,N,01055.78382,E,10.0,90.0,201022,,,R,V"
        ));
        bodies.push("GNGSA,A,3,01,02,03,04,05,,,,,,,,1.2,0.6,1.0".into());
        bodies.push(format!("GNGST,{t},0.45,0.020,0.015,77.4,0.018,0.017,0.031"));
    }
    nmea_text(&bodies)
}

fn json(out: &std::process::Output) -> serde_json::Value {
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_non_ascii_byte_in_an_nmea_field_is_counted_by_import_and_record_and_loses_nothing() {
    let d = tempfile::tempdir().unwrap();
    let capture = d.path().join("rx.nmea");
    let text = format!("{}{NON_ASCII_GGA}\r\n{}", epochs(0, 30), epochs(30, 30));
    std::fs::write(&capture, &text).unwrap();
    let out = d.path().join("imported.mcap");
    let r = json(&ok(&[
        "import",
        "--format",
        "nmea",
        s(&capture),
        "-o",
        s(&out),
        "--json",
    ]));
    assert_eq!(r["messages"], 60, "{r}");
    assert_eq!(r["lines"], 241, "{r}");
    assert_eq!(
        r["skipped"]["NMEA sentence with a non-ASCII byte"], 1,
        "{r}"
    );
    assert_eq!(
        r["first_problems"][0], "line 121: NMEA sentence with a byte that is not ASCII",
        "{r}"
    );
    assert_eq!(gnss_fixes_in(&out).len(), 60);

    // The same bytes to a live recorder over TCP: the source goes on, the file is finished.
    let rec = d.path().join("live.mcap");
    let r = record_nmea_over_tcp(text.as_bytes(), &rec);
    let src = &r["sources"][0];
    assert_eq!(
        src["skipped"]["NMEA sentence with a non-ASCII byte"], 1,
        "{r}"
    );
    assert_eq!(src["written"], 60, "{r}");
    assert_eq!(gnss_fixes_in(&rec).len(), 60);
}

/// `bytes` sent in one go to a live recorder's NMEA TCP listener recording to `rec`; its
/// closing report.
fn record_nmea_over_tcp(bytes: &[u8], rec: &std::path::Path) -> serde_json::Value {
    let tcp = free_port();
    let child = spawn(&[
        "record",
        "-o",
        s(rec),
        "--tcp",
        &format!("{tcp}:nmea"),
        "--json",
    ]);
    wait_listening(tcp);
    let mut conn = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
    conn.write_all(bytes).unwrap();
    drop(conn);
    std::thread::sleep(Duration::from_millis(500));
    stop(child)
}

fn gnss_fixes_in(path: &std::path::Path) -> Vec<GnssFix> {
    messages(path, "/gnss/fix")
}

#[test]
fn fixes_across_midnight_and_the_new_year_take_their_own_epochs_date_and_covariance() {
    let d = tempfile::tempdir().unwrap();
    let capture = d.path().join("midnight.nmea");
    let mut bodies = Vec::new();
    for (t, date) in [
        ("235958", "311224"),
        ("235959", "311224"),
        ("000000", "010125"),
        ("000001", "010125"),
    ] {
        // The date (RMC), the fix mode (GSA) and the covariance (GST) all after the GGA.
        bodies.push(format!(
            "GPGGA,{t}.00,0000.500,S,00000.300,W,1,08,0.9,5.4,M,46.9,M,,"
        ));
        bodies.push(format!(
            "GPRMC,{t}.00,A,0000.500,S,00000.300,W,0.1,,{date},,,A"
        ));
        bodies.push("GPGSA,A,3,01,02,03,04,,,,,,,,,1.5,0.9,1.2".into());
        bodies.push(format!(
            "GPGST,{t}.00,0.45,0.020,0.015,77.4,1.{},2.5,3.5",
            &t[5..]
        ));
    }
    std::fs::write(&capture, nmea_text(&bodies)).unwrap();
    let out = d.path().join("midnight.mcap");
    ok(&["import", "--format", "nmea", s(&capture), "-o", s(&out)]);
    let fixes = gnss_fixes_in(&out);
    let new_year = 1_735_689_600_000_000_000u64;
    let stamps: Vec<i64> = fixes
        .iter()
        .map(|f| f.stamp_ns as i64 - new_year as i64)
        .collect();
    assert_eq!(stamps, [-2_000_000_000, -1_000_000_000, 0, 1_000_000_000]);
    for (f, sigma_lat) in fixes.iter().zip([1.8, 1.9, 1.0, 1.1]) {
        assert_eq!(f.fix_type, FixType::Single);
        let c = f.position_covariance_enu_m2.unwrap();
        assert!((c[4] - f64::powi(sigma_lat, 2)).abs() < 1e-9, "{f:?}");
        // South and west of (0, 0): the signs of the hemispheres.
        assert!(f.latitude_deg.unwrap() < 0.0 && f.longitude_deg.unwrap() < 0.0);
        assert_eq!(
            (f.altitude_m, f.altitude_msl_m),
            (Some(5.4 + 46.9), Some(5.4))
        );
    }
}

fn radar_count(path: &std::path::Path) -> usize {
    messages::<RadarSpeed>(path, "/radar/speed").len()
}

#[test]
fn recover_as_the_readme_writes_it_gets_the_recording_back_and_never_touches_its_input() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("c3.mcap");
    let partial = killed_recording(&out, 3000);
    let before = std::fs::read(&partial).unwrap();
    // The README's command: the output's own `.partial` is the input.
    let r = json(&ok(&["recover", s(&partial), "-o", s(&out), "--json"]));
    assert_eq!(radar_count(&out), 3000, "{r}");
    assert_eq!(
        std::fs::read(&partial).unwrap(),
        before,
        "the input changed"
    );
    // The input itself, or a hard link to it, as the output: refused in one line, untouched.
    let o = railfuse(&["recover", s(&partial), "-o", s(&partial)]);
    let err = stderr(&o);
    assert!(!o.status.success() && err.lines().count() == 1, "{err}");
    assert!(err.contains("is the input"), "{err}");
    let link = d.path().join("link.mcap");
    std::fs::hard_link(&partial, &link).unwrap();
    let o = railfuse(&["recover", s(&partial), "-o", s(&link)]);
    assert!(
        !o.status.success() && stderr(&o).contains("is the input"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read(&partial).unwrap(),
        before,
        "the input changed"
    );
}

#[test]
fn record_moves_an_unrecovered_partial_aside_and_says_where() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("again.mcap");
    let partial = killed_recording(&out, 500);
    let before = std::fs::read(&partial).unwrap();
    let o = ok(&["record", "-o", s(&out), "--speed", "20", "--duration", "1"]);
    let aside = d.path().join("again-unrecovered-1.mcap.partial");
    let err = stderr(&o);
    assert!(
        err.contains(&format!("moved to {}", aside.display())),
        "{err}"
    );
    assert_eq!(std::fs::read(&aside).unwrap(), before);
    assert!(out.exists());
    // And what was moved aside still recovers, as the line says.
    let salvaged = d.path().join("again-unrecovered-1.mcap");
    ok(&["recover", s(&aside), "-o", s(&salvaged)]);
    assert_eq!(radar_count(&salvaged), 500);
}

#[test]
fn a_stop_drains_what_tcp_senders_had_already_sent() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("drained.mcap");
    let tcp = free_port();
    let child = spawn(&["record", "-o", s(&out), "--tcp", &tcp.to_string(), "--json"]);
    wait_listening(tcp);
    let mut conn = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
    let n = 100_000;
    let mut text = String::new();
    for k in 0..n {
        text += &radar_line(k);
        text.push('\n');
    }
    conn.write_all(text.as_bytes()).unwrap();
    // Everything is sent (much of it still in the sockets' buffers): stop at once.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["per_topic"]["/radar/speed"], n, "{r}");
    assert_eq!(radar_count(&out), n);
}

/// CPU time (user + system) of process `pid` so far, in clock ticks.
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .unwrap()
        .1
        .split_whitespace()
        .collect();
    fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap()
}

#[test]
fn a_listener_out_of_file_descriptors_backs_off_says_so_at_once_and_accepts_again() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("fds.mcap");
    let tcp = free_port();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_railfuse"));
    cmd.args(["record", "-o", s(&out), "--tcp", &tcp.to_string(), "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit only, between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 40,
                rlim_max: 40,
            };
            libc::setrlimit(libc::RLIMIT_NOFILE, &lim);
            Ok(())
        });
    }
    let child = cmd.spawn().unwrap();
    wait_listening(tcp);
    let crowd: Vec<TcpStream> = (0..60)
        .filter_map(|_| TcpStream::connect(("127.0.0.1", tcp)).ok())
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let (t0, ticks0) = (Instant::now(), cpu_ticks(child.id()));
    std::thread::sleep(Duration::from_secs(2));
    let busy = (cpu_ticks(child.id()) - ticks0) as f64 / 100.0 / t0.elapsed().as_secs_f64();
    assert!(
        busy < 0.5,
        "the accept loop spins: {:.0} % of a core",
        busy * 100.0
    );
    drop(crowd);
    std::thread::sleep(Duration::from_millis(1500));
    let mut good = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
    for k in 0..10 {
        good.write_all(format!("{}\n", radar_line(k)).as_bytes())
            .unwrap();
    }
    std::thread::sleep(Duration::from_millis(800));
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("cannot accept a connection"), "{err}");
    assert_eq!(radar_count(&out), 10, "{err}");
}

#[test]
fn a_full_disk_in_a_split_recording_names_the_part_and_counts_only_what_reached_it() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("run.mcap");
    std::os::unix::fs::symlink("/dev/full", d.path().join("run-002.mcap.partial")).unwrap();
    let o = railfuse(&[
        "record",
        "-o",
        s(&out),
        "--speed",
        "20",
        "--duration",
        "6",
        "--split-size",
        "0.5",
        "--chunk-interval",
        "0.2",
        "--json",
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("run-002.mcap.partial") && !err.contains("/run.mcap.partial"),
        "{err}"
    );
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // What the report says was written is what part 1 holds (part 2 got nothing).
    let part1 = d.path().join("run-001.mcap");
    let mut in_part1 = 0u64;
    let mut reader = LogReader::open(&part1).unwrap();
    while let Some(rec) = reader.next() {
        if let LogRecord::Message(m) = rec.unwrap() {
            // The sources' messages (not the recorder's health, nor Foxglove twins of them).
            in_part1 += u64::from(r["per_topic"].get(&m.channel.topic).is_some());
        }
    }
    assert_eq!(r["messages"].as_u64(), Some(in_part1), "{r}");
    // Part 2 fails as it opens (the run's state repeated into it), before a message of its
    // own is taken: the report names it, and nothing taken is lost.
    assert!(
        r["failed_file"].as_str().unwrap().ends_with("run-002.mcap"),
        "{r}"
    );
    assert_eq!(r["lost_to_write_error"].as_u64(), Some(0), "{r}");
}

/// `a` and `b` equal within `tol` (both absent counts as equal).
fn close(a: Option<f64>, b: &serde_json::Value, tol: f64) -> bool {
    match (a, b.as_f64()) {
        (None, None) => true,
        (Some(x), Some(y)) => (x - y).abs() <= tol,
        _ => false,
    }
}

/// Field-by-field mismatches of railfuse's fixes against the protocol library's.
fn mismatches(fixes: &[GnssFix], expected: &[serde_json::Value], ubx: bool) -> Vec<String> {
    let mut bad = Vec::new();
    if fixes.len() != expected.len() {
        bad.push(format!(
            "{} fixes where the library reads {}",
            fixes.len(),
            expected.len()
        ));
    }
    for (k, (f, e)) in fixes.iter().zip(expected).enumerate() {
        let course = f.course_rad.map(f64::to_degrees);
        let checks = [
            ("stamp", f.stamp_ns == e["stamp_ns"].as_u64().unwrap()),
            (
                "fix",
                f.fix_type.has_position() == e["has_position"].as_bool().unwrap(),
            ),
            ("latitude", close(f.latitude_deg, &e["latitude_deg"], 1e-9)),
            (
                "longitude",
                close(f.longitude_deg, &e["longitude_deg"], 1e-9),
            ),
            ("height", close(f.altitude_m, &e["altitude_m"], 1e-9)),
            (
                "MSL height",
                close(f.altitude_msl_m, &e["altitude_msl_m"], 1e-9),
            ),
            (
                "satellites",
                u64::from(f.satellites) == e["satellites"].as_u64().unwrap(),
            ),
            ("speed", close(f.speed_mps, &e["speed_mps"], 1e-9)),
            ("course", close(course, &e["course_deg"], 1e-9)),
        ];
        for (what, _) in checks.iter().filter(|(_, ok)| !ok) {
            bad.push(format!("fix {k}: {what}: {f:?} against {e}"));
        }
        let cov = f.position_covariance_enu_m2;
        let want = if ubx {
            &e["covariance_enu"]
        } else {
            &e["sigmas"]
        };
        let same_cov = match (cov, want.as_array()) {
            (None, None) => true,
            (Some(c), Some(w)) if ubx => c.iter().zip(w).all(|(x, y)| close(Some(*x), y, 1e-6)),
            (Some(c), Some(w)) => {
                let sd = |i: usize| c[i].sqrt();
                close(Some(sd(4)), &w[0], 1e-12)
                    && close(Some(sd(0)), &w[1], 1e-12)
                    && close(Some(sd(8)), &w[2], 1e-12)
            }
            _ => false,
        };
        if !same_cov {
            bad.push(format!("fix {k}: covariance {cov:?} against {want}"));
        }
    }
    bad
}

#[test]
fn nmea_and_ubx_fixes_match_pynmeagps_and_pyubx2_field_by_field_across_midnight_and_the_equator() {
    let d = tempfile::tempdir().unwrap();
    let py = python("gnss_protocols.py", &[s(d.path())]);
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let expected: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("expected.json")).unwrap()).unwrap();
    for (format, file) in [("nmea", "rx.nmea"), ("ubx", "rx.ubx")] {
        let out = d.path().join(format!("{format}.mcap"));
        let r = json(&ok(&[
            "import",
            "--format",
            format,
            s(&d.path().join(file)),
            "-o",
            s(&out),
            "--json",
        ]));
        let want = expected[format].as_array().unwrap();
        let bad = mismatches(&gnss_fixes_in(&out), want, format == "ubx");
        assert!(
            bad.is_empty(),
            "{format}: {} mismatches, first: {:?}\n{r}",
            bad.len(),
            &bad[..bad.len().min(5)]
        );
        // Every bad line or frame is counted under its reason, with where it was.
        let skipped = r["skipped"].as_object().unwrap();
        assert!(
            !skipped.is_empty() && !r["first_problems"].as_array().unwrap().is_empty(),
            "{r}"
        );

        // The same bytes to a live recorder over TCP, in reads of every size: the same
        // fixes, and the same counts under the same reasons.
        let tcp = free_port();
        let rec = d.path().join(format!("{format}-live.mcap"));
        let child = spawn(&[
            "record",
            "-o",
            s(&rec),
            "--tcp",
            &format!("{tcp}:{format}"),
            "--json",
        ]);
        wait_listening(tcp);
        let mut conn = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
        conn.set_nodelay(true).unwrap();
        let bytes = std::fs::read(d.path().join(file)).unwrap();
        let mut at = 0;
        for n in (1..).map(|k| 1 + (k * 7919) % 97) {
            let end = (at + n).min(bytes.len());
            conn.write_all(&bytes[at..end]).unwrap();
            at = end;
            if at == bytes.len() {
                break;
            }
        }
        drop(conn);
        std::thread::sleep(Duration::from_millis(800));
        let live = stop(child);
        let src = &live["sources"][0];
        assert_eq!(
            src["skipped"].as_object(),
            Some(skipped),
            "import: {r}\nrecord: {live}"
        );
        assert_eq!(src["written"].as_u64(), r["messages"].as_u64(), "{live}");
    }
}

#[test]
fn a_listener_serves_at_most_its_connection_cap_and_counts_the_rest() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("crowd.mcap");
    let tcp = free_port();
    let child = spawn(&["record", "-o", s(&out), "--tcp", &tcp.to_string(), "--json"]);
    wait_listening(tcp);
    let crowd: Vec<TcpStream> = (0..70)
        .map(|k| {
            let mut c = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
            c.write_all(format!("{}\n", radar_line(k)).as_bytes())
                .unwrap();
            std::thread::sleep(Duration::from_millis(20)); // accepted in order
            c
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let r = stop(child);
    drop(crowd);
    let cap = railfuse_record::recorder::sources::MAX_CONNECTIONS;
    assert_eq!(
        r["sources"][0]["skipped"]["connection refused: too many open"],
        70 - cap as u64,
        "{r}"
    );
    assert_eq!(radar_count(&out), cap);
}

/// Captures in the manner of real receivers (issue 44), timed a minute ago so that a live
/// recorder's clock and the import date them alike: ST Teseo LIV4F (`$$` before every
/// sentence), Quectel EG25-G (an outage: GNS with mode NNN, untimed GGA/RMC/GSA, then the
/// first fix), SiRFstarV (GPGGA + GLGGA + GNGSA), Telit PLS83-W (GPGGA + GAGGA + GNGNS).
fn receiver_captures() -> Vec<(&'static str, String, Vec<(bool, u8)>)> {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs()
        - 60;
    let days = (now / 86_400) as i64;
    // Civil date of `days` (Howard Hinnant's algorithm, as the decoder's own calendar).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    let date = format!("{d:02}{m:02}{:02}", y % 100);
    let t = |k: u64| {
        let s = (now + k) % 86_400;
        format!("{:02}{:02}{:02}.00", s / 3600, s / 60 % 60, s % 60)
    };
    let b = |s: String| s;
    let mut captures = Vec::new();
    let teseo: Vec<String> = (0..6)
        .flat_map(|k| {
            [
                b(format!(
                    "GNRMC,{},A,4723.00484,N,00045.88150,E,0.5,120.9,{date},,,A,C",
                    t(k)
                )),
                format!(
                    "GNGGA,{},4723.00484,N,00045.88150,E,1,13,1.7,063.64,M,48.3,M,,",
                    t(k)
                ),
                "GNGSA,A,3,27,08,07,,,,,,,,,,2.5,1.7,1.8,1".into(),
            ]
        })
        .collect();
    let teseo = nmea_text(&teseo)
        .lines()
        .map(|l| format!("${l}\r\n"))
        .collect();
    captures.push(("teseo", teseo, vec![(true, 13); 6]));
    let mut quectel = Vec::new();
    for k in 0..3 {
        quectel.extend([
            format!("GNGNS,{},,,,,NNN,,,,,,", t(k)),
            "GPVTG,,T,,M,,N,,K,N".into(),
            "GPGSA,A,1,,,,,,,,,,,,,,,,".into(),
            "GPGGA,,,,,,0,,,,,,,,".into(),
            "GPRMC,,V,,,,,,,,,,N".into(),
        ]);
    }
    for k in 3..6 {
        quectel.extend([
            format!(
                "GPGGA,{},3645.876324,N,03124.670280,E,1,03,1.3,-6.7,M,32.0,M,,",
                t(k)
            ),
            format!(
                "GNGNS,{},3645.876324,N,03124.670280,E,AAN,08,1.3,-6.7,32.0,,,V",
                t(k)
            ),
            format!(
                "GPRMC,{},A,3645.876324,N,03124.670280,E,1.3,300.5,{date},3.6,E,A,V",
                t(k)
            ),
            "GPGSA,A,3,13,15,17,,,,,,,,,,2.9,1.3,2.6,1".into(),
        ]);
    }
    let mut want = vec![(false, 0); 3];
    want.extend([(true, 8); 3]);
    captures.push(("quectel", nmea_text(&quectel), want));
    let sirf: Vec<String> = (0..4)
        .flat_map(|k| {
            [
                format!(
                    "GPGGA,{},4404.1351,N,12118.8556,W,1,08,0.9,1123.9,M,-19.6,M,,0000",
                    t(k)
                ),
                format!(
                    "GLGGA,{},4404.1351,N,12118.8556,W,1,02,0.9,1123.9,M,-19.6,M,,0000",
                    t(k)
                ),
                "GNGSA,A,3,15,17,30,28,01,19,24,11,,,,,1.8,0.9,1.5".into(),
                "GNGSA,A,3,73,82,,,,,,,,,,,1.8,0.9,1.5".into(),
                format!(
                    "GNRMC,{},A,4404.1351,N,12118.8556,W,0.04,359.11,{date},,,A",
                    t(k)
                ),
            ]
        })
        .collect();
    captures.push(("sirfstarv", nmea_text(&sirf), vec![(true, 10); 4]));
    let telit: Vec<String> = (0..4)
        .flat_map(|k| {
            [
                format!(
                    "GPGGA,{},4333.190206,N,00127.618380,E,1,05,1.3,250.8,M,50.0,M,,",
                    t(k)
                ),
                format!(
                    "GAGGA,{},4333.190206,N,00127.618380,E,1,01,1.3,250.8,M,50.0,M,,",
                    t(k)
                ),
                format!(
                    "GNGNS,{},4333.190206,N,00127.618380,E,AAAAN,14,1.3,250.8,50.0,,,V",
                    t(k)
                ),
                format!(
                    "GPRMC,{},A,4333.190206,N,00127.618380,E,0.0,,{date},1.7,W,A,V",
                    t(k)
                ),
            ]
        })
        .collect();
    captures.push(("telit", nmea_text(&telit), vec![(true, 14); 4]));
    captures
}

#[test]
fn real_receivers_captures_decode_alike_in_import_and_record() {
    let d = tempfile::tempdir().unwrap();
    for (name, text, want) in receiver_captures() {
        let capture = d.path().join(format!("{name}.nmea"));
        std::fs::write(&capture, &text).unwrap();
        let out = d.path().join(format!("{name}.mcap"));
        let r = json(&ok(&["import", s(&capture), "-o", s(&out), "--json"]));
        let imported = gnss_fixes_in(&out);
        let got: Vec<(bool, u8)> = imported
            .iter()
            .map(|f| (f.latitude_deg.is_some(), f.satellites))
            .collect();
        assert_eq!(got, want, "{name}: {r}");

        let rec = d.path().join(format!("{name}-live.mcap"));
        let live = record_nmea_over_tcp(text.as_bytes(), &rec);
        assert_eq!(
            gnss_fixes_in(&rec),
            imported,
            "{name}: record and import differ\n{live}"
        );
        // The same counts under the same reasons (none is an empty table in either).
        let reasons = |v: &serde_json::Value| v.as_object().cloned().unwrap_or_default();
        assert_eq!(
            reasons(&live["sources"][0]["skipped"]),
            reasons(&r["skipped"]),
            "{name}"
        );
        if name == "teseo" {
            assert_eq!(
                r["skipped"][railfuse_record::decode::nmea::JUNK_REASON],
                18,
                "{r}"
            );
        }
    }
}
