//! The serial line protocol of SLCAN adapters (the Lawicel ASCII protocol of CANUSB,
//! CANable, USBtin and most USB dongles), as Linux's `slcan` driver and python-can speak it.
//!
//! The host opens the channel with a bit rate (`S0`–`S8`) and `O`; the adapter then sends
//! each frame as one line ended by `\r`:
//!
//! ```text
//! t1232DEAD      11-bit id 123, DLC 2, data DE AD
//! T123456781AA   29-bit id, DLC 1
//! r1230          remote request, DLC 0        R12345678 0: 29-bit remote
//! d123F<64 B>    FD (DLC F: 64 bytes)          D: 29-bit FD; b / B: FD with bit-rate switch
//! ```
//!
//! An adapter may append a 4-digit millisecond stamp (after `Z1`); it is read past, and the
//! recorder's receive time is the bus time. `\r` alone acknowledges a command, `\x07` refuses
//! one, `z`/`Z` acknowledge a transmission: none of those is a frame.

use crate::frame::{Frame, FD_LENGTHS, MAX_CLASSIC_LEN};

/// The longest line: `B`, 8 id digits, a DLC digit, 64 bytes of data and a stamp.
pub const MAX_LINE: usize = 1 + 8 + 1 + 128 + 4;

/// The `S` command of a bit rate (`S8` for 1 Mbit/s), or `None` for one SLCAN has no code for.
pub fn bitrate_command(bitrate: u32) -> Option<&'static str> {
    Some(match bitrate {
        10_000 => "S0\r",
        20_000 => "S1\r",
        50_000 => "S2\r",
        100_000 => "S3\r",
        125_000 => "S4\r",
        250_000 => "S5\r",
        500_000 => "S6\r",
        800_000 => "S7\r",
        1_000_000 => "S8\r",
        _ => return None,
    })
}

/// The bit rates SLCAN has a code for.
pub const BITRATES: [u32; 9] = [
    10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
];

/// What a line is.
#[derive(Debug, Clone, PartialEq)]
pub enum Line {
    Frame(Frame),
    /// A reply to a command (`z`, `Z`, a version or status), not a frame.
    Reply,
}

/// One line (without its `\r`); the frame's `stamp_ns` and `bus` are the caller's to set.
pub fn parse_line(line: &[u8]) -> Result<Line, String> {
    let text = std::str::from_utf8(line).map_err(|_| "not ASCII".to_owned())?;
    let Some(kind) = text.chars().next() else {
        return Ok(Line::Reply);
    };
    let (extended, rtr, fd, brs) = match kind {
        't' => (false, false, false, false),
        'T' => (true, false, false, false),
        'r' => (false, true, false, false),
        'R' => (true, true, false, false),
        'd' => (false, false, true, false),
        'D' => (true, false, true, false),
        'b' => (false, false, true, true),
        'B' => (true, false, true, true),
        'z' | 'Z' | 'V' | 'v' | 'N' | 'F' => return Ok(Line::Reply),
        other => return Err(format!("'{other}' does not start a frame")),
    };
    let id_len = if extended { 8 } else { 3 };
    let rest = &text[1..];
    if rest.len() < id_len + 1 {
        return Err(format!("'{text}' is too short for its id and DLC"));
    }
    let id = u32::from_str_radix(&rest[..id_len], 16)
        .map_err(|_| format!("id '{}' is not hex", &rest[..id_len]))?;
    if id > if extended { 0x1FFF_FFFF } else { 0x7FF } {
        return Err(format!("id '{}' is beyond its bits", &rest[..id_len]));
    }
    let dlc = rest[id_len..id_len + 1]
        .chars()
        .next()
        .and_then(|c| c.to_digit(16))
        .ok_or_else(|| format!("DLC '{}' is not hex", &rest[id_len..id_len + 1]))?
        as usize;
    let len = match fd {
        true => FD_LENGTHS[dlc],
        false if dlc > MAX_CLASSIC_LEN => return Err(format!("DLC {dlc} is beyond 8")),
        false => dlc,
    };
    let data_hex = &rest[id_len + 1..];
    let data_digits = if rtr { 0 } else { 2 * len };
    // What follows the data is a 4-digit stamp, or nothing.
    if data_hex.len() != data_digits && data_hex.len() != data_digits + 4 {
        return Err(format!(
            "'{text}' has {} digits after its DLC {dlc}: {data_digits} (or 4 more with a stamp)",
            data_hex.len()
        ));
    }
    let data = match rtr {
        true => Vec::new(),
        false => crate::candump::parse_data(&data_hex[..data_digits], 64)?,
    };
    Ok(Line::Frame(Frame {
        stamp_ns: 0,
        bus: String::new(),
        id,
        extended,
        rtr,
        error: false,
        fd,
        brs,
        esi: false,
        data,
    }))
}

