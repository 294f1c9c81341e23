//! The log format of can-utils' `candump -l` (`candump -L` writes the same lines to stdout):
//!
//! ```text
//! (1700000000.123456) can0 123#DEADBEEF        classic, 11-bit id
//! (1700000000.123457) can0 12345678#01         29-bit id (eight hex digits)
//! (1700000000.123458) can0 123#R               remote request (R4: with its DLC)
//! (1700000000.123459) can0 123##3112233        FD: a flags digit (1 BRS, 2 ESI), then data
//! (1700000000.123460) can0 20000080#0000000000000000   error frame (CAN_ERR_FLAG in the id)
//! ```
//!
//! A line that does not parse is skipped and reported with its number; a line longer than
//! [`MAX_LINE`] is refused unread ([`crate::lines`]).

use std::io::BufRead;

use crate::frame::{Frame, ERROR_FLAG, MAX_CLASSIC_LEN, MAX_FD_LEN};
use crate::lines::Lines;
pub use crate::lines::{BadLine, MAX_LINE};

/// One `candump -l` line as a frame.
pub fn parse_line(line: &str) -> Result<Frame, String> {
    let line = line.trim();
    let rest = line
        .strip_prefix('(')
        .ok_or("no '(' opening the time stamp")?;
    let (stamp, rest) = rest
        .split_once(')')
        .ok_or("no ')' closing the time stamp")?;
    let stamp_ns = parse_stamp(stamp)?;
    let mut fields = rest.split_whitespace();
    let bus = fields.next().ok_or("no interface after the time stamp")?;
    let body = fields.next().ok_or("no frame after the interface")?;
    // candump -l may add a direction (R/T) after the frame; nothing else follows.
    if fields.nth(1).is_some() {
        return Err(format!("more fields than a frame after '{body}'"));
    }
    let mut frame = parse_body(body)?;
    frame.stamp_ns = stamp_ns;
    frame.bus = bus.to_owned();
    Ok(frame)
}

/// `seconds.fraction` since the Unix epoch, as ns.
pub(crate) fn parse_stamp(s: &str) -> Result<u64, String> {
    let bad = || format!("time stamp '{s}' is not seconds.microseconds");
    let (secs, frac) = s.split_once('.').unwrap_or((s, ""));
    if secs.is_empty()
        || frac.len() > 9
        || !(secs.bytes().chain(frac.bytes())).all(|b| b.is_ascii_digit())
    {
        return Err(bad());
    }
    let secs: u64 = secs.parse().map_err(|_| bad())?;
    let frac_ns: u64 = match frac.is_empty() {
        true => 0,
        false => frac.parse::<u64>().map_err(|_| bad())? * 10u64.pow(9 - frac.len() as u32),
    };
    secs.checked_mul(1_000_000_000)
        .and_then(|ns| ns.checked_add(frac_ns))
        .ok_or_else(bad)
}

/// `ID#DATA`, `ID#R[DLC]` or `ID##FLAGSDATA`.
fn parse_body(body: &str) -> Result<Frame, String> {
    let (id, rest) = body
        .split_once('#')
        .ok_or_else(|| format!("frame '{body}' has no '#'"))?;
    let raw_id = match id.len() {
        3 | 8 => u32::from_str_radix(id, 16).map_err(|_| format!("id '{id}' is not hex"))?,
        n => {
            return Err(format!(
                "id '{id}' has {n} digits: 3 (11-bit) or 8 (29-bit)"
            ))
        }
    };
    let error = id.len() == 8 && raw_id & ERROR_FLAG != 0;
    let extended = id.len() == 8 && !error;
    let id_value = match (error, extended) {
        (true, _) => raw_id & !ERROR_FLAG & 0x1FFF_FFFF,
        (false, true) if raw_id > 0x1FFF_FFFF => {
            return Err(format!("id '{id}' is beyond 29 bits"))
        }
        (false, true) => raw_id,
        (false, false) if raw_id > 0x7FF => return Err(format!("id '{id}' is beyond 11 bits")),
        (false, false) => raw_id,
    };
    let mut frame = Frame {
        stamp_ns: 0,
        bus: String::new(),
        id: id_value,
        extended,
        rtr: false,
        error,
        fd: false,
        brs: false,
        esi: false,
        data: Vec::new(),
    };
    if let Some(fd) = rest.strip_prefix('#') {
        let mut chars = fd.chars();
        let flags = chars
            .next()
            .and_then(|c| c.to_digit(16))
            .ok_or_else(|| format!("FD frame '{body}' has no flags digit after '##'"))?;
        frame.fd = true;
        frame.brs = flags & 1 != 0;
        frame.esi = flags & 2 != 0;
        frame.data = parse_data(chars.as_str(), MAX_FD_LEN)?;
        if !crate::frame::FD_LENGTHS.contains(&frame.data.len()) {
            return Err(format!(
                "FD frame of {} bytes: not a length a DLC gives",
                frame.data.len()
            ));
        }
    } else if let Some(dlc) = rest.strip_prefix('R').or_else(|| rest.strip_prefix('r')) {
        frame.rtr = true;
        if !dlc.is_empty() && !matches!(dlc.parse::<u8>(), Ok(0..=8)) {
            return Err(format!("remote request's DLC '{dlc}' is not 0-8"));
        }
    } else {
        // A classic frame may carry its raw DLC 9-15 after '_' (len8_dlc); the data is 8.
        let data = rest.split_once('_').map_or(rest, |(d, _)| d);
        frame.data = parse_data(data, MAX_CLASSIC_LEN)?;
    }
    Ok(frame)
}

