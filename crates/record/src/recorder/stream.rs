//! Byte streams to messages, per format: JSON lines (sensor gateways), NMEA 0183 and u-blox
//! UBX (GNSS receivers). Every length is bounded and every checksum checked; what does not
//! decode is counted in the source's statistics and skipped, never fatal.

use crate::error::UnknownStreamFormat;
use railfuse_catalog::messages::{AnyMessage, GnssFix, SourceStats};
use railfuse_catalog::topics;

use super::message::{parse_json_line, Item};
use crate::decode::nmea::{self, Decoded, FixAssembler, NmeaError};
use crate::decode::ubx::{self, NavCov, NavPvt, PvtCovPairing, UbxError};

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
    nmea: FixAssembler,
    pairing: PvtCovPairing,
    undated_pvt: u64,
}

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
            nmea: FixAssembler::with_date(date),
            pairing: PvtCovPairing::default(),
            undated_pvt: 0,
        }
    }

    /// Fixes dropped for want of a time: NMEA fixes no date came for (after
    /// [`StreamDecoder::finish`]), NAV-PVTs without valid UTC read from a file.
    pub fn undated_fixes(&self) -> u64 {
        self.nmea.undated + self.undated_pvt
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
            Some(stamp) => push_fix(pvt.to_fix(stamp, cov), receive_ns, stats, out),
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
                        if !self.skipping {
                            let line = std::mem::take(&mut self.buf);
                            self.line(&line, receive_ns, stats, out);
                        }
                        self.buf.clear();
                        self.skipping = false;
                    } else if !self.skipping {
                        if self.buf.len() >= MAX_LINE {
                            stats.oversized += 1;
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

    /// End of stream: a last line without newline, a NAV-PVT waiting for its NAV-COV.
    pub fn finish(&mut self, receive_ns: u64, stats: &mut SourceStats, out: &mut Vec<Item>) {
        if self.format != StreamFormat::Ubx && !self.buf.is_empty() && !self.skipping {
            let line = std::mem::take(&mut self.buf);
            self.line(&line, receive_ns, stats, out);
        }
        self.nmea.finish();
        if let Some(pvt) = self.pairing.finish() {
            self.push_pvt(&pvt, None, receive_ns, stats, out);
        }
    }

    fn line(&mut self, raw: &[u8], receive_ns: u64, stats: &mut SourceStats, out: &mut Vec<Item>) {
        let text = match std::str::from_utf8(raw) {
            Ok(t) => t.trim_end_matches('\r'),
            Err(_) => {
                stats.malformed += 1;
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
                    stats.last_error = Some(e.to_string());
                }
            },
            StreamFormat::Nmea => {
                // A live source's receive time is a UTC clock; a file's is 0 (none).
                let clock = (receive_ns > 0).then_some(receive_ns);
                let fed = nmea::parse(text).and_then(|s| self.nmea.feed(&s, clock));
                while let Some(fix) = self.nmea.next_fix() {
                    push_fix(fix, receive_ns, stats, out);
                }
                count_nmea_outcome(fed, stats);
            }
            StreamFormat::Ubx => unreachable!("UBX is binary"),
        }
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
                    stats.malformed += 1;
                }
                start = self.buf.len() - keep;
                break;
            };
            if sync > 0 {
                stats.malformed += 1; // bytes between frames
            }
            let at = start + sync;
            match ubx::parse_frame(&self.buf[at..]) {
                Err(UbxError::Truncated) => {
                    start = at;
                    break;
                }
                Err(UbxError::Checksum { .. }) => {
                    stats.checksum_failures += 1;
                    start = at + 2;
                }
                Err(e) => {
                    stats.malformed += 1;
                    stats.last_error = Some(e.to_string());
                    start = at + 2;
                }
                Ok((frame, used)) => {
                    match (frame.class, frame.id) {
                        NavPvt::CLASS_ID => match NavPvt::decode(&frame) {
                            Ok(pvt) => {
                                if let Some(prev) = self.pairing.pvt(pvt) {
                                    self.push_pvt(&prev, None, receive_ns, stats, out);
                                }
                            }
                            Err(_) => stats.malformed += 1,
                        },
                        NavCov::CLASS_ID => {
                            let paired = NavCov::decode(&frame)
                                .ok()
                                .and_then(|c| self.pairing.cov(&c));
                            if let Some((pvt, cov)) = paired {
                                self.push_pvt(&pvt, cov, receive_ns, stats, out);
                            }
                        }
                        _ => {}
                    }
                    start = at + used;
                }
            }
        }
        self.buf.drain(..start);
        // A sync pair followed by a huge claimed length cannot hold the buffer for ever.
        if self.buf.len() > 2 * ubx::MAX_PAYLOAD {
            stats.malformed += 1;
            self.buf.clear();
        }
    }
}

fn push_fix(fix: GnssFix, receive_ns: u64, stats: &mut SourceStats, out: &mut Vec<Item>) {
    stats.received += 1;
    out.push(Item {
        topic: topics::GNSS_FIX.to_owned(),
        log_time_ns: receive_ns,
        message: AnyMessage::GnssFix(fix),
    });
}

fn count_nmea_outcome(fed: Result<Decoded, NmeaError>, stats: &mut SourceStats) {
    match fed {
        Ok(_) => {}
        Err(NmeaError::Checksum { .. }) => stats.checksum_failures += 1,
        Err(NmeaError::TooLong(_)) => stats.oversized += 1,
        Err(e) => {
            stats.malformed += 1;
            stats.last_error = Some(e.to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_between_ubx_frames_is_counted_and_frames_split_anywhere_still_decode() {
        let mut frames = Vec::new();
        let mut b = Vec::new();
        for hex in ["b56205010200068a98c1", "b56205000200068a97bc"] {
            ubx::hex_into(hex, &mut b);
            frames.extend_from_slice(&b);
            frames.extend_from_slice(b"\x00\xffnoise");
        }
        let mut bad = frames.clone();
        bad[6] ^= 0xff;
        let mut d = StreamDecoder::new(StreamFormat::Ubx);
        let mut stats = SourceStats::default();
        let mut out = Vec::new();
        for chunk in bad.chunks(3) {
            d.feed(chunk, 0, &mut stats, &mut out);
        }
        assert_eq!(stats.checksum_failures, 1);
        assert!(stats.malformed >= 2, "{stats:?}");
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
