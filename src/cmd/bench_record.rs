//! `railfuse bench --record`: the recorder under load, measured from outside as a user would
//! see it: a `railfuse record` child process fed over UDP on loopback.
//!
//! 1. Ingest: JSON-line datagrams at rising rates for a few seconds each; the highest rate
//!    with no loss (every datagram in the file) is the sustained zero-loss rate.
//! 2. Field load: IMU 1.6 kHz, GNSS 10 Hz, radar 50 Hz, two odometers 100 Hz and eddy-current
//!    blocks carrying 10 kHz of samples per sensor, for the given time; the child's CPU time
//!    (from /proc) over wall time is its share of one core, and its resident memory at the
//!    start and the end shows whether memory grows.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

pub(super) fn proc_stat(pid: u32) -> Option<(f64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks =
        (fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?) / 100.0;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let rss = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    Some((ticks, rss))
}

struct Child {
    child: std::process::Child,
    out: PathBuf,
}

fn start(dir: &Path, name: &str, port: u16) -> Result<Child> {
    let out = dir.join(format!("{name}.mcap"));
    let exe = std::env::current_exe()?;
    let child = Command::new(exe)
        .args(["record", "--json", "--udp", &port.to_string(), "-o"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?;
    std::thread::sleep(Duration::from_millis(300));
    Ok(Child { child, out })
}

fn finish(c: Child) -> Result<serde_json::Value> {
    // SAFETY: signalling our own child by its pid.
    unsafe { libc::kill(c.child.id() as i32, libc::SIGTERM) };
    let out = c.child.wait_with_output()?;
    if !out.status.success() {
        bail!("the recorder failed");
    }
    std::fs::remove_file(&c.out).ok();
    Ok(serde_json::from_slice(&out.stdout)?)
}

fn radar_line(k: u64) -> String {
    format!(
        r#"{{"topic":"/radar/speed","stamp_ns":{k},"speed_mps":{}.5,"quality":1.0,"valid":true}}"#,
        k % 100
    )
}

/// Sends `rate` datagrams/s for `secs`, paced in 1 ms slices; returns how many it sent.
fn send_at(
    sock: &UdpSocket,
    port: u16,
    rate: f64,
    secs: f64,
    mut line: impl FnMut(u64) -> String,
) -> Result<u64> {
    let start = Instant::now();
    let mut sent = 0u64;
    while start.elapsed().as_secs_f64() < secs {
        let due = (start.elapsed().as_secs_f64() * rate) as u64;
        while sent < due {
            sock.send_to(line(sent).as_bytes(), ("127.0.0.1", port))?;
            sent += 1;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    Ok(sent)
}

pub fn run(dir: &Path, field_secs: f64, speedup: f64) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_write_timeout(Some(Duration::from_secs(1)))?;
    ingest(dir, &sock)?;

    println!("\nfield load ×{speedup} for {field_secs:.0} s (= {:.0} s of field data): IMU 1.6 kHz, GNSS 10 Hz, radar 50 Hz, 2 odometers 100 Hz, eddy-current 10 kHz (100 blocks/s of 100 samples × 2 sensors)", field_secs * speedup);
    let port = std::net::UdpSocket::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let c = start(dir, "field", port)?;
    let pid = c.child.id();
    let samples: Vec<String> = (0..100)
        .map(|i| format!("{:.4}", (i as f64 * 0.3).sin()))
        .collect();
    let block = samples.join(",");
    let (cpu0, rss0) = proc_stat(pid).context("no /proc")?;
    let t0 = Instant::now();
    let mut sent = 0u64;
    let mut k = 0u64;
    let mut rss_mid = rss0;
    // 1 ms slices: 1.6 IMU, and the slower ones on their periods.
    while t0.elapsed().as_secs_f64() < field_secs {
        let ms = (t0.elapsed().as_secs_f64() * 1000.0 * speedup) as u64;
        while k < ms {
            for l in field_slice(k, &block) {
                sock.send_to(l.as_bytes(), ("127.0.0.1", port))?;
                sent += 1;
            }
            k += 1;
        }
        if (t0.elapsed().as_secs_f64() - field_secs / 2.0).abs() < 0.01 {
            rss_mid = proc_stat(pid).map_or(rss_mid, |x| x.1);
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    let wall = t0.elapsed().as_secs_f64();
    let (cpu1, rss1) = proc_stat(pid).context("no /proc")?;
    std::thread::sleep(Duration::from_millis(300));
    let r = finish(c)?;
    let written = r["messages"].as_u64().unwrap_or(0);
    println!(
        "sent {sent} messages ({:.0}/s), written {written} (+ the recorder's own diagnostics)",
        sent as f64 / wall
    );
    println!(
        "recorder CPU {:.2} % of one core; resident memory {} MiB at start, {} MiB midway, {} MiB at the end",
        100.0 * (cpu1 - cpu0) / wall,
        super::measure::mib_of(Some(rss0)),
        super::measure::mib_of(Some(rss_mid)),
        super::measure::mib_of(Some(rss1)),
    );
    Ok(())
}

/// The ingest table: rising rates of radar datagrams until the recorder loses one.
fn ingest(dir: &Path, sock: &UdpSocket) -> Result<()> {
    println!("UDP ingest (JSON lines, one message per datagram, 3 s per rate):");
    println!(
        "{:>12} {:>10} {:>10} {:>8} {:>22}",
        "rate msg/s", "sent", "written", "lost", "counted as kernel drop"
    );
    let mut best = 0.0;
    // Doubling to 80 000, then finer steps to find where loss begins.
    for rate in [
        5_000.0, 10_000.0, 20_000.0, 40_000.0, 80_000.0, 100_000.0, 120_000.0, 140_000.0, 160_000.0,
    ] {
        let port = std::net::UdpSocket::bind("127.0.0.1:0")?
            .local_addr()?
            .port();
        let c = start(dir, "ingest", port)?;
        let sent = send_at(sock, port, rate, 3.0, radar_line)?;
        std::thread::sleep(Duration::from_millis(500));
        let r = finish(c)?;
        let written = r["per_topic"]["/radar/speed"].as_u64().unwrap_or(0);
        let kernel = r["sources"][0]["kernel_dropped"].as_u64().unwrap_or(0);
        println!(
            "{rate:>12.0} {sent:>10} {written:>10} {:>8} {kernel:>22}",
            sent.saturating_sub(written)
        );
        if written >= sent {
            best = rate;
        } else {
            break;
        }
    }
    println!("highest rate with zero loss: {best:.0} msg/s");
    Ok(())
}

/// The field load's datagrams of millisecond `k`: IMU at 1.6 kHz, GNSS 10 Hz, radar 50 Hz,
/// two odometers and the eddy-current blocks at 100 Hz.
fn field_slice(k: u64, block: &str) -> Vec<String> {
    let t = 1_780_300_800_000_000_000 + k * 1_000_000;
    let mut lines = Vec::new();
    for j in 0..(if k % 5 < 3 { 2 } else { 1 }) {
        lines.push(format!(
            r#"{{"topic":"/imu","stamp_ns":{},"sensor_id":"imu0","specific_force_mps2":[0.01,0.02,9.81],"angular_rate_radps":[0.001,0.002,0.003]}}"#,
            t + j * 500_000
        ));
    }
    if k.is_multiple_of(100) {
        lines.push(format!(
            r#"{{"topic":"/gnss/fix","stamp_ns":{t},"fix_type":"rtk_fixed","satellites":18,"latitude_deg":44.6,"longitude_deg":10.9,"speed_mps":20.0}}"#
        ));
    }
    if k.is_multiple_of(20) {
        lines.push(radar_line(t));
    }
    if k.is_multiple_of(10) {
        for o in ["/odometer/1", "/odometer/2"] {
            lines.push(format!(r#"{{"topic":"{o}","stamp_ns":{t},"sensor_id":"axle","pulse_count":{k},"pulses_per_revolution":200,"wheel_diameter_m":0.85,"distance_increment_m":0.2,"speed_mps":20.0}}"#));
        }
        lines.push(format!(
            r#"{{"topic":"/eddy_current/block","stamp_ns":{t},"sample_rate_hz":10000.0,"spacing_m":0.2,"sensor_a":[{block}],"sensor_b":[{block}]}}"#
        ));
    }
    lines
}
