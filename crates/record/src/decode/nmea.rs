//! NMEA 0183 sentences: `$<talker><type>,<fields>*<hh>` with the XOR checksum of everything
//! between `$` and `*`. GGA, RMC, ZDA, VTG, GSA and GST are decoded; other types (GSV, GLL,
//! TXT, proprietary `$P…`) are recognised and skipped.
//!
//! # One fix per reporting cycle
//!
//! A receiver reports each epoch as a burst of sentences in an order of its own (u-blox: RMC,
//! VTG, GGA, GSA, GST, ZDA; others GGA first). As gpsd does, the sentences between two changes
//! of the time of day are one reporting cycle, and one fix is made of that cycle when it ends
//! (at the first sentence stamped with another time, or at the end of the stream): the
//! position, fix quality, satellites and heights of its GGA, the date of its own RMC or ZDA,
//! the speed and course of its RMC or VTG, the fix mode of its GSA and the covariance of its
//! GST. Nothing of one cycle is carried into the next: a GSA or GST sent after the GGA belongs
//! to the GGA's epoch, and an empty field means "not reported this epoch". Sentences without a
//! time (GSA, VTG) belong to the cycle open when they arrive. A live fix therefore waits for
//! its cycle to end, about one epoch.
//!
//! # Dates
//!
//! GGA carries only the time of day. A cycle with its own RMC or ZDA takes that date. One
//! without takes the day that puts its time nearest a reference: a live recorder's UTC clock,
//! else the previous fix (so a stream crosses midnight whichever sentence brings the date),
//! else a date the import was given. Before any of these exists, fixes wait (up to
//! [`MAX_HELD`]) for the first dated cycle and take the day nearest it. A fix is never stamped
//! with a made-up day (1970).
//!
//! # Heights
//!
//! GGA gives the height above mean sea level and the geoid separation. A fix carries the MSL
//! height as `altitude_msl_m`, and the ellipsoidal height as `altitude_m` only when the
//! separation is given (MSL + N); with an empty separation it has no ellipsoidal height.
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
//! - Fix quality 1 is a single fix, 2 and 3 differential, 4 RTK fixed, 5 RTK float; 0, 6
//!   (estimated), 7 (manual) and 8 (simulator) carry no GNSS position. A GSA fix mode of 1 (no
//!   fix) in the same cycle overrides the GGA (gpsd).
//! - An RMC with status V, or a VTG with mode N, carries no speed or course.
//! - A GGA with no time and quality 0 (a receiver before its first fix) is skipped as such.

use std::collections::VecDeque;

use railfuse_catalog::messages::{FixType, GnssFix};

use super::time::{is_date, is_time_of_day, unix_ns};

/// Fixes held while no date is known (a minute at 10 Hz); older ones are dropped and counted.
pub const MAX_HELD: usize = 600;

/// A UTC calendar date.
pub type Date = (i64, u32, u32);

const DAY_NS: u64 = 86_400_000_000_000;

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

/// A checked sentence: its talker, type and fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Sentence<'a> {
    pub talker: &'a str,
    pub kind: &'a str,
    pub fields: Vec<&'a str>,
}

pub fn parse(line: &str) -> Result<Sentence<'_>, NmeaError> {
    let line = line.trim_end_matches(['\r', '\n']);
    if line.len() > MAX_SENTENCE {
        return Err(NmeaError::TooLong(line.len()));
    }
    let body = line.strip_prefix('$').ok_or(NmeaError::NotASentence)?;
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
    })
}

/// What a sentence did to the assembler.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoded {
    /// Part of a reporting cycle (GGA, RMC, ZDA, VTG, GSA, GST); a fix may be ready (take it
    /// with [`FixAssembler::next_fix`]).
    Used,
    /// A GGA with no time and no fix: a receiver that has not got a fix yet.
    NoFixYet,
    /// A sentence type railfuse does not use (GSV, GLL, TXT, proprietary, …).
    Skipped,
}

/// The field `i` (0-based after the address) of `s`, or "" past its end.
fn field<'a>(s: &Sentence<'a>, i: usize) -> &'a str {
    s.fields.get(i).copied().unwrap_or("")
}

