//! Byte streams to messages, per format: JSON lines (sensor gateways), NMEA 0183 and u-blox
//! UBX (GNSS receivers). Every length is bounded and every checksum checked; what does not
//! decode is counted in the source's statistics and skipped, never fatal.

use crate::error::UnknownStreamFormat;
use railfuse_catalog::messages::{AnyMessage, GnssFix, SourceStats};
use railfuse_catalog::topics;

use super::message::{parse_json_line, Item};
use crate::decode::nmea::{self, Decoded, FixAssembler, NmeaError};
use crate::decode::ubx::{self, NavCov, NavHpPosLlh, NavPvt, PvtCovPairing, UbxError};

/// Longest line accepted on a text stream.
pub const MAX_LINE: usize = 64 << 10;

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(try_from = "String")]
pub enum StreamFormat {
    JsonLines,
    Nmea,
    Ubx,
}

impl TryFrom<String> for StreamFormat {
    type Error = UnknownStreamFormat;
    fn try_from(s: String) -> Result<Self, UnknownStreamFormat> {
        s.parse()
    }
}

impl std::str::FromStr for StreamFormat {
    type Err = UnknownStreamFormat;
    fn from_str(s: &str) -> Result<Self, UnknownStreamFormat> {
        Ok(match s {
            "json" => StreamFormat::JsonLines,
            "nmea" => StreamFormat::Nmea,
            "ubx" => StreamFormat::Ubx,
            _ => return Err(UnknownStreamFormat(s.to_owned())),
        })
    }
}

pub struct StreamDecoder {
    format: StreamFormat,
    buf: Vec<u8>,
    /// Discarding the rest of an oversized line.
    skipping: bool,
    /// Lines begun so far (text formats): the current line's number.
    lines: u64,
    /// Stream bytes before `buf[0]` (UBX): where a problem was.
    offset: u64,
    /// Inside a stretch of bytes that are not a frame (UBX), counted once when it ends; and
    /// whether that stretch is the rest of a frame already counted as refused.
    in_noise: Option<bool>,
    nmea: FixAssembler,
    pairing: PvtCovPairing,
    undated_pvt: u64,
    /// The clock a file's fixes are checked against for the week-number rollover (a live
    /// source's are checked against their receive time).
    opened_ns: u64,
}

/// Why a fix without a time was not written.
const NMEA_UNDATED: &str = "NMEA fixes with no date (no RMC/ZDA after them; give --date)";
/// A receiver's date this far before the clock is the GPS week-number rollover's (1024
/// weeks early; four weeks of margin for a capture read a little after it was made).
const ROLLOVER_NS: u64 = 1020 * 7 * 86_400 * 1_000_000_000;
const ROLLOVER_WARNING: &str = "GNSS fixes dated about 1024 weeks (19.6 years) before the \
                                clock: a receiver caught by the GPS week-number rollover? \
                                Kept as the receiver dated them";

const NMEA_UNTIMED: &str = "NMEA epochs the receiver sent without a time (no fix to stamp)";
const UBX_UNDATED: &str = "UBX NAV-PVT without a valid UTC time";

impl StreamDecoder {
    pub fn new(format: StreamFormat) -> Self {
        Self::with_date(format, None)
    }

