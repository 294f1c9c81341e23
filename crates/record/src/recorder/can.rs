//! The vehicle's CAN bus as a recorder source: SocketCAN, an SLCAN serial adapter, a
//! socketcand server or a cannelloni gateway. Each frame is logged whole on
//! `/can/<bus>/frames` and, with the vehicle's DBC, decoded ([`CanDecoder`]).
//!
//! An adapter that goes away mid-run (a dongle unplugged, a gateway's connection lost) ends
//! that source with its reason; the recording and the other sources go on. What an adapter
//! sends that is not a frame is skipped and counted with where it was; drops are counted
//! where they can be seen: the kernel's on a full socket buffer (SocketCAN, cannelloni), the
//! gateway's sequence gaps (cannelloni), the recorder's own full queue (every source).

use std::io::{Read, Write};
use std::net::{TcpStream, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant};

use railfuse_can::dbc::Database;
use railfuse_can::frame::Frame;
use railfuse_can::{cannelloni, slcan, socketcand};
use railfuse_catalog::messages::SourceStats;

use super::source_spec::CanAdapter;
use super::sources::{lock, now_ns, Link, DRAIN, UDP_RECEIVE_BUFFER};
use crate::decode::can::CanDecoder;
use crate::error::SourceError;

/// How often a blocking read wakes to see whether the recorder is stopping.
const TICK: Duration = Duration::from_millis(100);
/// How long a socketcand server has to answer each step of the handshake.
const HANDSHAKE: Duration = Duration::from_secs(5);

/// Records `adapter` until it ends or the recorder stops.
pub(super) fn run(
    adapter: &CanAdapter,
    dbc: Option<Arc<Database>>,
    link: &Link,
) -> Result<(), SourceError> {
    let mut out = Frames {
        decoder: CanDecoder::new(dbc),
        bus: adapter.bus(),
        link,
        local: SourceStats::default(),
        items: Vec::new(),
    };
    let fail = |cause: String| SourceError::Can {
        adapter: adapter.to_string(),
        cause,
    };
    match adapter {
        CanAdapter::SocketCan { iface } => super::socketcan::run(iface, &mut out).map_err(fail),
        CanAdapter::Slcan {
            path,
            bitrate,
            baud,
        } => slcan_adapter(path, *bitrate, *baud, &mut out).map_err(fail),
        CanAdapter::Socketcand { addr, bus } => {
            socketcand_server(addr, bus, &mut out).map_err(fail)
        }
        CanAdapter::Cannelloni { addr, .. } => cannelloni_gateway(*addr, &mut out).map_err(fail),
    }
}

/// Where a source's frames go: decoded into items, counted, queued.
pub(super) struct Frames<'a> {
    decoder: CanDecoder,
    bus: String,
    link: &'a Link,
    pub(super) local: SourceStats,
    items: Vec<crate::recorder::message::Item>,
}

