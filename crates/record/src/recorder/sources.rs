//! The recorder's sources, one thread each, each with its own bounded queue: a slow or dead
//! source never stalls another, and when the writer falls behind a source drops (and counts)
//! rather than grows without bound.
//!
//! A source is isolated from the others: a panic in one (a decoder bug) ends that source, or
//! that one connection of a listener, with its reason counted and said; the recorder and the
//! other sources go on. A TCP listener caps its connections ([`MAX_CONNECTIONS`]), backs off
//! when it cannot accept (out of file descriptors) or start a thread, and says so at once.
//! Each connection decodes into figures of its own and adds them to the listener's after each
//! read, so a hostile client never holds a lock a good one waits on. When the recording stops,
//! stream sources drain what their peers had already sent (up to [`DRAIN`]).

use std::io::Read;
use std::net::{TcpListener, TcpStream, UdpSocket};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::*;

use super::link::nothing_waiting;
pub use super::link::{lock, now_ns, Link, Stats, DRAIN};
use super::message::Item;
use super::source_spec::SourceSpec;
use super::stream::{StreamDecoder, StreamFormat};
pub use super::udp::UDP_RECEIVE_BUFFER;
use crate::error::SourceError;

/// Connections one TCP listener serves at once; more are refused and counted.
pub const MAX_CONNECTIONS: usize = 64;
/// A connection silent this long drops the half line it holds (and its buffer).
pub const IDLE_HALF_LINE: Duration = Duration::from_secs(30);

/// The text of a panic's payload.
pub fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".to_owned())
}

/// Where a stream comes from, to say where its problems were.
struct Origin<'a> {
    /// A connection's peer, when a listener has several.
    peer: Option<String>,
    topic: Option<&'a str>,
}

/// Pumps a byte stream through a decoder until it ends, fails or the recorder stops (then it
/// reads on for up to [`DRAIN`] while the peer's bytes keep coming). A tty in raw mode returns
/// 0 bytes when its read times out: for it (`timeouts_read_empty`) an empty read is a quiet
/// line, not the end. The decoder's figures are its own, added to the source's after each read.
fn pump_with(
    mut r: impl Read,
    format: StreamFormat,
    origin: &Origin<'_>,
    link: &Link,
    timeouts_read_empty: bool,
) -> std::io::Result<()> {
    let mut d = StreamDecoder::new(format);
    let mut buf = vec![0u8; 16 << 10];
    let (mut items, mut local) = (Vec::new(), SourceStats::default());
    let mut drain_until: Option<Instant> = None;
    let mut last_data = Instant::now();
    let result = loop {
        if drain_until.is_none() && link.stopping() {
            drain_until = Some(Instant::now() + DRAIN);
        }
        if drain_until.is_some_and(|t| Instant::now() >= t) {
            break Ok(());
        }
        match r.read(&mut buf) {
            Ok(0) if timeouts_read_empty && drain_until.is_none() => {}
            Ok(0) => break Ok(()),
            Ok(n) => {
                last_data = Instant::now();
                d.feed(&buf[..n], now_ns(), &mut local, &mut items);
                merge(link, &mut local, origin);
                if !link.send(&mut items, origin.topic) {
                    return Ok(());
                }
            }
            Err(e) if nothing_waiting(&e) => {
                // Nothing waiting: a stopping recording has all this peer sent.
                if drain_until.is_some() {
                    break Ok(());
                }
                if last_data.elapsed() >= IDLE_HALF_LINE && d.drop_partial(&mut local) {
                    merge(link, &mut local, origin);
                }
            }
            Err(e) => break Err(e),
        }
    };
    d.finish(now_ns(), &mut local, &mut items);
    merge(link, &mut local, origin);
    link.send(&mut items, origin.topic);
    result
}

/// Adds a stream's figures to its source's, its problems prefixed with the peer they came from.
fn merge(link: &Link, local: &mut SourceStats, origin: &Origin<'_>) {
    if *local == SourceStats::default() {
        return;
    }
    if let Some(peer) = &origin.peer {
        for p in &mut local.first_problems {
            *p = format!("{peer} {p}");
        }
    }
    lock(&link.stats).absorb(local);
    *local = SourceStats::default();
}