fn bad(s: &Sentence<'_>, i: usize, name: &'static str, why: &'static str) -> NmeaError {
    NmeaError::BadField {
        sentence: s.kind.to_owned(),
        field: i + 1,
        name,
        value: field(s, i).chars().take(24).collect(),
        why,
    }
}

/// Digits with at most one point, a leading sign where `signed`: no `nan`, `inf` or exponent.
fn is_decimal(t: &str, signed: bool) -> bool {
    let body = if signed {
        t.strip_prefix(['-', '+']).unwrap_or(t)
    } else {
        t
    };
    let digits = body.bytes().filter(u8::is_ascii_digit).count();
    let points = body.bytes().filter(|&b| b == b'.').count();
    digits > 0 && points <= 1 && digits + points == body.len()
}

/// A decimal field; empty is `None`.
fn decimal(
    s: &Sentence<'_>,
    i: usize,
    name: &'static str,
    signed: bool,
) -> Result<Option<f64>, NmeaError> {
    match field(s, i) {
        "" => Ok(None),
        t if is_decimal(t, signed) => t
            .parse::<f64>()
            .map(Some)
            .map_err(|_| bad(s, i, name, "not a number")),
        t if is_decimal(t, true) => Err(bad(s, i, name, "negative")),
        _ => Err(bad(s, i, name, "not a number")),
    }
}

/// A whole number field; empty is `None`.
fn whole(s: &Sentence<'_>, i: usize, name: &'static str) -> Result<Option<u32>, NmeaError> {
    match field(s, i) {
        "" => Ok(None),
        t if t.bytes().all(|b| b.is_ascii_digit()) => t
            .parse::<u32>()
            .map(Some)
            .map_err(|_| bad(s, i, name, "out of range")),
        _ => Err(bad(s, i, name, "not a whole number")),
    }
}

/// `ddmm.mmmm` (latitude) or `dddmm.mmmm` (longitude) and its hemisphere → signed degrees.
fn angle(s: &Sentence<'_>, i: usize, longitude: bool) -> Result<Option<f64>, NmeaError> {
    let (name, deg_digits, max, hemispheres) = if longitude {
        ("longitude", 3, 180.0, ["E", "W"])
    } else {
        ("latitude", 2, 90.0, ["N", "S"])
    };
    let v = field(s, i);
    if v.is_empty() {
        return Ok(None);
    }
    let head = v.as_bytes().get(..deg_digits + 2);
    if !head.is_some_and(|h| h.iter().all(u8::is_ascii_digit)) || !is_decimal(v, false) {
        return Err(bad(s, i, name, "degrees and minutes (d…dmm.mmmm) expected"));
    }
    // ASCII digits up to deg_digits + 2: the split is on a character boundary.
    let degrees: f64 = v[..deg_digits]
        .parse()
        .map_err(|_| bad(s, i, name, "bad degrees"))?;
    let minutes: f64 = v[deg_digits..]
        .parse()
        .map_err(|_| bad(s, i, name, "bad minutes"))?;
    if minutes >= 60.0 {
        return Err(bad(s, i, name, "minutes of 60 or more"));
    }
    let x = degrees + minutes / 60.0;
    if x > max {
        return Err(bad(s, i, name, "beyond the pole or the antimeridian"));
    }
    match field(s, i + 1) {
        h if h == hemispheres[0] => Ok(Some(x)),
        h if h == hemispheres[1] => Ok(Some(-x)),
        _ => Err(bad(
            s,
            i + 1,
            if longitude { "E/W" } else { "N/S" },
            "hemisphere expected",
        )),
    }
}

