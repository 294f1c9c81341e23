//! `railfuse bench --can`: the recorder on the vehicle's CAN bus under load, measured from
//! outside: a `railfuse record --can … --dbc …` child fed frames at a set rate through an
//! SLCAN adapter (the master side of a pseudo-terminal pair) and then through a socketcand
//! server on the loopback. Every frame sent must be in the file or counted as dropped; the
//! child's resident memory at the start, midway and at the end shows whether it grows.

use std::io::Write;
use std::net::TcpListener;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use railfuse_can::frame::Frame;
use railfuse_can::{slcan, socketcand};

use super::bench_record::proc_stat;

/// The frames sent, in turn: the DBC's odometry and radar messages and an id it lacks.
fn frame(k: u64) -> Frame {
    let (id, data) = match k % 4 {
        0 => (0x100, [0xD2, 0x04, 0x96, 0x04, 0x01, 0, 0, (k % 16) as u8]),
        1 => (
            0x101,
            (k as u32)
                .to_be_bytes()
                .repeat(2)
                .try_into()
                .expect("8 bytes"),
        ),
        2 => (0x120, [0x09, 0xC4, 0xBA, 0x80, 0, 0, 0, 0]),
        _ => (0x7AB, [k as u8; 8]),
    };
    Frame {
        stamp_ns: 1_780_300_800_000_000_000 + k * 20_000,
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

/// Writes `rate` frames a second for `secs` in 1 ms slices, sampling the recorder's memory.
fn feed(
    out: &mut impl Write,
    rate: f64,
    secs: f64,
    pid: u32,
    format: fn(&Frame) -> String,
) -> Result<(u64, [u64; 3], f64)> {
    let (cpu0, rss0) = proc_stat(pid).context("no /proc")?;
    let (start, mut sent, mut rss_mid) = (Instant::now(), 0u64, rss0);
    let mut batch = String::new();
    while start.elapsed().as_secs_f64() < secs {
        let due = (start.elapsed().as_secs_f64() * rate) as u64;
        batch.clear();
        while sent < due {
            batch.push_str(&format(&frame(sent)));
            sent += 1;
        }
        out.write_all(batch.as_bytes())?;
        if (start.elapsed().as_secs_f64() - secs / 2.0).abs() < 0.002 {
            rss_mid = proc_stat(pid).map_or(rss_mid, |x| x.1);
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    let wall = start.elapsed().as_secs_f64();
    let (cpu1, rss1) = proc_stat(pid).context("no /proc")?;
    Ok((sent, [rss0, rss_mid, rss1], (cpu1 - cpu0) / wall))
}

fn recorder(dir: &Path, name: &str, can: &str, dbc: &Path) -> Result<std::process::Child> {
    let out = dir.join(format!("{name}.mcap"));
    let _ = std::fs::remove_file(&out);
    Ok(Command::new(std::env::current_exe()?)
        .args(["record", "--json", "--can", can, "--dbc"])
        .arg(dbc)
        .arg("-o")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?)
}

/// SIGTERM and the report (a source that ended with its adapter still counts).
fn report(child: std::process::Child) -> Result<serde_json::Value> {
    // SAFETY: signalling our own child by its pid.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = child.wait_with_output()?;
    serde_json::from_slice(&out.stdout).context("the recorder's report")
}

fn print(kind: &str, rate: f64, sent: u64, rss: [u64; 3], cpu: f64, r: &serde_json::Value) {
    let frames: u64 = r["per_topic"]
        .as_object()
        .map(|t| {
            t.iter()
                .filter(|(k, _)| k.ends_with("/frames"))
                .filter_map(|(_, v)| v.as_u64())
                .sum()
        })
        .unwrap_or(0);
    let s = &r["sources"][0];
    let dropped = s["dropped"].as_u64().unwrap_or(0) + s["kernel_dropped"].as_u64().unwrap_or(0);
    println!(
        "{kind:<11} {rate:>8.0} {sent:>10} {frames:>10} {:>7} {dropped:>8} {:>11} {:>6.1} %   {} / {} / {} MiB",
        sent.saturating_sub(frames),
        r["messages"].as_u64().unwrap_or(0),
        100.0 * cpu,
        super::measure::mib_of(Some(rss[0])),
        super::measure::mib_of(Some(rss[1])),
        super::measure::mib_of(Some(rss[2])),
    );
}

pub fn run(dir: &Path, secs: f64, rate: f64) -> Result<()> {
    if !(rate > 0.0 && secs > 0.0) {
        bail!("--can SECONDS and --can-rate must be positive");
    }
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let dbc = dir.join("vehicle.dbc");
    std::fs::write(&dbc, railfuse_record::simulator::can_bus::VEHICLE_DBC)?;
    println!(
        "CAN frames through the recorder with samples/vehicle.dbc ({secs:.0} s each; lost = sent − in the file)"
    );
    println!(
        "{:<11} {:>8} {:>10} {:>10} {:>7} {:>8} {:>11} {:>8}   memory start / mid / end",
        "adapter", "frames/s", "sent", "in file", "lost", "dropped", "messages", "CPU",
    );
    // SLCAN: the adapter's side of a pty pair.
    let (mut master, tty) = pty()?;
    let child = recorder(dir, "can-slcan", &format!("slcan:{tty}:1000000"), &dbc)?;
    let pid = child.id();
    wait_for_open(&mut master)?;
    let (sent, rss, cpu) = feed(&mut master, rate, secs, pid, slcan::format_line)?;
    std::thread::sleep(Duration::from_millis(500));
    let r = report(child)?;
    print("slcan", rate, sent, rss, cpu, &r);
    drop(master);
    // socketcand: a server on the loopback.
    let server = TcpListener::bind("127.0.0.1:0")?;
    let port = server.local_addr()?.port();
    let child = recorder(
        dir,
        "can-socketcand",
        &format!("socketcand:127.0.0.1:{port}"),
        &dbc,
    )?;
    let pid = child.id();
    let (mut conn, _) = server.accept()?;
    handshake(&mut conn)?;
    let (sent, rss, cpu) = feed(&mut conn, rate, secs, pid, |f| {
        socketcand::format_element(f)
    })?;
    std::thread::sleep(Duration::from_millis(500));
    let r = report(child)?;
    print("socketcand", rate, sent, rss, cpu, &r);
    Ok(())
}

/// A pseudo-terminal pair: the master, kept from the child, and the slave's path.
fn pty() -> Result<(std::fs::File, String)> {
    use std::os::fd::FromRawFd;
    let (mut master, mut slave) = (0, 0);
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: openpty fills the two descriptors and the name buffer it is given.
    let r = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            name.as_mut_ptr(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    if r != 0 {
        bail!("openpty: {}", std::io::Error::last_os_error());
    }
    // SAFETY: the descriptors were just made by openpty and are owned here.
    unsafe {
        libc::fcntl(master, libc::F_SETFD, libc::FD_CLOEXEC);
        drop(std::os::fd::OwnedFd::from_raw_fd(slave));
    }
    // SAFETY: openpty wrote a NUL-terminated name.
    let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    // SAFETY: as above.
    let file = std::fs::File::from(unsafe { std::os::fd::OwnedFd::from_raw_fd(master) });
    Ok((file, path))
}

/// Waits for the recorder's `O\r` (the channel opened) on the adapter's side.
fn wait_for_open(master: &mut std::fs::File) -> Result<()> {
    use std::io::Read;
    let (start, mut got, mut buf) = (Instant::now(), Vec::new(), [0u8; 64]);
    while !got.ends_with(b"O\r") {
        if start.elapsed() > Duration::from_secs(10) {
            bail!("the recorder never opened the SLCAN channel");
        }
        match master.read(&mut buf) {
            Ok(n) => got.extend(&buf[..n]),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    Ok(())
}

/// socketcand's side of the handshake: hi, then ok to `open` and to `rawmode`.
fn handshake(conn: &mut std::net::TcpStream) -> Result<()> {
    use std::io::Read;
    conn.write_all(b"< hi >")?;
    let mut said = String::new();
    let mut buf = [0u8; 128];
    while !said.contains("< rawmode >") {
        let n = conn.read(&mut buf)?;
        if n == 0 {
            bail!("the recorder closed the connection");
        }
        said.push_str(&String::from_utf8_lossy(&buf[..n]));
        for _ in 0..String::from_utf8_lossy(&buf[..n]).matches('>').count() {
            conn.write_all(b"< ok >")?;
        }
    }
    Ok(())
}
