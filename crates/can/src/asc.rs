//! Vector's ASC log (CANalyzer and CANoe's ASCII logging), as python-can's `ASCReader` reads
//! it:
//!
//! ```text
//! date Sat Dec 5 10:00:00.000 am 2026
//! base hex  timestamps absolute
//! Begin Triggerblock Sat Dec 5 10:00:00.000 am 2026
//!    0.012345 1  123             Rx   d 8 11 22 33 44 55 66 77 88
//!    0.013000 1  1234567x        Rx   d 2 AA BB          (x: a 29-bit id)
//!    0.014000 1  123             Rx   r                  (remote request)
//!    0.015000 1  ErrorFrame
//!    0.016000 CANFD   1 Rx        123  Name  1 0 9 12 11 22 33 44 55 66 77 88 99 AA BB CC
//! End TriggerBlock
//! ```
//!
//! Ids and data are hex or decimal as the header's `base` says. A line's time is seconds
//! from the trigger block's start, whose date (the logger's local time, with no zone) is
//! taken as UTC. Channels count from 1 in the file; a frame's bus is `CAN<n>`. Lines that are
//! not frames (comments, statistics, J1939, the start of measurement) are skipped; a frame
//! line that does not parse is reported with its number.

use std::io::BufRead;

use chrono::NaiveDateTime;

use crate::frame::{Frame, FD_LENGTHS, MAX_CLASSIC_LEN, MAX_FD_LEN};
use crate::lines::{BadLine, Lines};

/// An ASC log read line by line: each item a frame, or a frame line that did not parse.
pub struct Reader<R> {
    lines: Lines<R>,
    radix: u32,
    start_ns: u64,
}