/// `hhmmss[.s…]` → nanoseconds since midnight (a leap second runs past 86 400 s).
fn time_of_day(s: &Sentence<'_>, i: usize) -> Result<Option<u64>, NmeaError> {
    let t = field(s, i);
    if t.is_empty() {
        return Ok(None);
    }
    let (hms, frac) = t.split_once('.').unwrap_or((t, ""));
    let digits = |x: &str| x.bytes().all(|b| b.is_ascii_digit());
    if hms.len() != 6 || !digits(hms) || !digits(frac) {
        return Err(bad(s, i, "time", "hhmmss.ss expected"));
    }
    let two = |k: usize| {
        u32::from(hms.as_bytes()[k] - b'0') * 10 + u32::from(hms.as_bytes()[k + 1] - b'0')
    };
    let (h, m, sec) = (two(0), two(2), two(4));
    if !is_time_of_day(h, m, sec) {
        return Err(bad(s, i, "time", "not a time of day"));
    }
    // Nanoseconds from the first nine decimals.
    let mut ns = 0u64;
    for k in 0..9 {
        let d = frac.as_bytes().get(k).map_or(0, |b| u64::from(b - b'0'));
        ns = ns * 10 + d;
    }
    Ok(Some(
        (u64::from(h) * 3600 + u64::from(m) * 60 + u64::from(sec)) * 1_000_000_000 + ns,
    ))
}

/// The Unix time of midnight at the start of `date`.
fn midnight((y, mo, d): Date) -> Option<u64> {
    unix_ns(y, mo, d, 0, 0, 0, 0)
}

/// The stamp of time of day `tod_ns` on the day (of the days around `reference_ns`) that puts
/// it nearest that reference.
fn nearest_day(reference_ns: u64, tod_ns: u64) -> u64 {
    let at = reference_ns - reference_ns % DAY_NS + tod_ns;
    [at.checked_sub(DAY_NS), Some(at), at.checked_add(DAY_NS)]
        .into_iter()
        .flatten()
        .min_by_key(|t| t.abs_diff(reference_ns))
        .unwrap_or(at)
}

/// What a GGA says.
#[derive(Debug, Clone, PartialEq)]
struct Gga {
    fix_type: FixType,
    latitude_deg: Option<f64>,
    longitude_deg: Option<f64>,
    satellites: u8,
    hdop: Option<f64>,
    msl_m: Option<f64>,
    separation_m: Option<f64>,
}

/// One reporting cycle: what the sentences of one epoch said.
#[derive(Debug, Clone, Default, PartialEq)]
struct Cycle {
    /// Its time of day (ns since midnight); `None` while only untimed sentences came.
    tod_ns: Option<u64>,
    date: Option<Date>,
    gga: Option<Gga>,
    speed_mps: Option<f64>,
    course_rad: Option<f64>,
    /// A GSA of this cycle said "no fix".
    no_fix_mode: bool,
    /// (σ lat, σ lon, σ alt) in metres from this cycle's GST.
    sigmas: Option<(f64, f64, f64)>,
}

impl Cycle {
    /// The cycle's fix, stamped `stamp_ns`; `None` without a GGA.
    fn fix(&self, stamp_ns: u64) -> Option<GnssFix> {
        let g = self.gga.as_ref()?;
        let fix_type = if self.no_fix_mode {
            FixType::None
        } else {
            g.fix_type
        };
        let has = fix_type.has_position() && g.latitude_deg.is_some() && g.longitude_deg.is_some();
        let with = |x: Option<f64>| x.filter(|_| has);
        Some(GnssFix {
            stamp_ns,
            fix_type: if has { fix_type } else { FixType::None },
            satellites: g.satellites,
            hdop: g.hdop,
            latitude_deg: with(g.latitude_deg),
            longitude_deg: with(g.longitude_deg),
            altitude_m: with(g.msl_m.zip(g.separation_m).map(|(h, n)| h + n)),
            altitude_msl_m: with(g.msl_m),
            position_covariance_enu_m2: self
                .sigmas
                .filter(|_| has)
                .map(|(sn, se, su)| [se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, su * su]),
            speed_mps: with(self.speed_mps),
            course_rad: with(self.course_rad),
        })
    }
}

/// What one sentence adds to its cycle, decoded whole before it touches the cycle (a bad
/// sentence changes nothing).
enum Part {
    Gga(Gga),
    /// Date, and speed and course when the receiver says they are valid.
    Rmc(Option<Date>, Option<(Option<f64>, Option<f64>)>),
    Zda(Date),
    Vtg(Option<f64>, Option<f64>),
    Gsa(bool),
    Gst(Option<(f64, f64, f64)>),
}