fn pump(
    r: impl Read,
    format: StreamFormat,
    topic: Option<&str>,
    link: &Link,
) -> std::io::Result<()> {
    pump_with(r, format, &Origin { peer: None, topic }, link, false)
}

/// Runs one source until it ends or the recorder stops. An error that ends the source for
/// good (a port that cannot be bound, a file that cannot be read, a panic) is returned as
/// well as counted; sources that reconnect (serial, TCP client) only count theirs.
pub fn run(spec: SourceSpec, link: Link) -> Result<(), SourceError> {
    isolated(&link, || run_until_end(spec, &link))
}

/// Runs a source's body so that whatever happens in it ends that source alone: a panic
/// becomes [`SourceError::Panicked`], counted, and its figures stay readable.
fn isolated(
    link: &Link,
    body: impl FnOnce() -> Result<(), SourceError>,
) -> Result<(), SourceError> {
    let result = catch_unwind(AssertUnwindSafe(body))
        .unwrap_or_else(|payload| Err(SourceError::Panicked(panic_text(&*payload))));
    let mut s = lock(&link.stats);
    s.connected = false;
    if let Err(e) = &result {
        s.last_error = Some(e.to_string());
        if matches!(e, SourceError::Panicked(_)) {
            s.count("source ended by an internal error");
        }
    }
    result
}

fn run_until_end(spec: SourceSpec, link: &Link) -> Result<(), SourceError> {
    lock(&link.stats).connected = true;
    match spec {
        SourceSpec::Udp { addr } => udp(addr, link),
        SourceSpec::TcpListen {
            addr,
            format,
            topic,
        } => tcp_listen(addr, format, topic, link),
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
                pump(conn, format, topic.as_deref(), link).map_err(|source| SourceError::Connect {
                    addr: addr.clone(),
                    source,
                })
            };
            with_reconnects(link, open, run);
            Ok(())
        }
        SourceSpec::Stdin { format, topic } => {
            pump(std::io::stdin().lock(), format, topic.as_deref(), link)
                .map_err(SourceError::Stdin)
        }
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
            pump(f, format, topic.as_deref(), link).map_err(on_path)
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
            let origin = Origin {
                peer: None,
                topic: topic.as_deref(),
            };
            let run = |port| pump_with(port, format, &origin, link, true).map_err(on_path);
            with_reconnects(link, open, run);
            Ok(())
        }
        SourceSpec::Simulated {
            scenario,
            seed,
            speed,
            duration_s,
        } => simulated(&scenario, seed, speed, duration_s, link),
        SourceSpec::Can { adapter, dbc } => super::can::run(&adapter, dbc, link),
    }
}

/// How often a blocking read wakes to see whether the recorder is stopping.
const TICK: Duration = Duration::from_millis(200);

/// JSON lines in UDP datagrams on `addr`, until the recorder stops. The receive buffer is
/// sized for bursts ([`UDP_RECEIVE_BUFFER`]) and the kernel's own drops (a full buffer) are
/// read from each datagram (`SO_RXQ_OVFL`) and counted, as tcpdump reports "packets dropped
/// by kernel".
fn udp(addr: std::net::SocketAddr, link: &Link) -> Result<(), SourceError> {
    let sock = UdpSocket::bind(addr)
        .and_then(|s| s.set_read_timeout(Some(TICK)).map(|()| s))
        .map_err(|source| SourceError::Bind { addr, source })?;
    let granted = super::udp::size_receive_buffer(&sock, UDP_RECEIVE_BUFFER);
    if granted < UDP_RECEIVE_BUFFER {
        link.alert(format!(
            "udp {addr}: the kernel gives a receive buffer of {} KiB, not the {} KiB asked for \
             (net.core.rmem_max); bursts may be dropped, and are counted",
            granted >> 10,
            UDP_RECEIVE_BUFFER >> 10
        ));
    }
    let mut receiver = super::udp::Receiver::new(&sock);
    let mut buf = vec![0u8; 65_536];
    let (mut items, mut local) = (Vec::new(), SourceStats::default());
    let origin = Origin {
        peer: None,
        topic: None,
    };
    let (mut drain_until, mut kernel_dropped): (Option<Instant>, u64) = (None, 0);
    loop {
        if drain_until.is_none() && link.stopping() {
            drain_until = Some(Instant::now() + DRAIN);
        }
        if drain_until.is_some_and(|t| Instant::now() >= t) {
            return Ok(());
        }
        match receiver.recv(&mut buf) {
            Ok((n, dropped_so_far)) => {
                let t = now_ns();
                // The kernel's count is the socket's total since it was made.
                local.kernel_dropped = dropped_so_far.saturating_sub(kernel_dropped);
                kernel_dropped = kernel_dropped.max(dropped_so_far);
                if n == buf.len() {
                    local.oversized += 1;
                    local.skip(
                        "datagram over 64 KiB",
                        "datagram",
                        &"truncated by the socket",
                    );
                } else {
                    // Each datagram holds whole lines; a fresh decoder per datagram keeps a
                    // torn one from corrupting the next.
                    let mut d = StreamDecoder::new(StreamFormat::JsonLines);
                    d.feed(&buf[..n], t, &mut local, &mut items);
                    d.finish(t, &mut local, &mut items);
                }
                merge(link, &mut local, &origin);
                if !link.send(&mut items, None) {
                    return Ok(());
                }
            }
            Err(e) if nothing_waiting(&e) => {
                if drain_until.is_some() {
                    return Ok(());
                }
            }
            Err(e) => lock(&link.stats).last_error = Some(e.to_string()),
        }
    }
}