    /// A decoder whose NMEA fixes take `date` until an RMC or ZDA says otherwise (an import
    /// of a capture whose first fixes come before any date).
    pub fn with_date(format: StreamFormat, date: Option<nmea::Date>) -> Self {
        Self {
            format,
            buf: Vec::new(),
            skipping: false,
            lines: 0,
            offset: 0,
            in_noise: None,
            nmea: FixAssembler::with_date(date),
            pairing: PvtCovPairing::default(),
            undated_pvt: 0,
            opened_ns: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64),
        }
    }

    /// Drops a half line held since its peer fell silent (text formats), counted; says
    /// whether there was one.
    pub fn drop_partial(&mut self, stats: &mut SourceStats) -> bool {
        if self.format == StreamFormat::Ubx || self.buf.is_empty() {
            return false;
        }
        let at = format!("line {}", self.lines + 1);
        let why = format!("{} bytes with no end of line, then silence", self.buf.len());
        stats.malformed += 1;
        stats.skip("half line left idle", &at, &why);
        // Its rest, should it ever come, is discarded up to the end of the line.
        (self.buf, self.skipping) = (Vec::new(), true);
        true
    }

    /// Lines read so far (text formats).
    pub fn lines(&self) -> u64 {
        self.lines
    }

    /// Where the problem at `buf[at]` (UBX) or on the current line (text) was.
    fn place(&self, at: usize) -> String {
        match self.format {
            StreamFormat::Ubx => format!("byte {}", self.offset + at as u64),
            _ => format!("line {}", self.lines),
        }
    }

    /// A NAV-PVT as a fix, stamped with its UTC or, from a live source, the receive time; a
    /// file's PVT without valid time has neither and is counted, never stamped 1970.
    fn push_pvt(
        &mut self,
        pvt: &NavPvt,
        cov: Option<[f64; 9]>,
        receive_ns: u64,
        stats: &mut SourceStats,
        out: &mut Vec<Item>,
    ) {
        match pvt.utc_ns.or((receive_ns > 0).then_some(receive_ns)) {
            Some(stamp) => push_fix(
                pvt.to_fix(stamp, cov),
                receive_ns,
                self.opened_ns,
                stats,
                out,
            ),
            None => self.undated_pvt += 1,
        }
    }

    /// Decodes `bytes` (any split of the stream), received at `receive_ns`.
    pub fn feed(
        &mut self,
        bytes: &[u8],
        receive_ns: u64,
        stats: &mut SourceStats,
        out: &mut Vec<Item>,
    ) {
        match self.format {
            StreamFormat::Ubx => self.feed_ubx(bytes, receive_ns, stats, out),
            _ => {
                for &b in bytes {
                    if b == b'\n' {
                        self.lines += 1;
                        if !self.skipping {
                            let line = std::mem::take(&mut self.buf);
                            self.line(&line, receive_ns, stats, out);
                        }
                        self.buf.clear();
                        self.skipping = false;
                    } else if !self.skipping {
                        if self.buf.len() >= MAX_LINE {
                            stats.oversized += 1;
                            let at = format!("line {}", self.lines + 1);
                            let why = format!("longer than {MAX_LINE} bytes");
                            stats.skip("line over the length limit", &at, &why);
                            self.skipping = true;
                            self.buf.clear();
                        } else {
                            self.buf.push(b);
                        }
                    }
                }
            }
        }
    }

    /// End of stream: a last line without newline, a frame cut short, the last NMEA cycle, a
    /// NAV-PVT waiting for its NAV-COV; fixes that never got a time are counted.
    pub fn finish(&mut self, receive_ns: u64, stats: &mut SourceStats, out: &mut Vec<Item>) {
        if self.format == StreamFormat::Ubx {
            self.end_noise(stats);
            if !self.buf.is_empty() {
                stats.malformed += 1;
                let at = self.place(0);
                let why = format!("{} bytes at the end of the stream", self.buf.len());
                stats.skip(UbxError::Truncated.reason(), &at, &why);
                self.offset += self.buf.len() as u64;
                self.buf.clear();
            }
        } else if !self.buf.is_empty() && !self.skipping {
            self.lines += 1;
            let line = std::mem::take(&mut self.buf);
            self.line(&line, receive_ns, stats, out);
        }
        let clock = (receive_ns > 0).then_some(receive_ns);
        // The stream's totals: finish ends it.
        self.nmea.finish(clock);
        while let Some(fix) = self.nmea.next_fix() {
            push_fix(fix, receive_ns, self.opened_ns, stats, out);
        }
        if let Some((pvt, cov)) = self.pairing.finish() {
            self.push_pvt(&pvt, cov, receive_ns, stats, out);
        }
        for (reason, n) in [
            (NMEA_UNDATED, std::mem::take(&mut self.nmea.undated)),
            (NMEA_UNTIMED, std::mem::take(&mut self.nmea.untimed)),
            (UBX_UNDATED, std::mem::take(&mut self.undated_pvt)),
        ] {
            if n > 0 {
                *stats.skipped.entry(reason.to_owned()).or_insert(0) += n;
            }
        }
    }

    fn line(&mut self, raw: &[u8], receive_ns: u64, stats: &mut SourceStats, out: &mut Vec<Item>) {
        let text = match std::str::from_utf8(raw) {
            Ok(t) => t.trim_end_matches('\r'),
            Err(e) => {
                stats.malformed += 1;
                let at = self.place(0);
                stats.skip("line that is not UTF-8", &at, &e);
                return;
            }
        };
        if text.trim().is_empty() {
            return;
        }
        match self.format {
            StreamFormat::JsonLines => match parse_json_line(text, receive_ns) {
                Ok(item) => {
                    stats.received += 1;
                    out.push(item);
                }
                Err(e) => {
                    stats.malformed += 1;
                    let at = self.place(0);
                    stats.skip("JSON line that does not decode", &at, &e);
                    stats.last_error = Some(e.to_string());
                }
            },
            StreamFormat::Nmea => {
                // A live source's receive time is a UTC clock; a file's is 0 (none).
                let clock = (receive_ns > 0).then_some(receive_ns);
                let fed = nmea::parse(text).and_then(|s| {
                    if s.junk > 0 {
                        stats.count(nmea::JUNK_REASON);
                    }
                    self.nmea.feed(&s, clock)
                });
                while let Some(fix) = self.nmea.next_fix() {
                    push_fix(fix, receive_ns, self.opened_ns, stats, out);
                }
                let at = self.place(0);
                count_nmea_outcome(fed, &at, stats);
            }
            StreamFormat::Ubx => unreachable!("UBX is binary"),
        }
    }

    fn end_noise(&mut self, stats: &mut SourceStats) {
        end_noise(&mut self.in_noise, stats);
    }

    fn feed_ubx(
        &mut self,
        bytes: &[u8],
        receive_ns: u64,
        stats: &mut SourceStats,
        out: &mut Vec<Item>,
    ) {
        self.buf.extend_from_slice(bytes);
        let mut start = 0;
        loop {
            let rest = &self.buf[start..];
            let Some(sync) = rest.windows(2).position(|w| w == ubx::SYNC) else {
                // Keep a trailing b5 that may start the next frame; the rest is noise.
                let keep = usize::from(rest.last() == Some(&ubx::SYNC[0]));
                if rest.len() > keep {
                    self.in_noise.get_or_insert(false);
                }
                start = self.buf.len() - keep;
                break;
            };
            if sync > 0 {
                self.in_noise.get_or_insert(false);
            }
            let at = start + sync;
            match ubx::parse_frame(&self.buf[at..]) {
                Err(UbxError::Truncated) => {
                    start = at;
                    break;
                }
                Err(e) => {
                    end_noise(&mut self.in_noise, stats);
                    if matches!(e, UbxError::Checksum { .. }) {
                        stats.checksum_failures += 1;
                    } else {
                        stats.malformed += 1;
                        stats.last_error = Some(e.to_string());
                    }
                    let place = self.place(at);
                    stats.skip(e.reason(), &place, &e);
                    // What follows the sync up to the next frame is the refused frame's.
                    self.in_noise = Some(true);
                    start = at + 2;
                }
                Ok((frame, used)) => {
                    end_noise(&mut self.in_noise, stats);
                    let refused = match UbxMessage::decode(&frame) {
                        Ok(message) => {
                            self.ubx_message(message, receive_ns, stats, out);
                            None
                        }
                        Err(e) => Some(e),
                    };
                    if let Some(e) = refused {
                        stats.malformed += 1;
                        let place = self.place(at);
                        stats.skip(e.reason(), &place, &e);
                    }
                    start = at + used;
                }
            }
        }
        self.buf.drain(..start);
        self.offset += start as u64;
        // A sync pair followed by a huge claimed length cannot hold the buffer for ever.
        if self.buf.len() > 2 * ubx::MAX_PAYLOAD {
            stats.malformed += 1;
            let place = self.place(0);
            stats.skip("UBX bytes that never completed a frame", &place, &"dropped");
            self.offset += self.buf.len() as u64;
            self.buf.clear();
        }
    }

    /// One decoded UBX message: a NAV-PVT or NAV-COV paired into a fix and recorded, any
    /// other class counted by its id.
    fn ubx_message(
        &mut self,
        message: UbxMessage,
        receive_ns: u64,
        stats: &mut SourceStats,
        out: &mut Vec<Item>,
    ) {
        let solution = match message {
            UbxMessage::Pvt(pvt) => self.pairing.pvt(pvt),
            UbxMessage::Cov(c) => self.pairing.cov(&c),
            UbxMessage::HpPosLlh(hp) => self.pairing.hp(hp),
            UbxMessage::Other(class, id) => {
                stats.count(&format!("UBX {class:02x}/{id:02x} (not decoded)"));
                None
            }
        };
        if let Some((pvt, cov)) = solution {
            self.push_pvt(&pvt, cov, receive_ns, stats, out);
        }
    }
}

