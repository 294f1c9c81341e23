//! The recorder's sources, one thread each, each with its own bounded queue: a slow or dead
//! source never stalls another, and when the writer falls behind a source drops (and counts)
//! rather than grows without bound.

use std::io::Read;
use std::net::{TcpListener, TcpStream, UdpSocket};

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::*;

use super::message::Item;
use super::source_spec::SourceSpec;
use super::stream::{StreamDecoder, StreamFormat};
use crate::error::SourceError;

pub type Stats = Arc<Mutex<SourceStats>>;

pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Queues decoded items; false when the recorder has gone.
fn send(tx: &SyncSender<Item>, stats: &Stats, items: &mut Vec<Item>) -> bool {
    send_as(tx, stats, items, None)
}

/// Queues decoded items, GNSS fixes on `gnss_topic` when the source is mapped to one.
fn send_as(
    tx: &SyncSender<Item>,
    stats: &Stats,
    items: &mut Vec<Item>,
    gnss_topic: Option<&str>,
) -> bool {
    for mut item in items.drain(..) {
        if let (Some(t), AnyMessage::GnssFix(_)) = (gnss_topic, &item.message) {
            item.topic = t.to_owned();
        }
        match tx.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => stats.lock().expect("stats").dropped += 1,
            Err(TrySendError::Disconnected(_)) => return false,
        }
    }
    true
}

/// Pumps a byte stream through a decoder until it ends, fails or the recorder stops. A tty
/// in raw mode returns 0 bytes when its read times out: for it (`timeouts_read_empty`) an
/// empty read is a quiet line, not the end.
fn pump_with(
    mut r: impl Read,
    format: StreamFormat,
    topic: Option<&str>,
    tx: &SyncSender<Item>,
    stats: &Stats,
    stop: &AtomicBool,
    timeouts_read_empty: bool,
) -> std::io::Result<()> {
    let mut d = StreamDecoder::new(format);
    let mut buf = vec![0u8; 64 << 10];
    let mut items = Vec::new();
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        match r.read(&mut buf) {
            Ok(0) if timeouts_read_empty => {}
            Ok(0) => {
                d.finish(now_ns(), &mut stats.lock().expect("stats"), &mut items);
                send_as(tx, stats, &mut items, topic);
                return Ok(());
            }
            Ok(n) => {
                d.feed(
                    &buf[..n],
                    now_ns(),
                    &mut stats.lock().expect("stats"),
                    &mut items,
                );
                if !send_as(tx, stats, &mut items, topic) {
                    return Ok(());
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) => {}
            Err(e) => return Err(e),
        }
    }
}

fn pump(
    r: impl Read,
    format: StreamFormat,
    topic: Option<&str>,
    tx: &SyncSender<Item>,
    stats: &Stats,
    stop: &AtomicBool,
) -> std::io::Result<()> {
    pump_with(r, format, topic, tx, stats, stop, false)
}

fn set_error(stats: &Stats, e: impl std::fmt::Display) {
    stats.lock().expect("stats").last_error = Some(e.to_string());
}

/// Runs one source until it ends or `stop` is set. An error that ends the source for good (a
/// port that cannot be bound, a file that cannot be read) is returned as well as counted;
/// sources that reconnect (serial, TCP client) only count theirs.
pub fn run(
    spec: SourceSpec,
    tx: SyncSender<Item>,
    stats: Stats,
    stop: Arc<AtomicBool>,
) -> Result<(), SourceError> {
    let result = run_until_end(spec, tx, &stats, stop);
    let mut s = stats.lock().expect("stats");
    s.connected = false;
    if let Err(e) = &result {
        s.last_error = Some(e.to_string());
    }
    result
}

