//! Field readers shared by the sentence decoders: every number, angle, time and mode
//! indicator checked before it is trusted, a bad one named by its field.

use railfuse_catalog::messages::FixType;

use super::{NmeaError, Sentence};
use crate::decode::time::is_time_of_day;

/// The field `i` (0-based after the address) of `s`, or "" past its end.
pub(super) fn field<'a>(s: &Sentence<'a>, i: usize) -> &'a str {
    s.fields.get(i).copied().unwrap_or("")
}

pub(super) fn bad(s: &Sentence<'_>, i: usize, name: &'static str, why: &'static str) -> NmeaError {
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
pub(super) fn decimal(
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
pub(super) fn whole(
    s: &Sentence<'_>,
    i: usize,
    name: &'static str,
) -> Result<Option<u32>, NmeaError> {
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
pub(super) fn angle(s: &Sentence<'_>, i: usize, longitude: bool) -> Result<Option<f64>, NmeaError> {
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
pub(super) fn time_of_day(s: &Sentence<'_>, i: usize) -> Result<Option<u64>, NmeaError> {
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

/// One FAA mode indicator character as a fix type (`None`: not a mode indicator).
fn faa_mode(c: u8) -> Option<FixType> {
    Some(match c {
        b'A' => FixType::Single,
        b'D' | b'P' => FixType::Dgps,
        b'R' => FixType::RtkFixed,
        b'F' => FixType::RtkFloat,
        b'N' | b'E' | b'M' | b'S' => FixType::None,
        _ => return None,
    })
}

/// A mode indicator field (one character, or one per constellation in GNS) → the best fix
/// type of its characters; empty is `None`.
pub(super) fn mode_indicator(s: &Sentence<'_>, i: usize) -> Result<Option<FixType>, NmeaError> {
    let t = field(s, i);
    if t.is_empty() {
        return Ok(None);
    }
    let mut best = FixType::None;
    for &c in t.as_bytes() {
        let m = faa_mode(c).ok_or_else(|| {
            bad(
                s,
                i,
                "mode indicator",
                "N, A, D, P, R, F, E, M or S expected",
            )
        })?;
        if rank(m) > rank(best) {
            best = m;
        }
    }
    Ok(Some(best))
}

/// How good a fix type is: none < single < differential < RTK float < RTK fixed.
pub(super) fn rank(f: FixType) -> u8 {
    match f {
        FixType::None => 0,
        FixType::Single => 1,
        FixType::Dgps => 2,
        FixType::RtkFloat => 3,
        FixType::RtkFixed => 4,
    }
}

/// An RMC/GLL status field: A valid, V (or empty) not.
pub(super) fn status(s: &Sentence<'_>, i: usize) -> Result<bool, NmeaError> {
    match field(s, i) {
        "A" => Ok(true),
        "V" | "" => Ok(false),
        _ => Err(bad(s, i, "status", "A or V expected")),
    }
}

/// The NMEA 4.1 navigation status (RMC, GNS): true for `U`, unsafe.
pub(super) fn unsafe_status(s: &Sentence<'_>, i: usize) -> Result<bool, NmeaError> {
    match field(s, i) {
        "U" => Ok(true),
        "" | "S" | "C" | "V" => Ok(false),
        _ => Err(bad(s, i, "navigation status", "S, C, U or V expected")),
    }
}