/// A UBX frame decoded: the messages a fix is made of, or another class left as its id.
enum UbxMessage {
    Pvt(NavPvt),
    Cov(NavCov),
    HpPosLlh(NavHpPosLlh),
    Other(u8, u8),
}

impl UbxMessage {
    fn decode(frame: &ubx::Frame<'_>) -> Result<Self, UbxError> {
        Ok(match (frame.class, frame.id) {
            NavPvt::CLASS_ID => UbxMessage::Pvt(NavPvt::decode(frame)?),
            NavCov::CLASS_ID => UbxMessage::Cov(NavCov::decode(frame)?),
            NavHpPosLlh::CLASS_ID => UbxMessage::HpPosLlh(NavHpPosLlh::decode(frame)?),
            (class, id) => UbxMessage::Other(class, id),
        })
    }
}

/// A stretch of bytes that were not a frame ends: counted once (unless it was the rest of a
/// frame already refused).
fn end_noise(in_noise: &mut Option<bool>, stats: &mut SourceStats) {
    if in_noise.take() == Some(false) {
        stats.malformed += 1;
        stats.count("bytes between UBX frames");
    }
}

/// Records `fix`, received at `receive_ns` (0 from a file, checked against `opened_ns`).
fn push_fix(
    fix: GnssFix,
    receive_ns: u64,
    opened_ns: u64,
    stats: &mut SourceStats,
    out: &mut Vec<Item>,
) {
    let clock = if receive_ns > 0 {
        receive_ns
    } else {
        opened_ns
    };
    if fix.stamp_ns > 0 && clock.saturating_sub(fix.stamp_ns) >= ROLLOVER_NS {
        stats.warn(ROLLOVER_WARNING);
    }
    stats.received += 1;
    out.push(Item {
        topic: topics::GNSS_FIX.to_owned(),
        log_time_ns: receive_ns,
        message: AnyMessage::GnssFix(fix),
    });
}

