//! `railfuse record --can` over real byte paths, with no CAN hardware: an SLCAN adapter on a
//! pseudo-terminal pair, a socketcand server and a cannelloni gateway on the loopback, and
//! SocketCAN on a vcan interface where the machine can make one (skipped, with its reason,
//! where it cannot). An adapter unplugged mid-run ends that source alone.

mod common;

use std::io::{Read, Write};
use std::net::{TcpListener, UdpSocket};
use std::path::Path;
use std::time::{Duration, Instant};

use common::live::*;
use common::*;
use railfuse_can::frame::Frame;
use railfuse_can::{cannelloni, slcan, socketcand};
use railfuse_catalog::messages::{CanFrame, CanSignals};

/// SIGTERM to a recorder started with `--json`: its exit status and report.
fn stop_any(child: std::process::Child) -> (bool, serde_json::Value) {
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = child.wait_with_output().unwrap();
    let report = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    (out.status.success(), report)
}

fn frame(id: u32, data: &[u8], stamp_ns: u64) -> Frame {
    Frame {
        stamp_ns,
        bus: String::new(),
        id,
        extended: false,
        rtr: false,
        error: false,
        fd: false,
        brs: false,
        esi: false,
        data: data.to_vec(),
    }
}

/// Reads what the recorder sent the adapter until `want` has come (10 s at most).
fn read_until(master: &mut std::fs::File, want: &[u8]) -> Vec<u8> {
    let (start, mut got) = (Instant::now(), Vec::new());
    let mut buf = [0u8; 64];
    while !got.windows(want.len()).any(|w| w == want) {
        assert!(start.elapsed() < Duration::from_secs(10), "got {got:?}");
        match master.read(&mut buf) {
            Ok(n) => got.extend(&buf[..n]),
            // No one has the slave open yet.
            Err(e) if e.raw_os_error() == Some(libc::EIO) => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("{e}"),
        }
    }
    got
}

/// Waits until a socket is bound to UDP `port` on this machine (20 s at most).
fn wait_bound_udp(port: u16) {
    let hex = format!(":{port:04X} ");
    let start = Instant::now();
    while !std::fs::read_to_string("/proc/net/udp").is_ok_and(|t| t.contains(&hex)) {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "nothing bound UDP port {port}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn topic_counts(path: &Path) -> std::collections::BTreeMap<String, u64> {
    let info = ok_json(&["info", s(path), "--json"]);
    info["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["topic"].as_str().unwrap().to_owned(),
                t["messages"].as_u64().unwrap(),
            )
        })
        .collect()
}

#[test]
fn slcan_on_a_pty_and_socketcand_record_every_frame_and_an_unplugged_adapter_ends_alone() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("bus.mcap");
    // The recorder opens the slave by its name; this process keeps no copy of it.
    let (mut master, slave, tty) = pty();
    drop(slave);
    // A socketcand server: the handshake, 2000 radar frames, then 1000 more once told.
    let server = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = server.local_addr().unwrap().port();
    let (go_on, later) = std::sync::mpsc::channel::<()>();
    let socketcand = std::thread::spawn(move || {
        let (mut c, _) = server.accept().unwrap();
        c.write_all(b"< hi >").unwrap();
        let mut said = Vec::new();
        let mut buf = [0u8; 64];
        while !String::from_utf8_lossy(&said).contains("< rawmode >") {
            let n = c.read(&mut buf).unwrap();
            said.extend(&buf[..n]);
            if n > 0 {
                c.write_all(b"< ok >").unwrap();
            }
        }
        let radar = |k: u64| {
            frame(
                0x120,
                &[0x09, 0xC4, 0xBA, 0x80, 0, 0, 0, 0],
                1_700_000_000_000_000_000 + k * 1000,
            )
        };
        for k in 0..2000 {
            c.write_all(socketcand::format_element(&radar(k)).as_bytes())
                .unwrap();
        }
        later.recv().unwrap();
        for k in 2000..3000 {
            c.write_all(socketcand::format_element(&radar(k)).as_bytes())
                .unwrap();
        }
        // Kept open: this server stays up until the recording ends.
        (String::from_utf8_lossy(&said).into_owned(), c)
    });
    let child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--can",
        &format!("slcan:{tty}:1000000"),
        "--can",
        &format!("socketcand:127.0.0.1:{port}"),
        "--dbc",
        s(&sample("vehicle.dbc")),
        "--json",
    ]);
    // The adapter is told its bit rate and opened before it sends.
    let commands = read_until(&mut master, b"O\r");
    assert_eq!(commands, b"C\rS8\rO\r");
    for k in 0..2000u16 {
        let speed = (1000 + k).to_le_bytes();
        let f = frame(0x100, &[speed[0], speed[1], 0, 0, 1, 0, 0, 0], 0);
        master.write_all(slcan::format_line(&f).as_bytes()).unwrap();
    }
    master.write_all(b"not a frame\r").unwrap();
    std::thread::sleep(Duration::from_millis(500));
    drop(master); // unplugged
    std::thread::sleep(Duration::from_millis(500));
    go_on.send(()).unwrap();
    let (said, connection) = socketcand.join().unwrap();
    assert_eq!(said, "< open can0 >< rawmode >");
    std::thread::sleep(Duration::from_millis(500));
    let (success, r) = stop_any(child);
    drop(connection);
    assert!(
        !success,
        "a source that failed makes the exit non-zero: {r}"
    );
    let bus = Path::new(&tty)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let counts = topic_counts(&out);
    assert_eq!(counts[&format!("/can/{bus}/frames")], 2000, "{counts:?}");
    assert_eq!(
        counts[&format!("/can/{bus}/WheelSpeed")],
        2000,
        "{counts:?}"
    );
    assert_eq!(
        counts["/can/can0/frames"], 3000,
        "the socketcand source went on after the SLCAN adapter was unplugged: {counts:?}"
    );
    let failed = r["failed_sources"].as_array().unwrap();
    assert_eq!(failed.len(), 1, "{r}");
    assert!(failed[0].as_str().unwrap().contains("slcan"), "{r}");
    let slcan_stats = &r["sources"][0];
    assert_eq!(
        slcan_stats["skipped"]["SLCAN line that does not parse"], 1,
        "{r}"
    );
    // Every frame whole and decoded in its units: AxleSpeed1 is 0.01 m/s a bit.
    let frames: Vec<CanFrame> = messages(&out, &format!("/can/{bus}/frames"));
    assert!(frames
        .iter()
        .all(|f| f.id == 0x100 && f.data.0.len() == 8 && f.bus == bus));
    let signals: Vec<CanSignals> = messages(&out, &format!("/can/{bus}/WheelSpeed"));
    let speeds: Vec<f64> = signals.iter().map(|m| m.signals[0].value).collect();
    let want: Vec<f64> = (0..2000).map(|k| f64::from(1000 + k) * 0.01).collect();
    assert!(speeds.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-9));
    // socketcand's frames keep the server's bus time.
    let radar: Vec<CanFrame> = messages(&out, "/can/can0/frames");
    assert_eq!(radar[1].stamp_ns - radar[0].stamp_ns, 1000);
}