impl Frames<'_> {
    /// One frame at bus time `stamp_ns` (None: the receive time), received now.
    pub(super) fn frame(&mut self, mut frame: Frame, stamp_ns: Option<u64>) {
        let receive_ns = now_ns();
        frame.stamp_ns = stamp_ns.unwrap_or(receive_ns);
        frame.bus.clone_from(&self.bus);
        self.decoder
            .frame(&frame, receive_ns, &mut self.local, &mut self.items);
    }

    /// Queues what was decoded and adds the figures to the source's; false when the recorder
    /// has gone.
    pub(super) fn flush(&mut self) -> bool {
        if self.local != SourceStats::default() {
            lock(&self.link.stats).absorb(&self.local);
            self.local = SourceStats::default();
        }
        self.link.send(&mut self.items, None)
    }

    pub(super) fn stopping(&self) -> bool {
        self.link.stop.load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// Reads `r` until it ends, fails, or the recorder stops (then for up to [`DRAIN`] while
/// bytes keep coming), each read handed to `feed`. A tty's timed-out read returns 0 bytes,
/// as does one whose device is gone: `tty_hung_up` tells them apart (None: a socket, whose
/// 0 bytes are its end).
fn pump(
    mut r: impl Read,
    out: &mut Frames<'_>,
    tty_hung_up: Option<&dyn Fn() -> bool>,
    mut feed: impl FnMut(&[u8], &mut Frames<'_>),
) -> Result<(), String> {
    let mut buf = vec![0u8; 64 << 10];
    let mut drain_until: Option<Instant> = None;
    loop {
        if drain_until.is_none() && out.stopping() {
            drain_until = Some(Instant::now() + DRAIN);
        }
        if drain_until.is_some_and(|t| Instant::now() >= t) {
            return Ok(());
        }
        match r.read(&mut buf) {
            Ok(0) if drain_until.is_some() => return Ok(()),
            Ok(0) => match tty_hung_up {
                Some(hung_up) if !hung_up() => {}
                Some(_) => return Err("went away (the line hung up)".into()),
                None => return Err("the adapter closed the connection".into()),
            },
            Ok(n) => {
                feed(&buf[..n], out);
                if !out.flush() {
                    return Ok(());
                }
            }
            Err(e) if super::sources::nothing_waiting(&e) => {
                if drain_until.is_some() {
                    return Ok(());
                }
            }
            Err(e) => return Err(format!("went away: {e}")),
        }
    }
}

/// An SLCAN adapter on a serial line: closed, set to the bit rate and opened, then read.
fn slcan_adapter(
    path: &std::path::Path,
    bitrate: u32,
    baud: u32,
    out: &mut Frames<'_>,
) -> Result<(), String> {
    let mut port = super::serial::open(path, baud).map_err(|e| e.to_string())?;
    let speed = slcan::bitrate_command(bitrate).ok_or("no SLCAN code for the bit rate")?;
    // Closed first: an adapter left open by a crashed run refuses a new bit rate.
    for command in ["C\r", speed, "O\r"] {
        port.write_all(command.as_bytes())
            .map_err(|e| format!("cannot open the channel: {e}"))?;
    }
    let mut lines = slcan::LineSplitter::default();
    let mut line_no = 0u64;
    let fd = std::os::fd::AsRawFd::as_raw_fd(&port);
    let hung_up = move || {
        let mut p = libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one live pollfd; a zero timeout only looks.
        let n = unsafe { libc::poll(&mut p, 1, 0) };
        n > 0 && p.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0
    };
    let result = pump(&mut port, out, Some(&hung_up), |bytes, out| {
        lines.feed(bytes, |piece| {
            line_no += 1;
            match piece {
                slcan::Piece::Line(l) => match slcan::parse_line(l) {
                    Ok(slcan::Line::Frame(f)) => out.frame(f, None),
                    Ok(slcan::Line::Reply) => {}
                    Err(e) => out.local.skip(
                        "SLCAN line that does not parse",
                        &format!("line {line_no}"),
                        &e,
                    ),
                },
                slcan::Piece::Refused => out.local.count("command the SLCAN adapter refused"),
                slcan::Piece::Overlong => {
                    out.local.oversized += 1;
                    out.local.count("SLCAN line over its longest")
                }
            }
        })
    });
    // Closed again where the line is still there, so the adapter stops sending.
    let _ = port.write_all(b"C\r");
    result
}

/// A socketcand server: greeted, the bus opened in raw mode, then its frames read.
fn socketcand_server(addr: &str, bus: &str, out: &mut Frames<'_>) -> Result<(), String> {
    let mut conn = TcpStream::connect(addr).map_err(|e| format!("cannot connect: {e}"))?;
    conn.set_read_timeout(Some(TICK))
        .map_err(|e| e.to_string())?;
    let mut elements = socketcand::ElementSplitter::default();
    let mut pending = Vec::new();
    let mut next = |conn: &mut TcpStream, pending: &mut Vec<String>| -> Result<String, String> {
        let until = Instant::now() + HANDSHAKE;
        let mut buf = [0u8; 512];
        while pending.is_empty() {
            if Instant::now() >= until {
                return Err("the server did not answer within 5 s".into());
            }
            match conn.read(&mut buf) {
                Ok(0) => return Err("the server closed the connection".into()),
                Ok(n) => elements.feed(&buf[..n], |p| {
                    if let socketcand::Piece::Element(e) = p {
                        pending.push(e.to_owned());
                    }
                }),
                Err(e) if super::sources::nothing_waiting(&e) => {}
                Err(e) => return Err(e.to_string()),
            }
        }
        Ok(pending.remove(0))
    };
    let expect = |got: String, want: socketcand::Element| match socketcand::parse_element(&got) {
        Ok(e) if e == want => Ok(()),
        _ => Err(format!(
            "the server said '< {} >' where {want:?} was due",
            got.trim()
        )),
    };
    expect(next(&mut conn, &mut pending)?, socketcand::Element::Hi)?;
    for command in socketcand::open_commands(bus) {
        conn.write_all(command.as_bytes())
            .map_err(|e| e.to_string())?;
        expect(next(&mut conn, &mut pending)?, socketcand::Element::Ok)?;
    }
    let mut element_no = 0u64;
    let mut take = |text: &str, out: &mut Frames<'_>| {
        element_no += 1;
        match socketcand::parse_element(text) {
            Ok(socketcand::Element::Frame(f)) => {
                let stamp = f.stamp_ns;
                out.frame(f, Some(stamp));
            }
            Ok(socketcand::Element::Refused(why)) => {
                out.local
                    .skip("socketcand error", &format!("element {element_no}"), &why)
            }
            Ok(_) => out.local.count("socketcand element that is not a frame"),
            Err(e) => out.local.skip(
                "socketcand element that does not parse",
                &format!("element {element_no}"),
                &e,
            ),
        }
    };
    for text in pending.drain(..) {
        take(&text, out);
    }
    pump(&mut conn, out, None, |bytes, out| {
        elements.feed(bytes, |piece| match piece {
            socketcand::Piece::Element(text) => take(text, out),
            socketcand::Piece::Unreadable => {
                out.local.oversized += 1;
                out.local
                    .count("socketcand element over its longest or not text")
            }
        })
    })
}

/// A cannelloni gateway's datagrams, with the kernel's drops and the gateway's sequence gaps.
fn cannelloni_gateway(addr: std::net::SocketAddr, out: &mut Frames<'_>) -> Result<(), String> {
    let sock = UdpSocket::bind(addr).map_err(|e| format!("cannot bind {addr}: {e}"))?;
    sock.set_read_timeout(Some(TICK))
        .map_err(|e| e.to_string())?;
    let granted = super::udp::size_receive_buffer(&sock, UDP_RECEIVE_BUFFER);
    if granted < UDP_RECEIVE_BUFFER {
        out.link
            .alerts
            .send(format!(
            "cannelloni {addr}: the kernel gives a receive buffer of {} KiB (net.core.rmem_max); \
             bursts may be dropped, and are counted",
            granted >> 10
        ))
            .ok();
    }
    let mut receiver = super::udp::Receiver::new(&sock);
    let mut buf = vec![0u8; 65_536];
    let (mut last_sequence, mut kernel_dropped, mut datagram) = (None::<u8>, 0u64, 0u64);
    let mut drain_until: Option<Instant> = None;
    loop {
        if drain_until.is_none() && out.stopping() {
            drain_until = Some(Instant::now() + DRAIN);
        }
        if drain_until.is_some_and(|t| Instant::now() >= t) {
            return Ok(());
        }
        match receiver.recv(&mut buf) {
            Ok((n, dropped_so_far)) => {
                datagram += 1;
                out.local.kernel_dropped += dropped_so_far.saturating_sub(kernel_dropped);
                kernel_dropped = kernel_dropped.max(dropped_so_far);
                match cannelloni::parse(&buf[..n]) {
                    Ok(d) => {
                        if let Some(last) = last_sequence {
                            let lost = cannelloni::lost_between(last, d.sequence);
                            // A gap of more than half the sequence space is a reordering or a
                            // restarted gateway, not a loss.
                            if lost > 0 && lost < 128 {
                                *out.local
                                    .warnings
                                    .entry("cannelloni datagrams lost (sequence gaps)".into())
                                    .or_insert(0) += lost;
                            }
                        }
                        last_sequence = Some(d.sequence);
                        for f in d.frames {
                            out.frame(f, None);
                        }
                    }
                    Err(e) => out.local.skip(
                        "cannelloni datagram that does not parse",
                        &format!("datagram {datagram}"),
                        &e,
                    ),
                }
                if !out.flush() {
                    return Ok(());
                }
            }
            Err(e) if super::sources::nothing_waiting(&e) => {
                if drain_until.is_some() {
                    return Ok(());
                }
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}
