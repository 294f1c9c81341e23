//! Helpers of the live-recording tests: ports, a recorder child, stopping it, NMEA text.

use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A loopback port free at the moment.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `railfuse ARGS` as a child with its standard streams piped.
pub fn spawn(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// SIGTERM to a recorder started with `--json`: its report, after checking it exited 0.
pub fn stop(child: Child) -> serde_json::Value {
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Waits until the recorder listens on `port` (20 s at most).
pub fn wait_listening(port: u16) {
    let t = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "the recorder never listened on {port}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// NMEA sentences with their checksums, CRLF-terminated.
pub fn nmea_text(bodies: &[String]) -> String {
    bodies
        .iter()
        .map(|b| format!("${b}*{:02X}\r\n", b.bytes().fold(0u8, |a, x| a ^ x)))
        .collect()
}

/// A gateway's JSON line of radar message `k` (speed k m/s).
pub fn radar_line(k: usize) -> String {
    format!(
        r#"{{"topic":"/radar/speed","stamp_ns":{},"speed_mps":{k},"quality":1.0,"valid":true}}"#,
        1_000 + k
    )
}

/// Starts a recorder of `out` on a TCP JSON port (chunks closed every 0.2 s), sends it
/// `lines` radar messages, waits for several chunk intervals and kills it with SIGKILL;
/// returns the `.partial` it left.
pub fn killed_recording(out: &std::path::Path, lines: usize) -> std::path::PathBuf {
    use std::io::Write;
    let tcp = free_port();
    let args = [
        "record",
        "-o",
        super::s(out),
        "--tcp",
        &tcp.to_string(),
        "--chunk-interval",
        "0.2",
    ];
    let mut child = spawn(&args);
    wait_listening(tcp);
    let mut conn = TcpStream::connect(("127.0.0.1", tcp)).unwrap();
    for k in 0..lines {
        conn.write_all(format!("{}\n", radar_line(k)).as_bytes())
            .unwrap();
    }
    conn.flush().unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    child.kill().unwrap();
    child.wait().unwrap();
    let partial = railfuse_catalog::log::partial_path(out);
    assert!(partial.exists() && !out.exists());
    partial
}