/// Counts a sentence that was not used under its reason (and in the totals when it was bad).
fn count_nmea_outcome(fed: Result<Decoded, NmeaError>, at: &str, stats: &mut SourceStats) {
    let e = match fed {
        Ok(Decoded::Used) => return,
        Ok(Decoded::Skipped) => return stats.count(Decoded::SKIPPED_REASON),
        Err(e) => e,
    };
    match e {
        NmeaError::Checksum { .. } => stats.checksum_failures += 1,
        NmeaError::TooLong(_) => stats.oversized += 1,
        _ => {
            stats.malformed += 1;
            stats.last_error = Some(e.to_string());
        }
    }
    stats.skip(e.reason(), at, &e);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_between_ubx_frames_is_counted_once_however_the_stream_is_split() {
        let mut frames = Vec::new();
        let mut b = Vec::new();
        for hex in ["b56205010200068a98c1", "b56205000200068a97bc"] {
            ubx::hex_into(hex, &mut b);
            frames.extend_from_slice(&b);
            frames.extend_from_slice(b"\x00\xffnoise");
        }
        let mut bad = frames.clone();
        bad[6] ^= 0xff;
        bad.extend_from_slice(&frames[..7]); // a frame cut short by the end of the stream
        let decode = |chunk: usize| {
            let mut d = StreamDecoder::new(StreamFormat::Ubx);
            let (mut stats, mut out) = (SourceStats::default(), Vec::new());
            for c in bad.chunks(chunk) {
                d.feed(c, 0, &mut stats, &mut out);
            }
            d.finish(0, &mut stats, &mut out);
            stats
        };
        let whole = decode(bad.len());
        assert_eq!(whole.checksum_failures, 1);
        // The noise after the refused frame is that frame's; the one after the good frame and
        // the cut frame are counted once each.
        assert_eq!(whole.skipped["bytes between UBX frames"], 1, "{whole:?}");
        assert_eq!(whole.skipped["UBX frame cut short"], 1, "{whole:?}");
        assert_eq!(
            whole.first_problems[0],
            "byte 0: UBX checksum [8b, a7] where the frame gives [98, c1]"
        );
        for chunk in [1, 2, 3, 7] {
            assert_eq!(decode(chunk), whole, "split every {chunk} bytes");
        }
    }

    /// `body` with its `$` and checksum.
    fn nmea(body: &str) -> String {
        format!("${body}*{:02X}", body.bytes().fold(0u8, |a, b| a ^ b))
    }

    /// An NMEA capture decoded as `import` and `record` decode it, received at `receive_ns`.
    fn decode_nmea(text: &str, receive_ns: u64) -> (SourceStats, Vec<GnssFix>) {
        let mut d = StreamDecoder::new(StreamFormat::Nmea);
        let (mut stats, mut out) = (SourceStats::default(), Vec::new());
        d.feed(text.as_bytes(), receive_ns, &mut stats, &mut out);
        d.finish(receive_ns, &mut stats, &mut out);
        let fixes = out
            .into_iter()
            .filter_map(|i| match i.message {
                AnyMessage::GnssFix(f) => Some(f),
                _ => None,
            })
            .collect();
        (stats, fixes)
    }

    #[test]
    fn junk_before_dollar_is_counted_per_line_and_every_fix_decoded() {
        // An ST Teseo LIV4F capture: `$$` before every sentence.
        let mut text = String::new();
        for k in 0..12 {
            let t = format!("1358{:02}.000", k);
            for body in [
                format!("GNRMC,{t},A,4723.00484,N,00045.88150,E,0.5,120.9,210325,,,A,C"),
                format!("GNGGA,{t},4723.00484,N,00045.88150,E,1,13,1.7,063.64,M,48.3,M,,"),
                "GNGSA,A,3,27,08,07,,,,,,,,,,2.5,1.7,1.8,1".to_owned(),
            ] {
                text.push_str(&format!("${}\r\n", nmea(&body)));
            }
        }
        let (stats, fixes) = decode_nmea(&text, 0);
        assert_eq!(fixes.len(), 12);
        assert!(fixes
            .iter()
            .all(|f| f.satellites == 13 && f.latitude_deg.is_some()));
        assert_eq!(stats.skipped[nmea::JUNK_REASON], 36);
        assert_eq!(stats.checksum_failures, 0);
    }

    #[test]
    fn a_date_1024_weeks_early_is_kept_and_warned_of() {
        // A receiver caught by the rollover dates 2025-03-21 as 2005-08-05 (1024 weeks early).
        let epoch = |date: &str| {
            nmea(&format!(
                "GPRMC,135806.000,A,4723.00484,N,00045.88150,E,0.5,120.9,{date},,,A"
            )) + "\r\n"
        };
        let live = 1_742_565_486 * 1_000_000_000; // 2025-03-21 13:58:06 UTC
        let (stats, fixes) = decode_nmea(&epoch("050805"), live);
        assert_eq!(fixes[0].stamp_ns, live - 1024 * 7 * 86_400 * 1_000_000_000);
        assert_eq!(stats.warnings[ROLLOVER_WARNING], 1);
        let (stats, fixes) = decode_nmea(&epoch("210325"), live);
        assert_eq!((fixes[0].stamp_ns, stats.warnings.len()), (live, 0));
        // From a file, against the clock when the import ran.
        let (stats, _) = decode_nmea(&epoch("050805"), 0);
        assert_eq!(stats.warnings[ROLLOVER_WARNING], 1);
    }

    #[test]
    fn a_half_line_left_idle_is_dropped_counted_and_its_rest_discarded() {
        let mut d = StreamDecoder::new(StreamFormat::JsonLines);
        let (mut stats, mut out) = (SourceStats::default(), Vec::new());
        let good = br#"{"topic":"/radar/speed","speed_mps":3.0,"quality":1.0,"valid":true}"#;
        d.feed(b"{\"topic\":\"/radar/sp", 1, &mut stats, &mut out);
        assert!(d.drop_partial(&mut stats));
        assert!(!d.drop_partial(&mut stats), "nothing left to drop");
        d.feed(b"eed\"}\n", 1, &mut stats, &mut out);
        d.feed(good, 1, &mut stats, &mut out);
        d.feed(b"\n", 1, &mut stats, &mut out);
        assert_eq!(
            (
                stats.skipped["half line left idle"],
                stats.malformed,
                out.len()
            ),
            (1, 1, 1)
        );
        assert_eq!(
            stats.first_problems,
            ["line 1: 19 bytes with no end of line, then silence"]
        );
    }

    #[test]
    fn oversized_and_garbage_lines_are_counted_and_the_next_good_line_still_arrives() {
        let mut d = StreamDecoder::new(StreamFormat::JsonLines);
        let mut stats = SourceStats::default();
        let mut out = Vec::new();
        let mut input = vec![b'x'; MAX_LINE + 10];
        input.extend_from_slice(b"\n{not json}\n\xff\xfe\n");
        input.extend_from_slice(
            br#"{"topic":"/radar/speed","speed_mps":3.0,"quality":1.0,"valid":true}"#,
        );
        input.push(b'\n');
        d.feed(&input, 1, &mut stats, &mut out);
        assert_eq!(
            (stats.oversized, stats.malformed, stats.received, out.len()),
            (1, 2, 1, 1)
        );
    }
}
