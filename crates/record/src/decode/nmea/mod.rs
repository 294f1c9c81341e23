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
            "GGA" => match gga(s)? {
                Some(p) => p,
                None => return Ok(Decoded::NoFixYet),
            },
            "RMC" => rmc(s)?,
            "ZDA" => zda(s)?,
            "VTG" => vtg(s)?,
            "GSA" => (None, Part::Gsa(whole(s, 1, "fix mode")? == Some(1))),
            "GST" => gst(s)?,
            _ => return Ok(Decoded::Skipped),
        };
        self.enter(tod, clock_ns);
        self.cycle.get_or_insert_with(Cycle::default).add(part);
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

/// GGA: the fix, its quality, satellites, HDOP and heights (`None`: no fix yet, no time).
fn gga(s: &Sentence<'_>) -> Result<Option<(Option<u64>, Part)>, NmeaError> {
    let quality = whole(s, 5, "fix quality")?.unwrap_or(0);
    let Some(tod) = time_of_day(s, 0)? else {
        return if quality == 0 {
            Ok(None)
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
    Ok(Some((Some(tod), Part::Gga(gga))))
}

/// RMC: the date, and speed and course when the status is valid.
fn rmc(s: &Sentence<'_>) -> Result<(Option<u64>, Part), NmeaError> {
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
    Ok((tod, Part::Rmc(date, valid.then_some((speed, course)))))
}

/// ZDA: the date in full.
fn zda(s: &Sentence<'_>) -> Result<(Option<u64>, Part), NmeaError> {
    let tod = time_of_day(s, 0)?.ok_or_else(|| bad(s, 0, "time", "empty"))?;
    let d = whole(s, 1, "day")?.ok_or_else(|| bad(s, 1, "day", "empty"))?;
    let m = whole(s, 2, "month")?.ok_or_else(|| bad(s, 2, "month", "empty"))?;
    let y = whole(s, 3, "year")?.ok_or_else(|| bad(s, 3, "year", "empty"))?;
    if field(s, 3).len() != 4 || !is_date(y.into(), m, d) {
        return Err(bad(s, 3, "year", "not a date on the calendar"));
    }
    Ok((Some(tod), Part::Zda((y.into(), m, d))))
}

/// VTG: speed and course over ground (none in mode N).
fn vtg(s: &Sentence<'_>) -> Result<(Option<u64>, Part), NmeaError> {
    let course = decimal(s, 0, "course", false)?.map(f64::to_radians);
    let speed = decimal(s, 6, "speed", false)?.map(|kmh| kmh / 3.6);
    Ok(match field(s, 8) == "N" {
        true => (None, Part::Vtg(None, None)),
        false => (None, Part::Vtg(speed, course)),
    })
}

/// GST: the position's standard deviations.
fn gst(s: &Sentence<'_>) -> Result<(Option<u64>, Part), NmeaError> {
    let tod = time_of_day(s, 0)?;
    let sigmas = match (
        decimal(s, 5, "σ latitude", false)?,
        decimal(s, 6, "σ longitude", false)?,
        decimal(s, 7, "σ altitude", false)?,
    ) {
        (Some(a), Some(b), Some(c)) => Some((a, b, c)),
        _ => None,
    };
    Ok((tod, Part::Gst(sigmas)))
}

impl Cycle {
    /// A sentence's part added to the reporting cycle.
    fn add(&mut self, part: Part) {
        let c = self;
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
    }
}

#[cfg(test)]
mod tests;