fn run_until_end(
    spec: SourceSpec,
    tx: SyncSender<Item>,
    stats: &Stats,
    stop: Arc<AtomicBool>,
) -> Result<(), SourceError> {
    stats.lock().expect("stats").connected = true;
    match spec {
        SourceSpec::Udp { addr } => udp(addr, &tx, stats, &stop),
        SourceSpec::TcpListen {
            addr,
            format,
            topic,
        } => tcp_listen(addr, format, topic, &tx, stats, &stop),
        SourceSpec::TcpClient {
            addr,
            format,
            topic,
        } => {
            let open = || {
                let conn = TcpStream::connect(&addr).map_err(|source| SourceError::Connect {
                    addr: addr.clone(),
                    source,
                })?;
                let _ = conn.set_read_timeout(Some(TICK));
                Ok(conn)
            };
            let run = |conn| {
                pump(conn, format, topic.as_deref(), &tx, stats, &stop).map_err(|source| {
                    SourceError::Connect {
                        addr: addr.clone(),
                        source,
                    }
                })
            };
            with_reconnects(stats, &stop, open, run);
            Ok(())
        }
        SourceSpec::Stdin { format, topic } => pump(
            std::io::stdin().lock(),
            format,
            topic.as_deref(),
            &tx,
            stats,
            &stop,
        )
        .map_err(SourceError::Stdin),
        SourceSpec::File {
            path,
            format,
            topic,
        } => {
            let on_path = |source| SourceError::Path {
                path: path.clone(),
                source,
            };
            let f = std::fs::File::open(&path).map_err(on_path)?;
            pump(f, format, topic.as_deref(), &tx, stats, &stop).map_err(on_path)
        }
        SourceSpec::Serial {
            path,
            baud,
            format,
            topic,
        } => {
            let on_path = |source| SourceError::Path {
                path: path.clone(),
                source,
            };
            let open = || super::serial::open(&path, baud).map_err(on_path);
            let run = |port| {
                pump_with(port, format, topic.as_deref(), &tx, stats, &stop, true).map_err(on_path)
            };
            with_reconnects(stats, &stop, open, run);
            Ok(())
        }
        SourceSpec::Simulated {
            scenario,
            seed,
            speed,
            duration_s,
        } => simulated(&scenario, seed, speed, duration_s, &tx, stats, &stop),
    }
}

/// How often a blocking read wakes to see whether the recorder is stopping.
const TICK: Duration = Duration::from_millis(200);

