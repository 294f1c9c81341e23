//! A socketcand server: greeted, the bus opened in raw mode, then its elements read
//! ([`railfuse_can::socketcand`]).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use railfuse_can::socketcand;

use super::frames::{pump, Frames};
use crate::recorder::link::nothing_waiting;

/// How often a blocking read wakes to see whether the recorder is stopping.
const TICK: Duration = Duration::from_millis(100);
/// How long a socketcand server has to answer each step of the handshake.
const HANDSHAKE: Duration = Duration::from_secs(5);

/// A socketcand server: greeted, the bus opened in raw mode, then its frames read.
pub(super) fn run(addr: &str, bus: &str, out: &mut Frames<'_>) -> Result<(), String> {
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
                Err(e) if nothing_waiting(&e) => {}
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
