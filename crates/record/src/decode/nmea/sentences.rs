//! Each decoded sentence type read into what it says of its epoch ([`Report`]), whole
//! before it touches a cycle: a sentence with a bad field changes nothing.

use railfuse_catalog::messages::FixType;

use super::fields::{
    angle, bad, decimal, field, mode_indicator, status, time_of_day, unsafe_status, whole,
};
use super::{NmeaError, Sentence};
use crate::decode::time::is_date;
use crate::decode::time::Date;

/// The sentence types decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Gga,
    Gns,
    Rmc,
    Gll,
    Vtg,
    Gst,
    Zda,
    Gsa,
}

impl Kind {
    fn of(kind: &str) -> Option<Kind> {
        Some(match kind {
            "GGA" => Kind::Gga,
            "GNS" => Kind::Gns,
            "RMC" => Kind::Rmc,
            "GLL" => Kind::Gll,
            "VTG" => Kind::Vtg,
            "GST" => Kind::Gst,
            "ZDA" => Kind::Zda,
            "GSA" => Kind::Gsa,
            _ => return None,
        })
    }

    /// Sent once per talker and epoch (GSA comes once per constellation, or twice on
    /// dual-band receivers, and is not).
    pub(super) fn once_per_epoch(self) -> bool {
        self != Kind::Gsa
    }

    /// Has a time field: one that came empty marks an epoch without a time.
    pub(super) fn carries_time(self) -> bool {
        !matches!(self, Kind::Vtg | Kind::Gsa)
    }

    /// Carries the fix quality, satellites and heights (GGA, GNS), not only a position.
    pub(super) fn is_fix_sentence(self) -> bool {
        matches!(self, Kind::Gga | Kind::Gns)
    }
}

/// The talker of a sentence (`GP`, `GN`, …).
pub(super) type Talker = [u8; 2];

/// The combined, multi-constellation talker.
pub(super) const COMBINED: Talker = *b"GN";

/// A position report: GGA, GNS, RMC or GLL.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Position {
    pub talker: Talker,
    pub kind: Kind,
    pub fix_type: FixType,
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    /// Satellites used (GGA, GNS).
    pub satellites: Option<u32>,
    pub hdop: Option<f64>,
    pub msl_m: Option<f64>,
    pub separation_m: Option<f64>,
    /// Navigation status U: the receiver says the position is unsafe.
    pub unsafe_status: bool,
}

impl Position {
    fn new(talker: Talker, kind: Kind, fix_type: FixType) -> Self {
        Position {
            talker,
            kind,
            fix_type,
            latitude_deg: None,
            longitude_deg: None,
            satellites: None,
            hdop: None,
            msl_m: None,
            separation_m: None,
            unsafe_status: false,
        }
    }
}

/// Speed and course over ground, as far as given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Motion {
    pub speed_mps: Option<f64>,
    pub course_rad: Option<f64>,
}

/// What a GSA says.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Gsa {
    /// Fix mode 1 (`Some(true)`), 2 or 3 (`Some(false)`); `None` when not given.
    pub no_fix: Option<bool>,
    /// The satellites used, as (constellation, PRN): the NMEA 4.1 system id, else the
    /// talker's constellation, else 0 (a `GN` GSA numbers every constellation apart).
    pub satellites: Vec<(u8, u32)>,
    pub hdop: Option<f64>,
}

/// What one sentence adds to its cycle.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Part {
    /// GGA, GNS, GLL.
    Position(Position),
    /// The position, the date, and speed and course when the receiver says they are valid.
    Rmc(Position, Option<Date>, Option<Motion>),
    Zda(Date),
    /// `None`: the receiver says it has no speed or course (mode N).
    Vtg(Option<Motion>),
    Gsa(Gsa),
    Gst(Option<(f64, f64, f64)>),
}

/// A decoded sentence: its type, talker, time of day (ns since midnight) and what it says.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Report {
    pub kind: Kind,
    pub talker: Talker,
    pub tod_ns: Option<u64>,
    pub part: Part,
}