/// Assembles fixes from a stream of sentences of one receiver, one per reporting cycle.
#[derive(Debug, Default, Clone)]
pub struct FixAssembler {
    cycle: Option<Cycle>,
    /// The date an import was given, for fixes before any dated cycle.
    given_date: Option<Date>,
    /// The stamp of the latest dated or stamped cycle: the reference for the next undated one.
    last_ns: Option<u64>,
    held: VecDeque<(u64, GnssFix)>,
    ready: VecDeque<GnssFix>,
    /// Fixes dropped for want of a date.
    pub undated: u64,
}

impl FixAssembler {
    /// An assembler that knows the date from the start (an import given `--date`).
    pub fn with_date(date: Option<Date>) -> Self {
        Self {
            given_date: date,
            ..Self::default()
        }
    }

    /// The next fix ready, in the order of their cycles.
    pub fn next_fix(&mut self) -> Option<GnssFix> {
        self.ready.pop_front()
    }

    /// End of the stream: the open cycle's fix is made; fixes still waiting for a date are
    /// dropped. Returns how many were dropped for want of one in all.
    pub fn finish(&mut self, clock_ns: Option<u64>) -> u64 {
        self.close(clock_ns);
        self.undated += self.held.len() as u64;
        self.held.clear();
        self.undated
    }

    /// Feeds one sentence. `clock_ns` is a UTC clock near the sentence's time when there is
    /// one (a live recorder's receive time).
    pub fn feed(&mut self, s: &Sentence<'_>, clock_ns: Option<u64>) -> Result<Decoded, NmeaError> {
        let (tod, part) = match s.kind {
            "GGA" => {
                let quality = whole(s, 5, "fix quality")?.unwrap_or(0);
                let Some(tod) = time_of_day(s, 0)? else {
                    return if quality == 0 {
                        Ok(Decoded::NoFixYet)
                    } else {
                        Err(bad(s, 0, "time", "a fix without a time"))
                    };
                };
                let gga = Gga {
                    fix_type: match quality {
                        1 => FixType::Single,
                        2 | 3 => FixType::Dgps,
                        4 => FixType::RtkFixed,
                        5 => FixType::RtkFloat,
                        0 | 6..=8 => FixType::None,
                        _ => return Err(bad(s, 5, "fix quality", "0 to 8 expected")),
                    },
                    latitude_deg: angle(s, 1, false)?,
                    longitude_deg: angle(s, 3, true)?,
                    satellites: whole(s, 6, "satellites")?.unwrap_or(0).min(255) as u8,
                    hdop: decimal(s, 7, "HDOP", false)?,
                    msl_m: decimal(s, 8, "altitude", true)?,
                    separation_m: decimal(s, 10, "geoid separation", true)?,
                };
                (Some(tod), Part::Gga(gga))
            }
            "RMC" => {
                let tod = time_of_day(s, 0)?;
                let date = match field(s, 8) {
                    "" => None,
                    t => {
                        let n = whole(s, 8, "date")?.filter(|_| t.len() == 6);
                        let n = n.ok_or_else(|| bad(s, 8, "date", "ddmmyy expected"))?;
                        let yy = (n % 100) as i64;
                        let y = if yy >= 69 { 1900 + yy } else { 2000 + yy };
                        let (d, m) = (n / 10_000, n / 100 % 100);
                        if !is_date(y, m, d) {
                            return Err(bad(s, 8, "date", "not a date on the calendar"));
                        }
                        Some((y, m, d))
                    }
                };
                let speed = decimal(s, 6, "speed", false)?.map(|kn| kn * 1852.0 / 3600.0);
                let course = decimal(s, 7, "course", false)?.map(f64::to_radians);
                let valid = match field(s, 1) {
                    "A" => true,
                    "V" | "" => false,
                    _ => return Err(bad(s, 1, "status", "A or V expected")),
                };
                (tod, Part::Rmc(date, valid.then_some((speed, course))))
            }
            "ZDA" => {
                let tod = time_of_day(s, 0)?.ok_or_else(|| bad(s, 0, "time", "empty"))?;
                let d = whole(s, 1, "day")?.ok_or_else(|| bad(s, 1, "day", "empty"))?;
                let m = whole(s, 2, "month")?.ok_or_else(|| bad(s, 2, "month", "empty"))?;
                let y = whole(s, 3, "year")?.ok_or_else(|| bad(s, 3, "year", "empty"))?;
                if field(s, 3).len() != 4 || !is_date(y.into(), m, d) {
                    return Err(bad(s, 3, "year", "not a date on the calendar"));
                }
                (Some(tod), Part::Zda((y.into(), m, d)))
            }
            "VTG" => {
                let course = decimal(s, 0, "course", false)?.map(f64::to_radians);
                let speed = decimal(s, 6, "speed", false)?.map(|kmh| kmh / 3.6);
                if field(s, 8) == "N" {
                    (None, Part::Vtg(None, None))
                } else {
                    (None, Part::Vtg(speed, course))
                }
            }
            "GSA" => (None, Part::Gsa(whole(s, 1, "fix mode")? == Some(1))),
            "GST" => {
                let tod = time_of_day(s, 0)?;
                let sigmas = match (
                    decimal(s, 5, "σ latitude", false)?,
                    decimal(s, 6, "σ longitude", false)?,
                    decimal(s, 7, "σ altitude", false)?,
                ) {
                    (Some(a), Some(b), Some(c)) => Some((a, b, c)),
                    _ => None,
                };
                (tod, Part::Gst(sigmas))
            }
            _ => return Ok(Decoded::Skipped),
        };
        self.enter(tod, clock_ns);
        let c = self.cycle.get_or_insert_with(Cycle::default);
        match part {
            Part::Gga(g) => c.gga = Some(g),
            Part::Rmc(date, motion) => {
                c.date = date.or(c.date);
                if let Some((speed, course)) = motion {
                    (c.speed_mps, c.course_rad) = (speed, course);
                }
            }
            Part::Zda(date) => c.date = Some(date),
            Part::Vtg(speed, course) => {
                c.speed_mps = speed.or(c.speed_mps);
                c.course_rad = course.or(c.course_rad);
            }
            Part::Gsa(no_fix) => c.no_fix_mode |= no_fix,
            Part::Gst(sigmas) => c.sigmas = sigmas,
        }
        Ok(Decoded::Used)
    }