/// The line of `frame` as an adapter sends it (for tests and simulated adapters).
pub fn format_line(frame: &Frame) -> String {
    let kind = match (frame.extended, frame.rtr, frame.fd, frame.brs) {
        (false, true, ..) => 'r',
        (true, true, ..) => 'R',
        (false, _, false, _) => 't',
        (true, _, false, _) => 'T',
        (false, _, true, false) => 'd',
        (true, _, true, false) => 'D',
        (false, _, true, true) => 'b',
        (true, _, true, true) => 'B',
    };
    let id = match frame.extended {
        true => format!("{:08X}", frame.id),
        false => format!("{:03X}", frame.id),
    };
    let dlc = match frame.fd {
        true => FD_LENGTHS
            .iter()
            .position(|&l| l == frame.data.len())
            .unwrap_or(15),
        false => frame.data.len(),
    };
    let data: String = frame.data.iter().map(|b| format!("{b:02X}")).collect();
    format!("{kind}{id}{dlc:X}{data}\r")
}

/// Splits an adapter's byte stream into lines, bounded: a run of more than [`MAX_LINE`]
/// bytes without a `\r` is dropped whole (counted by the caller).
#[derive(Default)]
pub struct LineSplitter {
    buf: Vec<u8>,
    overlong: bool,
}

/// One piece of an adapter's stream.
#[derive(Debug, PartialEq)]
pub enum Piece<'a> {
    Line(&'a [u8]),
    /// `\x07`: the adapter refused a command.
    Refused,
    /// A line longer than [`MAX_LINE`], dropped.
    Overlong,
}

impl LineSplitter {
    /// Feeds `bytes`, calling `each` with every piece completed.
    pub fn feed(&mut self, bytes: &[u8], mut each: impl FnMut(Piece<'_>)) {
        for &b in bytes {
            match b {
                b'\r' | b'\n' => {
                    if self.overlong {
                        each(Piece::Overlong);
                    } else if !self.buf.is_empty() {
                        each(Piece::Line(&self.buf));
                    }
                    self.buf.clear();
                    self.overlong = false;
                }
                0x07 => each(Piece::Refused),
                _ if self.overlong => {}
                _ if self.buf.len() >= MAX_LINE => {
                    self.overlong = true;
                    self.buf.clear();
                }
                _ => self.buf.push(b),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(line: &str) -> Frame {
        match parse_line(line.as_bytes()).unwrap() {
            Line::Frame(f) => f,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn every_kind_of_line_reads_and_writes_back_and_bad_ones_say_why() {
        let f = frame("t1232DEAD");
        assert_eq!(
            (f.id, f.extended, f.data.clone()),
            (0x123, false, vec![0xDE, 0xAD])
        );
        let f = frame("T123456781AA1234");
        assert!(
            f.extended && f.id == 0x1234_5678 && f.data == [0xAA],
            "stamp read past"
        );
        assert!(frame("r1230").rtr && frame("R123456784").extended);
        let fd = frame(&format!("B1ABCDEF0F{}", "11".repeat(64)));
        assert!(fd.fd && fd.brs && fd.data.len() == 64);
        for line in [
            "t1232DEAD",
            "T123456781AA",
            "r1230",
            "d1239112233445566778899AABBCC",
        ] {
            let f = frame(line);
            assert_eq!(format_line(&f), format!("{line}\r"), "{f:?}");
        }
        assert_eq!(parse_line(b"z").unwrap(), Line::Reply);
        assert!(parse_line(b"t8002AAAA").unwrap_err().contains("beyond"));
        assert!(parse_line(b"t1239").unwrap_err().contains("beyond 8"));
        assert!(parse_line(b"t1232DEA")
            .unwrap_err()
            .contains("digits after"));
        assert!(parse_line(b"x").unwrap_err().contains("does not start"));
        assert!(parse_line(b"tXYZ0").unwrap_err().contains("not hex"));
    }

    #[test]
    fn the_stream_splits_at_carriage_returns_and_an_overlong_line_is_dropped() {
        let mut s = LineSplitter::default();
        let mut got = Vec::new();
        let mut stream = b"t1230\rt12".to_vec();
        stream.extend(b"31AA\r\x07");
        stream.extend(vec![b'1'; MAX_LINE + 5]);
        stream.extend(b"\rt1230\r");
        s.feed(&stream[..4], |p| got.push(format!("{p:?}")));
        s.feed(&stream[4..], |p| got.push(format!("{p:?}")));
        assert_eq!(got.len(), 5, "{got:?}");
        assert!(got[1].contains("[116, 49, 50, 51, 49, 65, 65]"));
        assert_eq!(got[2], "Refused");
        assert_eq!(got[3], "Overlong");
    }
}
