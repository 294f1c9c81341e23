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

/// A pseudo-terminal pair: the master (a device's side), the slave descriptor and the
/// slave's path. The master is not inherited by a child the test starts, so closing it here
/// hangs the line up as unplugging a device does.
pub fn pty() -> (std::fs::File, std::os::fd::OwnedFd, String) {
    use std::os::fd::FromRawFd;
    let (mut master, mut slave) = (0, 0);
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: openpty fills the two descriptors and the name buffer it is given.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            name.as_mut_ptr(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(rc, 0, "openpty failed");
    // SAFETY: `master` is open; the flag only keeps it from children.
    unsafe { libc::fcntl(master, libc::F_SETFD, libc::FD_CLOEXEC) };
    // SAFETY: openpty wrote a NUL-terminated name.
    let tty = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
        .to_str()
        .unwrap()
        .to_owned();
    // SAFETY: both descriptors were just made by openpty and are owned from here.
    unsafe {
        (
            std::fs::File::from_raw_fd(master),
            std::os::fd::OwnedFd::from_raw_fd(slave),
            tty,
        )
    }
}
