//! NMEA 0183 sentences: `$<talker><type>,<fields>*<hh>` with the XOR checksum of everything
//! between `$` and `*`. GGA, GNS, RMC, GLL, ZDA, VTG, GSA and GST are decoded; other types
//! (GSV, TXT, GBS, proprietary `$P…`) are recognised and skipped.
//!
//! The module is laid out as the decoding flows: [`parse`] checks a line and finds its
//! sentence, `sentences` turns each sentence type into what it says of its epoch, `cycle`
//! combines one epoch's sentences into one fix, and [`FixAssembler`] tells the epochs apart
//! and dates them.
//!
//! # Finding the sentence in a line
//!
//! A line is read from its last `$` (as gpsd and pynmeagps resync): what stands before it is
//! junk (ST Teseo LIV4F prefixes every sentence with `$$`, a serial link that reconnects
//! leaves half a sentence before the next), counted by the caller and skipped, and the
//! sentence after it is decoded as usual.
//!
//! # One fix per reporting cycle
//!
//! A receiver reports each epoch as a burst of sentences in an order of its own (u-blox: RMC,
//! VTG, GGA, GSA, GST, ZDA, GLL; Quectel: GGA, GNS, VTG, RMC, GSA; SiRFstarV: GPGGA, GLGGA,
//! GNGSA, GNRMC). As gpsd does, the sentences between two changes of the time of day are one
//! reporting cycle, and one fix is made of that cycle when it ends (at the first sentence
//! stamped with another time, or at the end of the stream). Nothing of one cycle is carried
//! into the next, and an empty field means "not reported this epoch".
//!
//! Sentences without a time are placed by these rules:
//!
//! 1. A sentence without a time (GSA, VTG; or a GGA, RMC, GNS, GLL or GST whose time field is
//!    empty) belongs to the cycle open when it arrives,
//! 2. except that a receiver sends each of GGA, GNS, RMC, GLL, VTG, GST and ZDA once per
//!    talker and epoch: one of these whose talker and type the open cycle already holds
//!    begins the next epoch (a u-blox that lost its fix repeats `$GNRMC,,V,…` with no time).
//! 3. A cycle begun by sentences without a time takes the time of the first timed sentence
//!    after them (receivers that send GSA before GGA), unless one of them is a GGA, RMC, GNS,
//!    GLL or GST that came without its time: then it is an epoch the receiver could not time
//!    (Quectel EG25-G: `$GPGGA,,,,,,0,,,,,,,,*66`), it ends there without a fix (counted in
//!    [`FixAssembler::untimed`]), and the next timed sentence begins a fresh cycle. A
//!    sentence of an epoch without a time therefore never overrides the next epoch's fix.
//!
//! A live fix therefore waits for its cycle to end, about one epoch.
//!
//! # One cycle, one fix: the sentences combined
//!
//! The fix sentences are GGA and GNS (they carry the fix quality, satellites and heights);
//! RMC and GLL carry a position too, and make the fix only in a cycle with neither.
//!
//! - **Position and fix type**: of the best sentence, in this order: a fix sentence before
//!   RMC/GLL; a combined `GN` talker before a single constellation's (GP, GL, GA, GB/BD,
//!   GQ, GI); the better fix type (RTK fixed, RTK float, differential, single, none); GGA
//!   before GNS; and among equals the first received. When one cycle holds both a GGA and a
//!   GNS of one talker, so, the GGA is the fix (gpsd's choice too).
//! - **Satellites used**: a `GN` fix sentence's count; else, with one talker's fix sentences,
//!   its count; else (several talkers, each counting its own constellation: SiRFstarV's GPGGA
//!   8 and GLGGA 2, Telit's GPGGA 5 and GAGGA 1) the distinct satellites listed by the cycle's
//!   GSAs with a fix, and without such GSAs the sum over the talkers.
//! - **HDOP**: the chosen sentence's, else the cycle's GSA's.
//! - **Fix mode of GSA**: when every GSA of the cycle says fix mode 1 (no fix) the cycle has
//!   no position, whatever the GGA says (gpsd); a GSA with a fix beside them (the epoch's own,
//!   of a receiver that sends GSA first) keeps it.
//! - **Navigation status** (NMEA 4.1, the last field of RMC and GNS): `U` (unsafe) takes the
//!   position away; `S` (safe), `C` (caution) and `V` (no status given, as u-blox and Quectel
//!   send with every fix) do not.
//! - The date of the cycle's own RMC or ZDA, the speed and course of its RMC or VTG (none in
//!   mode N), the covariance of its GST.
//!
//! # Fix types
//!
//! - GGA quality 1 is a single fix, 2 and 3 differential, 4 RTK fixed, 5 RTK float; 0, 6
//!   (estimated), 7 (manual) and 8 (simulator) carry no GNSS position.
//! - The FAA mode indicator of GNS (one character per constellation: GPS, GLONASS, Galileo,
//!   BeiDou, QZSS, NavIC), RMC, GLL and VTG: `A` single, `D` and `P` differential, `R` RTK
//!   fixed, `F` RTK float; `N`, `E` (estimated), `M` (manual) and `S` (simulator) no GNSS
//!   position. A GNS fix is the best of its constellations' (`AANN` is single, `NRN` RTK
//!   fixed): the solution is one, whichever constellation carried it.
//! - RMC or GLL with status V carries no position, speed or course.
//!
//! # Dates
//!
//! GGA, GNS and GLL carry only the time of day. A cycle with its own RMC or ZDA takes that
//! date. One without takes the day that puts its time nearest a reference: a live recorder's
//! UTC clock, else the previous fix (so a stream crosses midnight whichever sentence brings
//! the date), else a date the import was given. Before any of these exists, fixes wait (up to
//! [`MAX_HELD`]) for the first dated cycle and take the day nearest it. A fix is never
//! stamped with a made-up day (1970). A receiver's date is never moved either: one caught by
//! the GPS week-number rollover (1024 weeks, 19.6 years early) keeps its date and the
//! recorder warns (`recorder::stream`).
//!
//! # Heights
//!
//! GGA and GNS give the height above mean sea level and the geoid separation. A fix carries
//! the MSL height as `altitude_msl_m`, and the ellipsoidal height as `altitude_m` only when
//! the separation is given (MSL + N); with an empty separation it has no ellipsoidal height.
//!
//! # Where the standard is silent (following pynmeagps and gpsd)
//!
//! - Sentences are ASCII: one with any other byte is refused, whatever its checksum.
//! - A number is digits with at most one point (and a sign where the field is signed): `nan`,
//!   `inf` and exponents are refused, as is a latitude beyond 90°, a longitude beyond 180°,
//!   minutes of 60 or more and a hemisphere other than N/S or E/W.
//! - Two-digit RMC years 69–99 are 1969–1999 and 00–68 are 2000–2068 (Python's `%y`, which
//!   pynmeagps uses). Dates are checked against the calendar (no 31 February, no month 13).
//! - Time 23:59:60 is a leap second (the Unix instant of the next midnight); second 60 at any
//!   other minute is refused.
//! - A VTG without unit letters (before NMEA 2.0: course, magnetic course, knots, km/h) is
//!   read by position.