    /// A sentence of time `tod` arrives: a new time of day ends the open cycle.
    fn enter(&mut self, tod: Option<u64>, clock_ns: Option<u64>) {
        let Some(t) = tod else { return };
        match self.cycle.as_mut().map(|c| c.tod_ns) {
            Some(Some(open)) if open != t => {
                self.close(clock_ns);
                self.cycle = Some(Cycle {
                    tod_ns: Some(t),
                    ..Cycle::default()
                });
            }
            Some(Some(_)) => {}
            Some(None) => self.cycle.as_mut().expect("open cycle").tod_ns = Some(t),
            None => {
                self.cycle = Some(Cycle {
                    tod_ns: Some(t),
                    ..Cycle::default()
                })
            }
        }
    }

    /// Ends the open cycle: its fix is stamped (or held for a date) and queued.
    fn close(&mut self, clock_ns: Option<u64>) {
        let Some(c) = self.cycle.take() else { return };
        let Some(tod) = c.tod_ns else { return };
        let stamp = if let Some(date) = c.date {
            midnight(date).map(|m| m + tod)
        } else if let Some(reference) = clock_ns.or(self.last_ns) {
            Some(nearest_day(reference, tod))
        } else {
            self.given_date.and_then(midnight).map(|m| m + tod)
        };
        let Some(stamp) = stamp else {
            if let Some(fix) = c.fix(0) {
                if self.held.len() == MAX_HELD {
                    self.held.pop_front();
                    self.undated += 1;
                }
                self.held.push_back((tod, fix));
            }
            return;
        };
        // Fixes that waited for a date take the day nearest this one.
        for (held_tod, fix) in std::mem::take(&mut self.held) {
            self.ready.push_back(GnssFix {
                stamp_ns: nearest_day(stamp, held_tod),
                ..fix
            });
        }
        self.last_ns = Some(stamp);
        if let Some(fix) = c.fix(stamp) {
            self.ready.push_back(fix);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds whole lines, then ends the stream; returns the fixes.
    fn fixes(a: &mut FixAssembler, lines: &[&str], clock: Option<u64>) -> Vec<GnssFix> {
        for line in lines {
            let s = parse(line).unwrap_or_else(|e| panic!("{line}: {e}"));
            a.feed(&s, clock).unwrap_or_else(|e| panic!("{line}: {e}"));
        }
        a.finish(clock);
        std::iter::from_fn(|| a.next_fix()).collect()
    }

    /// `body` with its `$` and checksum.
    fn nmea(body: &str) -> String {
        format!("${body}*{:02X}", body.bytes().fold(0u8, |a, b| a ^ b))
    }

    #[test]
    fn a_fix_is_assembled_from_rmc_gst_and_gga() {
        let f = fixes(
            &mut FixAssembler::default(),
            &[
                "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F",
                "$GNGST,083559.00,0.45,0.020,0.015,77.4,0.018,0.017,0.031*45",
                GGA,
            ],
            None,
        );
        let f = &f[0];
        assert_eq!(f.fix_type, FixType::RtkFixed);
        assert_eq!(f.stamp_ns, STAMP);
        assert!((f.latitude_deg.unwrap() - 44.655110666).abs() < 1e-8);
        assert!((f.longitude_deg.unwrap() - 10.929730333).abs() < 1e-8);
        assert!((f.altitude_m.unwrap() - 79.3).abs() < 1e-9);
        assert_eq!(f.altitude_msl_m, Some(35.2));
        assert!((f.position_covariance_enu_m2.unwrap()[4] - 0.018f64.powi(2)).abs() < 1e-12);
    }

    #[test]
    fn bad_checksums_and_junk_are_errors_not_panics() {
        assert!(matches!(
            parse("$GNGGA,1*00"),
            Err(NmeaError::Checksum { .. })
        ));
        assert_eq!(parse("hello"), Err(NmeaError::NotASentence));
        assert_eq!(
            parse(&format!("${}*00", "A".repeat(300))),
            Err(NmeaError::TooLong(304))
        );
        let s = parse("$GBGSV,2,1,07,06,25,044,42,09,38,057,44,12,49,295,46,16,19,038,37,B*04")
            .unwrap();
        assert_eq!((s.talker, s.kind), ("GB", "GSV"));
        assert_eq!(
            FixAssembler::default().feed(&s, None).unwrap(),
            Decoded::Skipped
        );
        let bad_field = parse(
            "$GNGGA,08x559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*10",
        );
        assert!(FixAssembler::default()
            .feed(&bad_field.unwrap(), None)
            .is_err());
        // Proprietary sentences are sentences, skipped.
        let line = nmea("PUBX,00,081350.00");
        let pubx = parse(&line).unwrap();
        assert_eq!((pubx.talker, pubx.kind), ("P", "UBX"));
    }

    #[test]
    fn a_non_ascii_byte_with_a_good_checksum_is_refused_not_a_panic() {
        let line = "$GPGGA,2é5959.00,4807.038,S,01131.000,W,1,08,0.9,545.4,M,46.9,M,,*33";
        assert_eq!(parse(line), Err(NmeaError::NotAscii));
        // Past the sentence check, no field is ever sliced off a character boundary either.
        let s = Sentence {
            talker: "GP",
            kind: "GGA",
            fields: vec!["2é5959.00", "4é07.038", "S", "é1131.000", "W", "1"],
        };
        assert!(FixAssembler::default().feed(&s, None).is_err());
    }

    #[test]
    fn nan_inf_exponents_and_impossible_values_are_refused_naming_the_field() {
        let reason = |body: &str| {
            let line = nmea(body);
            match FixAssembler::default().feed(&parse(&line).unwrap(), None) {
                Err(NmeaError::BadField { name, why, .. }) => format!("{name}: {why}"),
                other => panic!("{line}: {other:?}"),
            }
        };
        let gga = |lat: &str, ns: &str| {
            format!("GPGGA,120000.00,{lat},{ns},01131.000,E,1,08,0.9,545.4,M,46.9,M,,")
        };
        let gst =
            |sigma: &str| format!("GPGST,120000.00,0.45,0.020,0.015,77.4,{sigma},0.017,0.031");
        for (body, why) in [
            (
                gga("48nan", "N"),
                "latitude: degrees and minutes (d…dmm.mmmm) expected",
            ),
            (
                gga("4807.0e1", "N"),
                "latitude: degrees and minutes (d…dmm.mmmm) expected",
            ),
            (gga("4860.000", "N"), "latitude: minutes of 60 or more"),
            (
                gga("9100.000", "N"),
                "latitude: beyond the pole or the antimeridian",
            ),
            (gga("4807.038", "X"), "N/S: hemisphere expected"),
            (gst("NaN"), "σ latitude: not a number"),
            (gst("-0.5"), "σ latitude: negative"),
            (gst("inf"), "σ latitude: not a number"),
        ] {
            assert_eq!(reason(&body), why, "{body}");
        }
        for date in ["311322", "000124", "310224", "2902x3"] {
            let rmc = format!("GPRMC,120000.00,A,4807.038,N,01131.000,E,0.1,,{date},,,A");
            assert!(reason(&rmc).starts_with("date: "), "{date}");
        }
        assert_eq!(
            reason(&gga("4807.038", "N").replace("120000.00", "120060.00")),
            "time: not a time of day"
        );
        // 23:59:60 is a leap second: the same Unix instant as the next midnight.
        let mut a = FixAssembler::with_date(Some((2016, 12, 31)));
        let leap = nmea(&gga("4807.038", "N").replace("120000.00", "235960.00"));
        let f = fixes(&mut a, &[&leap], None);
        assert_eq!(f[0].stamp_ns, 1_483_228_800 * 1_000_000_000);
    }

    const GGA: &str =
        "$GNGGA,083559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*5B";
    const STAMP: u64 = 1_666_254_959 * 1_000_000_000; // 2022-10-20 08:35:59 UTC

    #[test]
    fn a_fix_before_the_date_waits_for_it_and_is_never_stamped_1970() {
        let rmc = "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F";
        let f = fixes(&mut FixAssembler::default(), &[GGA, rmc], None);
        assert_eq!(f[0].stamp_ns, STAMP);
        // ZDA gives the date too.
        let zda = "$GNZDA,083559.00,20,10,2022,00,00*7B";
        let f = fixes(&mut FixAssembler::default(), &[GGA, zda], None);
        assert_eq!(f[0].stamp_ns, STAMP);
        // Never dated: dropped and counted at the end, not stamped 1970.
        let mut n = FixAssembler::default();
        assert!(fixes(&mut n, &[GGA], None).is_empty());
        assert_eq!(n.undated, 1);
        // A date given up front, or a live clock near the fix (just after midnight UTC).
        let f = fixes(
            &mut FixAssembler::with_date(Some((2022, 10, 20))),
            &[GGA],
            None,
        );
        assert_eq!(f[0].stamp_ns, STAMP);
        let f = fixes(
            &mut FixAssembler::default(),
            &[GGA],
            Some(STAMP + 3_000_000_000),
        );
        assert_eq!(f[0].stamp_ns, STAMP);
        let late =
            "$GNGGA,235959.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*58";
        let after_midnight = 1_666_310_400 * 1_000_000_000 + 2_000_000_000; // 2022-10-21 00:00:02
        let f = fixes(&mut FixAssembler::default(), &[late], Some(after_midnight));
        assert_eq!(f[0].stamp_ns, after_midnight - 3_000_000_000);
    }

    /// A GGA at `hhmmss` and an RMC of the same epoch dated `ddmmyy`.
    fn epoch(hhmmss: &str, ddmmyy: &str) -> [String; 2] {
        [
            nmea(&format!(
                "GPGGA,{hhmmss}.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
            )),
            nmea(&format!(
                "GPRMC,{hhmmss}.00,A,4807.038,N,01131.000,E,0.1,,{ddmmyy},,,A"
            )),
        ]
    }

    #[test]
    fn each_fix_takes_its_own_epochs_date_across_midnight_and_the_new_year() {
        let new_year = 1_735_689_600 * 1_000_000_000u64; // 2025-01-01 00:00:00
                                                         // RMC after the GGA (the date comes last in each epoch).
        let mut lines: Vec<String> = epoch("235958", "311224").into();
        lines.extend(epoch("235959", "311224"));
        lines.extend(epoch("000000", "010125"));
        lines.extend(epoch("000001", "010125"));
        let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
        let stamps: Vec<u64> = fixes(&mut FixAssembler::default(), &refs, None)
            .iter()
            .map(|f| f.stamp_ns)
            .collect();
        let s = 1_000_000_000;
        assert_eq!(
            stamps,
            [new_year - 2 * s, new_year - s, new_year, new_year + s]
        );
        // Held before the first date, released by a date after midnight: the day before.
        let first = nmea("GPGGA,235959.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        let mut lines = vec![first];
        lines.extend(epoch("000000", "010125"));
        let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
        let stamps: Vec<u64> = fixes(&mut FixAssembler::default(), &refs, None)
            .iter()
            .map(|f| f.stamp_ns)
            .collect();
        assert_eq!(stamps, [new_year - s, new_year]);
        // GGA only after one dated epoch: the day rolls over with the time of day.
        let mut lines: Vec<String> = epoch("235959", "311224").into();
        lines.push(nmea(
            "GPGGA,000000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        ));
        let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
        let f = fixes(&mut FixAssembler::default(), &refs, None);
        assert_eq!(f[1].stamp_ns, new_year);
    }

    #[test]
    fn gsa_and_gst_after_the_gga_belong_to_its_epoch_and_empty_fields_carry_nothing_over() {
        let gga = |t: &str, q: u8| {
            nmea(&format!(
                "GPGGA,{t},4807.038,N,01131.000,E,{q},08,0.9,545.4,M,,M,,"
            ))
        };
        let lines = [
            // Epoch 1: no fix, GSA mode 1, no GST.
            gga("120000.00", 0),
            nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
            // Epoch 2: a fix, its GSA and GST after the GGA.
            gga("120001.00", 1),
            nmea("GPGSA,A,3,01,02,03,04,,,,,,,,,1.5,0.9,1.2"),
            nmea("GPGST,120001.00,0.45,0.020,0.015,77.4,1.5,2.5,3.5"),
            nmea("GPVTG,45.0,T,,M,10.0,N,18.52,K,A"),
            // Epoch 3: empty GST and VTG course: nothing from epoch 2.
            gga("120002.00", 1),
            nmea("GPGST,120002.00,,,,,,,"),
            nmea("GPVTG,,T,,M,10.0,N,18.52,K,A"),
        ];
        let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
        let f = fixes(
            &mut FixAssembler::with_date(Some((2025, 3, 1))),
            &refs,
            None,
        );
        assert_eq!(f.len(), 3);
        assert_eq!(f[0].fix_type, FixType::None);
        assert_eq!(f[1].fix_type, FixType::Single);
        assert_eq!(f[1].position_covariance_enu_m2.map(|c| c[0]), Some(6.25));
        assert!((f[1].course_rad.unwrap() - 45f64.to_radians()).abs() < 1e-12);
        assert_eq!(f[2].position_covariance_enu_m2, None);
        assert_eq!(f[2].course_rad, None);
        assert!((f[2].speed_mps.unwrap() - 18.52 / 3.6).abs() < 1e-12);
        // An empty geoid separation: the MSL height, and no ellipsoidal height.
        assert_eq!((f[1].altitude_m, f[1].altitude_msl_m), (None, Some(545.4)));
    }
}
