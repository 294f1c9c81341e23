//! An SLCAN adapter on a serial line: closed, set to the bit rate and opened, then read line
//! by line ([`railfuse_can::slcan`]).

use std::io::Write;

use railfuse_can::slcan;

use super::frames::{pump, Frames};

/// An SLCAN adapter on a serial line: closed, set to the bit rate and opened, then read.
pub(super) fn run(
    path: &std::path::Path,
    bitrate: u32,
    baud: u32,
    out: &mut Frames<'_>,
) -> Result<(), String> {
    let mut port = crate::recorder::serial::open(path, baud).map_err(|e| e.to_string())?;
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