mod assembler;
mod cycle;
mod fields;
mod sentences;

pub use crate::decode::time::Date;
pub use assembler::{FixAssembler, MAX_HELD};

/// Longest sentence accepted (the standard says 82 characters; receivers exceed it a little).
pub const MAX_SENTENCE: usize = 256;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NmeaError {
    #[error("not an NMEA sentence ($…*hh)")]
    NotASentence,
    #[error("NMEA sentence of {0} bytes exceeds the {MAX_SENTENCE}-byte limit")]
    TooLong(usize),
    #[error("NMEA checksum {found:02X} where the sentence gives {expected:02X}")]
    Checksum { expected: u8, found: u8 },
    #[error("NMEA sentence with a byte that is not ASCII")]
    NotAscii,
    #[error("NMEA {sentence} field {field} ({name}) '{value}': {why}")]
    BadField {
        sentence: String,
        /// 1-based, after the address field.
        field: usize,
        name: &'static str,
        /// The field as it stood (cut to 24 characters).
        value: String,
        why: &'static str,
    },
}

impl NmeaError {
    /// The reason a sentence is refused, as reports count it: one name per kind of problem.
    pub fn reason(&self) -> &'static str {
        match self {
            NmeaError::NotASentence => "not an NMEA sentence",
            NmeaError::TooLong(_) => "NMEA sentence over the length limit",
            NmeaError::Checksum { .. } => "NMEA checksum failure",
            NmeaError::NotAscii => "NMEA sentence with a non-ASCII byte",
            NmeaError::BadField { .. } => "NMEA field that does not parse",
        }
    }
}

/// Why a line's leading bytes were skipped, as reports count it.
pub const JUNK_REASON: &str = "NMEA line with bytes before its last `$` (skipped; the sentence \
                               after them decoded)";

/// A checked sentence: its talker, type and fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Sentence<'a> {
    pub talker: &'a str,
    pub kind: &'a str,
    pub fields: Vec<&'a str>,
    /// Bytes of the line before the sentence's `$`, skipped (0 for a clean line).
    pub junk: usize,
}

/// Checks one line and returns the sentence that starts at its last `$`.
pub fn parse(line: &str) -> Result<Sentence<'_>, NmeaError> {
    let line = line.trim_end_matches(['\r', '\n']);
    let start = line.rfind('$').ok_or(NmeaError::NotASentence)?;
    let sentence = &line[start..];
    if sentence.len() > MAX_SENTENCE {
        return Err(NmeaError::TooLong(sentence.len()));
    }
    let body = &sentence[1..];
    let (data, hex) = body.rsplit_once('*').ok_or(NmeaError::NotASentence)?;
    if hex.len() != 2 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(NmeaError::NotASentence);
    }
    let expected = u8::from_str_radix(hex, 16).map_err(|_| NmeaError::NotASentence)?;
    let found = data.bytes().fold(0u8, |a, b| a ^ b);
    if expected != found {
        return Err(NmeaError::Checksum { expected, found });
    }
    if !data.is_ascii() {
        return Err(NmeaError::NotAscii);
    }
    let mut fields = data.split(',');
    let head = fields.next().unwrap_or_default();
    if !head.bytes().all(|b| b.is_ascii_alphanumeric()) {
        return Err(NmeaError::NotASentence);
    }
    // Proprietary sentences are `$P<maker><type>`; the rest `$<talker, 2><type, 3>`.
    let (talker, kind) = match head.strip_prefix('P') {
        Some(rest) if !rest.is_empty() => ("P", rest),
        _ if head.len() == 5 => head.split_at(2),
        _ => return Err(NmeaError::NotASentence),
    };
    Ok(Sentence {
        talker,
        kind,
        fields: fields.collect(),
        junk: start,
    })
}

/// What a sentence did to the assembler.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoded {
    /// Part of a reporting cycle (GGA, GNS, RMC, GLL, ZDA, VTG, GSA, GST); a fix may be
    /// ready (take it with [`FixAssembler::next_fix`]).
    Used,
    /// A sentence type railfuse does not use (GSV, TXT, proprietary, …).
    Skipped,
}

impl Decoded {
    /// Why a skipped sentence was not used, as reports count it.
    pub const SKIPPED_REASON: &'static str = "NMEA sentence type not used (GSV, TXT, GBS, …)";
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod receivers;