/// A TCP listener on `addr`: each connection read on its own thread (at most
/// [`MAX_CONNECTIONS`] at once), until the recorder stops.
fn tcp_listen(
    addr: std::net::SocketAddr,
    format: StreamFormat,
    topic: Option<String>,
    link: &Link,
) -> Result<(), SourceError> {
    let listener = TcpListener::bind(addr)
        .and_then(|l| l.set_nonblocking(true).map(|()| l))
        .map_err(|source| SourceError::Bind { addr, source })?;
    let live = Arc::new(AtomicUsize::new(0));
    let mut backoff = Duration::ZERO;
    std::thread::scope(|scope| {
        while !link.stopping() {
            let (conn, peer) = match listener.accept() {
                Ok(accepted) => accepted,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                Err(e) => {
                    // Out of file descriptors (EMFILE) and the like: back off instead of
                    // spinning, and say so at once.
                    backoff = next_backoff(backoff);
                    link.alert(format!(
                        "tcp {addr}: cannot accept a connection: {e}; retrying every {} ms",
                        backoff.as_millis()
                    ));
                    sleep_unless_stopping(link, backoff);
                    continue;
                }
            };
            if live.load(Ordering::Relaxed) >= MAX_CONNECTIONS {
                let at = format!("connection from {peer}");
                let why = format!("{MAX_CONNECTIONS} connections already open");
                lock(&link.stats).skip("connection refused: too many open", &at, &why);
                continue;
            }
            let (conn_link, topic, live_now) = (link.clone(), topic.clone(), live.clone());
            live.fetch_add(1, Ordering::Relaxed);
            let serve = move || {
                serve_connection(conn, peer, format, topic.as_deref(), &conn_link);
                live_now.fetch_sub(1, Ordering::Relaxed);
            };
            let spawned = std::thread::Builder::new()
                .name(format!("tcp {peer}"))
                .stack_size(256 << 10)
                .spawn_scoped(scope, serve);
            match spawned {
                Ok(_) => backoff = Duration::ZERO,
                Err(e) => {
                    live.fetch_sub(1, Ordering::Relaxed);
                    backoff = next_backoff(backoff);
                    link.alert(format!(
                        "tcp {addr}: cannot start a thread for the connection from {peer}: {e}; \
                         it was closed, the listener goes on"
                    ));
                    sleep_unless_stopping(link, backoff);
                }
            }
        }
    });
    Ok(())
}