/// Decodes `s`; `None` for a type that is not used.
pub(super) fn decode(s: &Sentence<'_>) -> Result<Option<Report>, NmeaError> {
    let Some(kind) = Kind::of(s.kind) else {
        return Ok(None);
    };
    let t = s.talker.as_bytes();
    let talker = [
        t.first().copied().unwrap_or(b' '),
        t.get(1).copied().unwrap_or(b' '),
    ];
    let (tod_ns, part) = match kind {
        Kind::Gga => gga(s, talker)?,
        Kind::Gns => gns(s, talker)?,
        Kind::Rmc => rmc(s, talker)?,
        Kind::Gll => gll(s, talker)?,
        Kind::Vtg => (None, vtg(s)?),
        Kind::Gst => gst(s)?,
        Kind::Zda => zda(s)?,
        Kind::Gsa => (None, Part::Gsa(gsa(s, talker)?)),
    };
    Ok(Some(Report {
        kind,
        talker,
        tod_ns,
        part,
    }))
}

/// The time of a position sentence (field `i`); an empty one is allowed only where it
/// reports no fix.
fn position_time(s: &Sentence<'_>, i: usize, fix_type: FixType) -> Result<Option<u64>, NmeaError> {
    let tod = time_of_day(s, i)?;
    if tod.is_none() && fix_type.has_position() {
        return Err(bad(s, i, "time", "a fix without a time"));
    }
    Ok(tod)
}

/// Latitude at field `i`, longitude at `i + 2`.
fn lat_lon(s: &Sentence<'_>, i: usize, p: &mut Position) -> Result<(), NmeaError> {
    p.latitude_deg = angle(s, i, false)?;
    p.longitude_deg = angle(s, i + 2, true)?;
    Ok(())
}

/// GGA: the fix, its quality, satellites, HDOP and heights.
fn gga(s: &Sentence<'_>, talker: Talker) -> Result<(Option<u64>, Part), NmeaError> {
    let fix_type = match whole(s, 5, "fix quality")?.unwrap_or(0) {
        1 => FixType::Single,
        2 | 3 => FixType::Dgps,
        4 => FixType::RtkFixed,
        5 => FixType::RtkFloat,
        0 | 6..=8 => FixType::None,
        _ => return Err(bad(s, 5, "fix quality", "0 to 8 expected")),
    };
    let tod = position_time(s, 0, fix_type)?;
    let mut p = Position::new(talker, Kind::Gga, fix_type);
    lat_lon(s, 1, &mut p)?;
    p.satellites = whole(s, 6, "satellites")?;
    p.hdop = decimal(s, 7, "HDOP", false)?;
    p.msl_m = decimal(s, 8, "altitude", true)?;
    p.separation_m = decimal(s, 10, "geoid separation", true)?;
    Ok((tod, Part::Position(p)))
}

/// GNS (NMEA 4.x): the fix with a mode indicator per constellation, satellites, HDOP,
/// heights and the navigation status.
fn gns(s: &Sentence<'_>, talker: Talker) -> Result<(Option<u64>, Part), NmeaError> {
    let fix_type = mode_indicator(s, 5)?.unwrap_or(FixType::None);
    let tod = position_time(s, 0, fix_type)?;
    let mut p = Position::new(talker, Kind::Gns, fix_type);
    lat_lon(s, 1, &mut p)?;
    p.satellites = whole(s, 6, "satellites")?;
    p.hdop = decimal(s, 7, "HDOP", false)?;
    p.msl_m = decimal(s, 8, "altitude", true)?;
    p.separation_m = decimal(s, 9, "geoid separation", true)?;
    p.unsafe_status = unsafe_status(s, 12)?;
    Ok((tod, Part::Position(p)))
}

/// The fix type of an RMC or GLL: none unless the status is A, then its mode indicator
/// (before NMEA 2.3 there is none: a single fix).
fn valid_fix(s: &Sentence<'_>, status_at: usize, mode_at: usize) -> Result<FixType, NmeaError> {
    let valid = status(s, status_at)?;
    let mode = mode_indicator(s, mode_at)?.unwrap_or(FixType::Single);
    Ok(if valid { mode } else { FixType::None })
}