/// Hex pairs (dots between bytes allowed, as cansend takes), at most `max` bytes.
pub(crate) fn parse_data(s: &str, max: usize) -> Result<Vec<u8>, String> {
    let hex: Vec<u8> = s.bytes().filter(|&b| b != b'.').collect();
    if !hex.len().is_multiple_of(2) {
        return Err(format!("data '{s}' has an odd number of hex digits"));
    }
    if hex.len() / 2 > max {
        return Err(format!("data of {} bytes, more than {max}", hex.len() / 2));
    }
    hex.chunks(2)
        .map(|p| {
            std::str::from_utf8(p)
                .ok()
                .and_then(|p| u8::from_str_radix(p, 16).ok())
                .ok_or_else(|| format!("data '{s}' is not hex"))
        })
        .collect()
}

/// A `candump -l` log read line by line: each item a frame, or a line that did not parse.
pub struct Reader<R> {
    lines: Lines<R>,
}

impl<R: BufRead> Reader<R> {
    pub fn new(input: R) -> Self {
        Self {
            lines: Lines::new(input),
        }
    }
}

impl<R> Reader<R> {
    /// Lines read so far.
    pub fn lines_read(&self) -> usize {
        self.lines.count()
    }
}

impl<R: BufRead> Iterator for Reader<R> {
    type Item = Result<Frame, BadLine>;

    fn next(&mut self) -> Option<Self::Item> {
        let (line, text) = match self.lines.next_line()? {
            Ok(l) => l,
            Err(e) => return Some(Err(e)),
        };
        Some(parse_line(text).map_err(|reason| BadLine { line, reason }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_of_line_parses_and_a_bad_one_names_its_number() {
        let log = "(1700000000.123456) can0 123#DEADBEEF\n\
                   (1700000000.5) can1 12345678#01\n\
                   \n\
                   (1700000001.000001) can0 7FF#R4\n\
                   (1700000001.000002) can0 123##3112233\n\
                   (1700000001.000003) can0 20000080#0000000000000000\n\
                   (1700000001.000004) can0 12#00\n\
                   (1700000001.000005) can0 123#00112233445566778899\n";
        let items: Vec<_> = Reader::new(log.as_bytes()).collect();
        assert_eq!(items.len(), 7);
        let f = items[0].as_ref().unwrap();
        assert_eq!(
            (f.stamp_ns, f.bus.as_str(), f.id, f.extended, f.data.clone()),
            (
                1_700_000_000_123_456_000,
                "can0",
                0x123,
                false,
                vec![0xDE, 0xAD, 0xBE, 0xEF]
            )
        );
        let f = items[1].as_ref().unwrap();
        assert!(f.extended && f.id == 0x1234_5678 && f.stamp_ns == 1_700_000_000_500_000_000);
        let f = items[2].as_ref().unwrap();
        assert!(f.rtr && f.id == 0x7FF && f.data.is_empty());
        let f = items[3].as_ref().unwrap();
        assert!(f.fd && f.brs && f.esi && f.data == vec![0x11, 0x22, 0x33]);
        let f = items[4].as_ref().unwrap();
        assert!(f.error && f.id == 0x80 && !f.extended);
        assert_eq!(
            items[5].as_ref().unwrap_err(),
            &BadLine {
                line: 7,
                reason: "id '12' has 2 digits: 3 (11-bit) or 8 (29-bit)".into()
            }
        );
        assert_eq!(items[6].as_ref().unwrap_err().line, 8);
    }

    #[test]
    fn an_overlong_line_is_refused_and_the_next_one_read() {
        let log = format!(
            "(1.0) can0 123#{}\n(2.0) can0 123#01\n",
            "0".repeat(4 * MAX_LINE)
        );
        let items: Vec<_> = Reader::new(log.as_bytes()).collect();
        assert_eq!(items.len(), 2);
        assert!(items[0]
            .as_ref()
            .unwrap_err()
            .reason
            .contains("longer than"));
        assert_eq!(items[1].as_ref().unwrap().data, vec![1]);
    }
}