/// One accepted connection read until it closes or the recording stops; an internal error
/// ends this connection only, counted with its cause.
fn serve_connection(
    conn: TcpStream,
    peer: std::net::SocketAddr,
    format: StreamFormat,
    topic: Option<&str>,
    link: &Link,
) {
    let origin = Origin {
        peer: Some(peer.to_string()),
        topic,
    };
    let _ = conn.set_nonblocking(false);
    let _ = conn.set_read_timeout(Some(TICK));
    match catch_unwind(AssertUnwindSafe(|| {
        pump_with(conn, format, &origin, link, false)
    })) {
        Ok(Ok(())) => {}
        Ok(Err(e)) => lock(&link.stats).last_error = Some(format!("{peer}: {e}")),
        Err(payload) => {
            let why = panic_text(&*payload);
            let at = format!("connection from {peer}");
            lock(&link.stats).skip("connection ended by an internal error", &at, &why);
        }
    }
}

/// Out of file descriptors (EMFILE), out of threads: wait twice as long as last time, from
/// 50 ms up to a second, instead of spinning.
fn next_backoff(backoff: Duration) -> Duration {
    (backoff * 2).clamp(Duration::from_millis(50), Duration::from_secs(1))
}

fn sleep_unless_stopping(link: &Link, d: Duration) {
    let until = Instant::now() + d;
    while Instant::now() < until && !link.stopping() {
        std::thread::sleep(Duration::from_millis(20).min(d));
    }
}

/// Opens a connection (a TCP receiver, a serial device) and reads it, again and again until
/// the recorder stops: 0.25 s between attempts, doubling to 8 s, back to 0.25 s after a
/// success; a connection after an earlier one counts as a reconnect.
fn with_reconnects<C>(
    link: &Link,
    mut open: impl FnMut() -> Result<C, SourceError>,
    mut run: impl FnMut(C) -> Result<(), SourceError>,
) {
    const FIRST: Duration = Duration::from_millis(250);
    let (mut backoff, mut connected_before) = (FIRST, false);
    while !link.stopping() {
        match open() {
            Ok(connection) => {
                {
                    let mut s = lock(&link.stats);
                    s.reconnects += u64::from(connected_before);
                    s.connected = true;
                }
                (backoff, connected_before) = (FIRST, true);
                if let Err(e) = run(connection) {
                    lock(&link.stats).last_error = Some(e.to_string());
                }
            }
            Err(e) => lock(&link.stats).last_error = Some(e.to_string()),
        }
        lock(&link.stats).connected = false;
        sleep_unless_stopping(link, backoff);
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
    link: &Link,
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
        if link.stopping() {
            break;
        }
        let LogRecord::Message(m) = rec? else {
            continue;
        };
        let t0 = *sim0.get_or_insert(m.log_time_ns);
        let offset = m.log_time_ns.saturating_sub(t0);
        let due = wall0 + Duration::from_nanos((offset as f64 / speed) as u64);
        while Instant::now() < due && !link.stopping() {
            std::thread::sleep((due - Instant::now()).min(Duration::from_millis(50)));
        }
        // Shift the run onto the live clock: sensor and log times keep their spacing.
        let shift = |t: u64| live0 + ((t.saturating_sub(t0)) as f64 / speed) as u64;
        // Messages of kinds the catalogue does not know are passed over.
        let Some(mut message) = m.decode_any(&path)? else {
            continue;
        };
        let stamp = message.stamp_ns_mut();
        *stamp = shift(*stamp);
        lock(&link.stats).received += 1;
        items.push(Item {
            topic: m.channel.topic.clone(),
            log_time_ns: shift(m.log_time_ns),
            message,
        });
        if !link.send(&mut items, None) {
            break;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_while_holding_the_figures_ends_that_source_alone_with_its_reason_counted() {
        let (queue, _rx) = flume::bounded(4);
        let (alerts, _a) = flume::unbounded();
        let link = Link {
            queue,
            stats: Stats::default(),
            stop: Arc::default(),
            alerts,
        };
        let result = isolated(&link, || {
            let mut s = lock(&link.stats);
            s.received += 1;
            panic!("a decoder bug");
        });
        assert!(matches!(result, Err(SourceError::Panicked(ref m)) if m == "a decoder bug"));
        // The lock it died holding is poisoned, and still reads.
        assert!(link.stats.is_poisoned());
        let s = lock(&link.stats);
        assert_eq!(
            (s.received, s.skipped["source ended by an internal error"]),
            (1, 1)
        );
        assert!(s.last_error.as_ref().unwrap().contains("a decoder bug"));
    }
}