impl<R: BufRead> Reader<R> {
    pub fn new(input: R) -> Self {
        Self {
            lines: Lines::new(input),
            radix: 16,
            start_ns: 0,
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
        loop {
            let (line, text) = match self.lines.next_line()? {
                Ok(l) => l,
                Err(e) => return Some(Err(e)),
            };
            let lower = text.to_ascii_lowercase();
            let header = if let Some(rest) = lower.strip_prefix("base ") {
                self.radix = match rest.split_whitespace().next() {
                    Some("dec") => 10,
                    _ => 16,
                };
                Ok(())
            } else if let Some(date) = lower.strip_prefix("begin triggerblock") {
                parse_date(date).map(|ns| self.start_ns = ns)
            } else if let Some(date) = lower.strip_prefix("date ") {
                parse_date(date).map(|ns| self.start_ns = ns)
            } else {
                match frame_line(text, self.radix, self.start_ns) {
                    Some(parsed) => return Some(parsed.map_err(|reason| BadLine { line, reason })),
                    None => Ok(()),
                }
            };
            if let Err(reason) = header {
                return Some(Err(BadLine { line, reason }));
            }
        }
    }
}

/// `Sat Dec 5 10:00:00.000 am 2026` (weekday first; English or German month names; 12 or 24
/// hour), as ns since the Unix epoch, taken as UTC. An empty date (a trigger block without
/// one) leaves the start at 0.
fn parse_date(s: &str) -> Result<u64, String> {
    let mut words: Vec<String> = s.split_whitespace().skip(1).map(str::to_owned).collect();
    if words.is_empty() {
        return Ok(0);
    }
    const MONTHS: [(&str, u32); 16] = [
        ("jan", 1),
        ("feb", 2),
        ("mar", 3),
        ("mär", 3),
        ("apr", 4),
        ("may", 5),
        ("mai", 5),
        ("jun", 6),
        ("jul", 7),
        ("aug", 8),
        ("sep", 9),
        ("oct", 10),
        ("okt", 10),
        ("nov", 11),
        ("dec", 12),
        ("dez", 12),
    ];
    let month = MONTHS
        .iter()
        .find(|(name, _)| words[0].starts_with(name))
        .ok_or_else(|| format!("date '{s}': no month name"))?;
    words[0] = format!("{:02}", month.1);
    let text = words.join(" ");
    let formats = [
        "%m %d %I:%M:%S%.f %p %Y",
        "%m %d %I:%M:%S %p %Y",
        "%m %d %H:%M:%S%.f %Y",
        "%m %d %H:%M:%S %Y",
    ];
    let t = formats
        .iter()
        .find_map(|f| NaiveDateTime::parse_from_str(&text, f).ok())
        .ok_or_else(|| format!("date '{s}' is not month day time [am|pm] year"))?;
    let ns = t
        .and_utc()
        .timestamp_nanos_opt()
        .ok_or("date beyond 2262")?;
    u64::try_from(ns).map_err(|_| format!("date '{s}' before 1970"))
}

/// A frame line as a frame; `None` for a line that is not a frame.
fn frame_line(text: &str, radix: u32, start_ns: u64) -> Option<Result<Frame, String>> {
    let mut words = text.split_whitespace();
    let time = words.next()?;
    // A frame line starts with its seconds.
    if !time.contains('.') || !time.bytes().all(|b| b.is_ascii_digit() || b == b'.') {
        return None;
    }
    let channel = words.next()?;
    let rest: Vec<&str> = words.collect();
    let seconds: f64 = time.parse().ok()?;
    let stamp_ns = start_ns + (seconds * 1e9).round() as u64;
    let frame = |bus: String| Frame {
        stamp_ns,
        bus,
        id: 0,
        extended: false,
        rtr: false,
        error: false,
        fd: false,
        brs: false,
        esi: false,
        data: Vec::new(),
    };
    if channel.eq_ignore_ascii_case("canfd") {
        let (ch, body) = rest.split_first()?;
        let mut f = frame(format!("CAN{ch}"));
        return Some(fd_frame(body, radix, &mut f).map(|_| f));
    }
    if !channel.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let mut f = frame(format!("CAN{channel}"));
    match rest.first() {
        Some(w) if w.eq_ignore_ascii_case("errorframe") => {
            f.error = true;
            Some(Ok(f))
        }
        // Rx or Tx after the id: a frame; anything else (a statistic, a chip status) is not.
        Some(_) if matches!(rest.get(1), Some(&"Rx") | Some(&"Tx")) => {
            Some(classic_frame(&rest, radix, &mut f).map(|_| f))
        }
        _ => None,
    }
}

/// `<id>[x] Rx|Tx d <dlc> <bytes…>` or `<id>[x] Rx|Tx r [dlc]`.
fn classic_frame(words: &[&str], radix: u32, f: &mut Frame) -> Result<(), String> {
    (f.id, f.extended) = parse_id(words[0], radix)?;
    match words.get(2).map(|w| w.to_ascii_lowercase()).as_deref() {
        Some("r") => {
            f.rtr = true;
            Ok(())
        }
        Some("d") => {
            let dlc = words
                .get(3)
                .and_then(|d| usize::from_str_radix(d, radix).ok())
                .ok_or_else(|| format!("'{}' has no DLC after 'd'", words.join(" ")))?;
            // A classic frame's DLC 9–15 still carries 8 bytes.
            f.data = parse_bytes(&words[4..], dlc.min(MAX_CLASSIC_LEN), radix)?;
            Ok(())
        }
        _ => Err(format!(
            "'{}': neither data (d) nor a remote request (r)",
            words.join(" ")
        )),
    }
}

/// `<ch> Rx|Tx <id>[x] [name] <brs> <esi> <dlc> <length> <bytes…>`, `<ch>` already taken.
fn fd_frame(words: &[&str], radix: u32, f: &mut Frame) -> Result<(), String> {
    let bad = || format!("CANFD line '{}' is short", words.join(" "));
    let (_dir, id) = (
        words.first().ok_or_else(bad)?,
        words.get(1).ok_or_else(bad)?,
    );
    if id.eq_ignore_ascii_case("errorframe") {
        f.error = true;
        f.fd = true;
        return Ok(());
    }
    (f.id, f.extended) = parse_id(id, radix)?;
    f.fd = true;
    // The symbolic name is optional: the BRS flag is a digit, a name is not.
    let skip = if words
        .get(2)
        .is_some_and(|w| w.bytes().all(|b| b.is_ascii_digit()))
    {
        2
    } else {
        3
    };
    let field = |k: usize| words.get(skip + k).copied().ok_or_else(bad);
    f.brs = field(0)? == "1";
    f.esi = field(1)? == "1";
    let length: usize = field(3)?.parse().map_err(|_| {
        format!(
            "CANFD data length '{}' is not a number",
            field(3).unwrap_or("")
        )
    })?;
    if length == 0 {
        f.rtr = true;
        return Ok(());
    }
    if !FD_LENGTHS.contains(&length) || length > MAX_FD_LEN {
        return Err(format!(
            "CANFD data length {length}: not a length a DLC gives"
        ));
    }
    f.data = parse_bytes(&words[(skip + 4).min(words.len())..], length, radix)?;
    Ok(())
}

/// An id, `x` after it for 29 bits.
fn parse_id(s: &str, radix: u32) -> Result<(u32, bool), String> {
    let (digits, extended) = match s.strip_suffix(['x', 'X']) {
        Some(d) => (d, true),
        None => (s, false),
    };
    let id = u32::from_str_radix(digits, radix).map_err(|_| format!("id '{s}' is not a number"))?;
    let limit = if extended { 0x1FFF_FFFF } else { 0x7FF };
    if id > limit {
        return Err(format!(
            "id '{s}' is beyond {} bits",
            if extended { 29 } else { 11 }
        ));
    }
    Ok((id, extended))
}

/// The first `n` of `words` as bytes.
fn parse_bytes(words: &[&str], n: usize, radix: u32) -> Result<Vec<u8>, String> {
    if words.len() < n {
        return Err(format!("{} bytes of data, {n} declared", words.len()));
    }
    words[..n]
        .iter()
        .map(|w| u8::from_str_radix(w, radix).map_err(|_| format!("data byte '{w}' is not a byte")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classic_fd_remote_and_error_lines_read_and_other_events_are_skipped() {
        let asc = "date Sat Dec 5 10:00:00.000 am 2026\n\
                   base hex  timestamps absolute\n\
                   internal events logged\n\
                   // version 9.0.0\n\
                   Begin Triggerblock Sat Dec 5 10:00:00.000 am 2026\n\
                   0.000000 Start of measurement\n\
                   0.012345 1  123             Rx   d 8 11 22 33 44 55 66 77 88\n\
                   0.013000 2  1234567x        Tx   d 2 AA BB\n\
                   0.014000 1  7FF             Rx   r\n\
                   0.015000 1  ErrorFrame\n\
                   0.016000 CANFD   1 Rx        123  Name  1 0 9 12 11 22 33 44 55 66 77 88 99 AA BB CC\n\
                   0.017000 1  Statistic: D 0 R 0 XD 0 XR 0 E 0 O 0 B 0.00%\n\
                   0.018000 1  800             Rx   d 1 00\n\
                   End TriggerBlock\n";
        let items: Vec<_> = Reader::new(asc.as_bytes()).collect();
        assert_eq!(items.len(), 6, "{items:?}");
        let start = 1_796_464_800_000_000_000u64; // 2026-12-05 10:00:00 UTC
        let f = items[0].as_ref().unwrap();
        assert_eq!(
            (f.stamp_ns, f.bus.as_str(), f.id, f.data.len()),
            (start + 12_345_000, "CAN1", 0x123, 8)
        );
        let f = items[1].as_ref().unwrap();
        assert!(f.extended && f.id == 0x123_4567 && f.data == vec![0xAA, 0xBB] && f.bus == "CAN2");
        assert!(items[2].as_ref().unwrap().rtr);
        assert!(items[3].as_ref().unwrap().error);
        let f = items[4].as_ref().unwrap();
        assert!(f.fd && f.brs && !f.esi && f.data.len() == 12 && f.data[11] == 0xCC);
        assert_eq!(
            items[5].as_ref().unwrap_err(),
            &BadLine {
                line: 13,
                reason: "id '800' is beyond 11 bits".into()
            }
        );
    }
}