#[test]
fn cannelloni_datagrams_are_recorded_and_a_lost_one_and_a_broken_one_counted() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("gw.mcap");
    let port = {
        let probe = UdpSocket::bind("127.0.0.1:0").unwrap();
        probe.local_addr().unwrap().port()
    };
    let child = spawn(&[
        "record",
        "-o",
        s(&out),
        "--can",
        &format!("cannelloni:{port}:gateway"),
        "--json",
    ]);
    wait_bound_udp(port);
    let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let frames: Vec<Frame> = (0..4).map(|i| frame(0x200 + i, &[i as u8; 8], 0)).collect();
    for seq in 0..100u16 {
        if seq == 40 || seq == 41 {
            continue; // lost in the network
        }
        tx.send_to(&cannelloni::format(seq as u8, &frames), ("127.0.0.1", port))
            .unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    tx.send_to(&[2, 0, 100, 0, 9, 1], ("127.0.0.1", port))
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let (success, r) = stop_any(child);
    assert!(success, "{r}");
    assert_eq!(topic_counts(&out)["/can/gateway/frames"], 98 * 4);
    let src = &r["sources"][0];
    assert_eq!(
        src["warnings"]["cannelloni datagrams lost (sequence gaps)"], 2,
        "{r}"
    );
    assert_eq!(
        src["skipped"]["cannelloni datagram that does not parse"], 1,
        "{r}"
    );
}

#[test]
fn socketcan_on_a_vcan_interface_where_the_machine_can_make_one() {
    let iface = "rfvcan0";
    let made = std::process::Command::new("ip")
        .args(["link", "add", "dev", iface, "type", "vcan"])
        .output();
    let reason = match &made {
        Err(e) => Some(format!("no `ip` command: {e}")),
        Ok(o) if !o.status.success() => Some(String::from_utf8_lossy(&o.stderr).trim().to_owned()),
        Ok(_) => None,
    };
    if let Some(reason) = reason {
        eprintln!("skipped: cannot make a vcan interface here ({reason})");
        return;
    }
    let _ = std::process::Command::new("ip")
        .args(["link", "set", iface, "up"])
        .status();
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("vcan.mcap");
    let child = spawn(&["record", "-o", s(&out), "--can", iface, "--json"]);
    std::thread::sleep(Duration::from_millis(800));
    for _ in 0..100 {
        let _ = std::process::Command::new("cansend")
            .args([iface, "123#DEADBEEF"])
            .status();
    }
    let (success, r) = stop_any(child);
    let _ = std::process::Command::new("ip")
        .args(["link", "del", iface])
        .status();
    assert!(success, "{r}");
    assert!(r["sources"][0]["connected"].is_boolean(), "{r}");
}