/// RMC: position, date, and speed and course when the status is valid.
fn rmc(s: &Sentence<'_>, talker: Talker) -> Result<(Option<u64>, Part), NmeaError> {
    let fix_type = valid_fix(s, 1, 11)?;
    let tod = position_time(s, 0, fix_type)?;
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
    let motion = Motion {
        speed_mps: decimal(s, 6, "speed", false)?.map(|kn| kn * 1852.0 / 3600.0),
        course_rad: decimal(s, 7, "course", false)?.map(f64::to_radians),
    };
    let mut p = Position::new(talker, Kind::Rmc, fix_type);
    lat_lon(s, 2, &mut p)?;
    p.unsafe_status = unsafe_status(s, 12)?;
    let motion = fix_type.has_position().then_some(motion);
    Ok((tod, Part::Rmc(p, date, motion)))
}

/// GLL: position and time, valid with status A.
fn gll(s: &Sentence<'_>, talker: Talker) -> Result<(Option<u64>, Part), NmeaError> {
    let fix_type = valid_fix(s, 5, 6)?;
    let tod = position_time(s, 4, fix_type)?;
    let mut p = Position::new(talker, Kind::Gll, fix_type);
    lat_lon(s, 0, &mut p)?;
    Ok((tod, Part::Position(p)))
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

/// VTG: speed and course over ground (none in mode N). NMEA 2.0 and later put a unit letter
/// after each value (`t,T,m,M,kn,N,kmh,K[,mode]`); older receivers send the four values alone.
fn vtg(s: &Sentence<'_>) -> Result<Part, NmeaError> {
    let (knots_at, kmh_at, mode_at) = match field(s, 1) {
        "T" | "" if s.fields.len() >= 8 => (4, 6, Some(8)),
        _ => (2, 3, None),
    };
    let course = decimal(s, 0, "course", false)?.map(f64::to_radians);
    let speed = match decimal(s, kmh_at, "speed", false)? {
        Some(kmh) => Some(kmh / 3.6),
        None => decimal(s, knots_at, "speed", false)?.map(|kn| kn * 1852.0 / 3600.0),
    };
    let mode = match mode_at {
        Some(i) => mode_indicator(s, i)?,
        None => None,
    };
    Ok(match mode {
        Some(m) if !m.has_position() => Part::Vtg(None),
        _ => Part::Vtg(Some(Motion {
            speed_mps: speed,
            course_rad: course,
        })),
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

/// The constellation a talker reports (NMEA 4.11 system ids), 0 for a combined talker.
fn constellation(talker: Talker) -> u8 {
    match &talker {
        b"GP" => 1,
        b"GL" => 2,
        b"GA" => 3,
        b"GB" | b"BD" => 4,
        b"GQ" => 5,
        b"GI" => 6,
        _ => 0,
    }
}

/// GSA: fix mode, the satellites used (twelve PRN fields), the DOPs and, from NMEA 4.1, the
/// system id.
fn gsa(s: &Sentence<'_>, talker: Talker) -> Result<Gsa, NmeaError> {
    let no_fix = match whole(s, 1, "fix mode")? {
        None => None,
        Some(1) => Some(true),
        Some(2 | 3) => Some(false),
        Some(_) => return Err(bad(s, 1, "fix mode", "1, 2 or 3 expected")),
    };
    let system = match whole(s, 17, "system id")? {
        Some(id) => u8::try_from(id).map_err(|_| bad(s, 17, "system id", "out of range"))?,
        None => constellation(talker),
    };
    let mut satellites = Vec::new();
    for i in 2..14 {
        if let Some(prn) = whole(s, i, "satellite PRN")? {
            satellites.push((system, prn));
        }
    }
    Ok(Gsa {
        no_fix,
        satellites,
        hdop: decimal(s, 15, "HDOP", false)?,
    })
}