/// JSON lines in UDP datagrams on `addr`, until `stop`.
fn udp(
    addr: std::net::SocketAddr,
    tx: &SyncSender<Item>,
    stats: &Stats,
    stop: &AtomicBool,
) -> Result<(), SourceError> {
    let sock = UdpSocket::bind(addr)
        .and_then(|s| s.set_read_timeout(Some(TICK)).map(|()| s))
        .map_err(|source| SourceError::Bind { addr, source })?;
    let mut buf = vec![0u8; 65_536];
    let mut items = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        match sock.recv(&mut buf) {
            Ok(n) => {
                // Each datagram holds whole lines; a fresh decoder per datagram keeps a torn
                // one from corrupting the next.
                let mut d = StreamDecoder::new(StreamFormat::JsonLines);
                let t = now_ns();
                let mut s = stats.lock().expect("stats");
                if n == buf.len() {
                    s.oversized += 1;
                    continue;
                }
                d.feed(&buf[..n], t, &mut s, &mut items);
                d.finish(t, &mut s, &mut items);
                drop(s);
                if !send(tx, stats, &mut items) {
                    return Ok(());
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => set_error(stats, e),
        }
    }
    Ok(())
}

/// A TCP listener on `addr`: each connection read on its own thread, until `stop`.
fn tcp_listen(
    addr: std::net::SocketAddr,
    format: StreamFormat,
    topic: Option<String>,
    tx: &SyncSender<Item>,
    stats: &Stats,
    stop: &Arc<AtomicBool>,
) -> Result<(), SourceError> {
    let listener = TcpListener::bind(addr)
        .and_then(|l| l.set_nonblocking(true).map(|()| l))
        .map_err(|source| SourceError::Bind { addr, source })?;
    std::thread::scope(|scope| {
        while !stop.load(Ordering::Relaxed) {
            match listener.accept() {
                Ok((conn, _)) => {
                    let (tx, stats, stop, topic) =
                        (tx.clone(), stats.clone(), stop.clone(), topic.clone());
                    scope.spawn(move || {
                        let _ = conn.set_nonblocking(false);
                        let _ = conn.set_read_timeout(Some(TICK));
                        if let Err(e) = pump(conn, format, topic.as_deref(), &tx, &stats, &stop) {
                            set_error(&stats, e);
                        }
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                Err(e) => set_error(stats, e),
            }
        }
    });
    Ok(())
}

/// Opens a connection (a TCP receiver, a serial device) and reads it, again and again until
/// the recorder stops: 0.25 s between attempts, doubling to 8 s, back to 0.25 s after a
/// success; a connection after an earlier one counts as a reconnect.
fn with_reconnects<C>(
    stats: &Stats,
    stop: &AtomicBool,
    mut open: impl FnMut() -> Result<C, SourceError>,
    mut run: impl FnMut(C) -> Result<(), SourceError>,
) {
    const FIRST: Duration = Duration::from_millis(250);
    let (mut backoff, mut connected_before) = (FIRST, false);
    while !stop.load(Ordering::Relaxed) {
        match open() {
            Ok(connection) => {
                {
                    let mut s = stats.lock().expect("stats");
                    s.reconnects += u64::from(connected_before);
                    s.connected = true;
                }
                (backoff, connected_before) = (FIRST, true);
                if let Err(e) = run(connection) {
                    set_error(stats, e);
                }
            }
            Err(e) => set_error(stats, e),
        }
        stats.lock().expect("stats").connected = false;
        let until = Instant::now() + backoff;
        while Instant::now() < until && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(20));
        }
        backoff = (backoff * 2).min(Duration::from_secs(8));
    }
}

/// The simulator as a live source: the run is simulated ahead into a temporary file (a
/// fraction of a second of work per minute of run) and played out at the pace of its log
/// times, stamped with the live clock.
fn simulated(
    scenario: &str,
    seed: u64,
    speed: f64,
    duration_s: Option<f64>,
    tx: &SyncSender<Item>,
    stats: &Stats,
    stop: &AtomicBool,
) -> Result<(), SourceError> {
    let preset = crate::Scenario::preset(scenario)
        .ok_or_else(|| SourceError::UnknownScenario(scenario.to_owned()))?;
    let dir = tempfile::tempdir().map_err(SourceError::TempFile)?;
    let path = dir.path().join("sim.mcap");
    crate::simulate(&preset, seed, duration_s, &[], &path)?;
    let mut reader = LogReader::open(&path)?;
    let (wall0, mut sim0, live0) = (Instant::now(), None, now_ns());
    let mut items = Vec::with_capacity(1);
    while let Some(rec) = reader.next() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let LogRecord::Message(m) = rec? else {
            continue;
        };
        let t0 = *sim0.get_or_insert(m.log_time_ns);
        let offset = m.log_time_ns.saturating_sub(t0);
        let due = wall0 + Duration::from_nanos((offset as f64 / speed) as u64);
        while Instant::now() < due && !stop.load(Ordering::Relaxed) {
            std::thread::sleep((due - Instant::now()).min(Duration::from_millis(50)));
        }
        // Shift the run onto the live clock: sensor and log times keep their spacing.
        let shift = |t: u64| live0 + ((t.saturating_sub(t0)) as f64 / speed) as u64;
        // Messages of kinds the catalogue does not know are passed over.
        let Some(kind) = MessageKind::from_schema(m.channel.schema_name()) else {
            continue;
        };
        let mut message = kind
            .decode(m.data)
            .map_err(|source| SourceError::SimulatedMessage {
                topic: m.channel.topic.clone(),
                source,
            })?;
        let stamp = message.stamp_ns_mut();
        *stamp = shift(*stamp);
        stats.lock().expect("stats").received += 1;
        items.push(Item {
            topic: m.channel.topic.clone(),
            log_time_ns: shift(m.log_time_ns),
            message,
        });
        if !send(tx, stats, &mut items) {
            break;
        }
    }
    Ok(())
}
