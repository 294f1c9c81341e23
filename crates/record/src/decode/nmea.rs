//! NMEA 0183 sentences: `$<talker><type>,<fields>*<hh>` with the XOR checksum of everything
//! between `$` and `*`. GGA, RMC, ZDA, VTG, GSA and GST are decoded and assembled into fixes:
//! one fix per GGA, with the date of the latest RMC/ZDA, the speed and course of the latest
//! RMC/VTG and the covariance of the latest GST. Other sentence types are recognised and
//! skipped.
//!
//! GGA carries only the time of day. A GGA before any date waits (up to [`MAX_HELD`] fixes)
//! for the first RMC or ZDA and is then stamped with its date; a live recorder gives its UTC
//! clock instead, and the fix takes the day that puts it nearest that clock; an import can be
//! told the date. A fix is never stamped with a made-up day (1970).

use std::collections::VecDeque;

use railfuse_catalog::messages::{FixType, GnssFix};

use super::time::unix_ns;

/// Fixes held while no date is known (a minute at 10 Hz); older ones are dropped and counted.
pub const MAX_HELD: usize = 600;

/// A UTC calendar date.
pub type Date = (i64, u32, u32);

/// Time of day: hours, minutes, seconds, nanoseconds.
type TimeOfDay = (u32, u32, u32, i64);

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
    #[error("NMEA {sentence}: field {field} does not parse")]
    BadField { sentence: String, field: usize },
}

/// A checked sentence: its type (without talker) and fields.
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
    let expected = u8::from_str_radix(hex, 16).map_err(|_| NmeaError::NotASentence)?;
    let found = data.bytes().fold(0u8, |a, b| a ^ b);
    if expected != found {
        return Err(NmeaError::Checksum { expected, found });
    }
    let mut fields = data.split(',');
    let head = fields.next().unwrap_or_default();
    if head.len() < 5 || !head.is_ascii() {
        return Err(NmeaError::NotASentence);
    }
    let (talker, kind) = head.split_at(head.len() - 3);
    Ok(Sentence {
        talker,
        kind,
        fields: fields.collect(),
    })
}

/// What a sentence did to the assembler.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoded {
    /// A fix (GGA) is ready: take it with [`FixAssembler::next_fix`].
    Fix,
    /// A fix (GGA) waits for a date.
    Held,
    /// Used to complete fixes (RMC, ZDA, VTG, GSA, GST); an RMC or ZDA may release held ones.
    Context,
    /// A sentence type railfuse does not use (GSV, GLL, TXT, …).
    Skipped,
}

/// Assembles fixes from a stream of sentences of one receiver.
#[derive(Debug, Default, Clone)]
pub struct FixAssembler {
    date: Option<Date>,
    held: VecDeque<(TimeOfDay, GnssFix)>,
    ready: VecDeque<GnssFix>,
    /// Fixes dropped for want of a date.
    pub undated: u64,
    speed_mps: Option<f64>,
    course_rad: Option<f64>,
    /// (σ lat, σ lon, σ alt) in metres from GST.
    sigmas: Option<(f64, f64, f64)>,
    no_fix_mode: bool,
}

fn num(s: &Sentence<'_>, i: usize) -> Result<Option<f64>, NmeaError> {
    match s.fields.get(i).copied().unwrap_or("") {
        "" => Ok(None),
        t => t.parse::<f64>().map(Some).map_err(|_| NmeaError::BadField {
            sentence: s.kind.to_owned(),
            field: i + 1,
        }),
    }
}

/// `ddmm.mmmm` + hemisphere → signed degrees.
fn angle(s: &Sentence<'_>, i: usize, deg_digits: usize) -> Result<Option<f64>, NmeaError> {
    let (v, hemi) = (
        s.fields.get(i).copied().unwrap_or(""),
        s.fields.get(i + 1).copied().unwrap_or(""),
    );
    if v.is_empty() {
        return Ok(None);
    }
    let bad = || NmeaError::BadField {
        sentence: s.kind.to_owned(),
        field: i + 1,
    };
    if v.len() < deg_digits + 2 {
        return Err(bad());
    }
    let d: f64 = v[..deg_digits].parse().map_err(|_| bad())?;
    let m: f64 = v[deg_digits..].parse().map_err(|_| bad())?;
    let x = d + m / 60.0;
    Ok(Some(if matches!(hemi, "S" | "W") { -x } else { x }))
}

/// The stamp of time of day `tod` on the day (of the days around `clock_ns`) that puts it
/// nearest that clock.
fn nearest_day(clock_ns: u64, (h, mi, se, ns): TimeOfDay) -> Option<u64> {
    const DAY_NS: u64 = 86_400_000_000_000;
    let midnight = clock_ns - clock_ns % DAY_NS;
    let tod = (h as u64 * 3600 + mi as u64 * 60 + se as u64) * 1_000_000_000;
    let at = (midnight + tod).checked_add_signed(ns)?;
    [at.checked_sub(DAY_NS), Some(at), at.checked_add(DAY_NS)]
        .into_iter()
        .flatten()
        .min_by_key(|t| t.abs_diff(clock_ns))
}

/// `hhmmss.ss` → (h, m, s, ns).
fn time_of_day(s: &Sentence<'_>, i: usize) -> Result<Option<TimeOfDay>, NmeaError> {
    let t = s.fields.get(i).copied().unwrap_or("");
    if t.is_empty() {
        return Ok(None);
    }
    let bad = || NmeaError::BadField {
        sentence: s.kind.to_owned(),
        field: i + 1,
    };
    if t.len() < 6 {
        return Err(bad());
    }
    let h = t[..2].parse().map_err(|_| bad())?;
    let m = t[2..4].parse().map_err(|_| bad())?;
    let sec: f64 = t[4..].parse().map_err(|_| bad())?;
    Ok(Some((
        h,
        m,
        sec.trunc() as u32,
        (sec.fract() * 1e9).round() as i64,
    )))
}

impl FixAssembler {
    /// An assembler that knows the date from the start (an import given `--date`).
    pub fn with_date(date: Option<Date>) -> Self {
        Self {
            date,
            ..Self::default()
        }
    }

    /// The next fix ready, in the order of their GGA sentences.
    pub fn next_fix(&mut self) -> Option<GnssFix> {
        self.ready.pop_front()
    }

    /// End of the stream: fixes still waiting for a date are dropped; returns how many were
    /// dropped for want of one in all.
    pub fn finish(&mut self) -> u64 {
        self.undated += self.held.len() as u64;
        self.held.clear();
        self.undated
    }

    /// A date is known: the held fixes get their stamps.
    fn release(&mut self) {
        let Some((y, mo, d)) = self.date else { return };
        while let Some(((h, mi, se, ns), mut fix)) = self.held.pop_front() {
            match unix_ns(y, mo, d, h, mi, se, ns) {
                Some(stamp) => {
                    fix.stamp_ns = stamp;
                    self.ready.push_back(fix);
                }
                None => self.undated += 1,
            }
        }
    }

    /// Feeds one sentence. `clock_ns` is a UTC clock near the sentence's time when there is
    /// one (a live recorder's receive time): a fix before any date takes the day nearest it.
    pub fn feed(&mut self, s: &Sentence<'_>, clock_ns: Option<u64>) -> Result<Decoded, NmeaError> {
        match s.kind {
            "GGA" => {
                let tod = time_of_day(s, 0)?;
                let (lat, lon) = (angle(s, 1, 2)?, angle(s, 3, 3)?);
                let quality = num(s, 5)?.unwrap_or(0.0) as u8;
                let fix_type = match quality {
                    1 => FixType::Single,
                    2 | 3 => FixType::Dgps,
                    4 => FixType::RtkFixed,
                    5 => FixType::RtkFloat,
                    _ => FixType::None,
                };
                let fix_type = if self.no_fix_mode {
                    FixType::None
                } else {
                    fix_type
                };
                let has = fix_type.has_position() && lat.is_some() && lon.is_some();
                let altitude = match (num(s, 8)?, num(s, 10)?) {
                    (Some(msl), sep) => Some(msl + sep.unwrap_or(0.0)),
                    _ => None,
                };
                let Some(tod) = tod else {
                    return Err(NmeaError::BadField {
                        sentence: "GGA".into(),
                        field: 1,
                    });
                };
                let fix = GnssFix {
                    stamp_ns: 0,
                    fix_type: if has { fix_type } else { FixType::None },
                    satellites: num(s, 6)?.unwrap_or(0.0).clamp(0.0, 255.0) as u8,
                    hdop: num(s, 7)?,
                    latitude_deg: lat.filter(|_| has),
                    longitude_deg: lon.filter(|_| has),
                    altitude_m: altitude.filter(|_| has),
                    position_covariance_enu_m2: self.sigmas.filter(|_| has).map(|(sn, se, su)| {
                        [se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, su * su]
                    }),
                    speed_mps: self.speed_mps.filter(|_| has),
                    course_rad: self.course_rad.filter(|_| has),
                };
                let (h, mi, se, ns) = tod;
                let stamp = match (self.date, clock_ns) {
                    (Some((y, mo, d)), _) => unix_ns(y, mo, d, h, mi, se, ns),
                    (None, Some(clock)) => nearest_day(clock, tod),
                    (None, None) => {
                        if self.held.len() == MAX_HELD {
                            self.held.pop_front();
                            self.undated += 1;
                        }
                        self.held.push_back((tod, fix));
                        return Ok(Decoded::Held);
                    }
                };
                let Some(stamp_ns) = stamp else {
                    return Err(NmeaError::BadField {
                        sentence: "GGA".into(),
                        field: 1,
                    });
                };
                self.ready.push_back(GnssFix { stamp_ns, ..fix });
                Ok(Decoded::Fix)
            }
            "ZDA" => {
                // hhmmss.ss, day, month, year
                if let (Some(d), Some(m), Some(y)) = (num(s, 1)?, num(s, 2)?, num(s, 3)?) {
                    self.date = Some((y as i64, m as u32, d as u32));
                    self.release();
                }
                Ok(Decoded::Context)
            }
            "RMC" => {
                let date = s.fields.get(8).copied().unwrap_or("");
                if date.len() == 6 {
                    let p = |r: std::ops::Range<usize>| date[r].parse::<u32>().ok();
                    if let (Some(d), Some(m), Some(y)) = (p(0..2), p(2..4), p(4..6)) {
                        self.date = Some((2000 + y as i64, m, d));
                        self.release();
                    }
                }
                let valid = s.fields.get(1).copied() == Some("A");
                self.speed_mps = num(s, 6)?.filter(|_| valid).map(|kn| kn * 1852.0 / 3600.0);
                self.course_rad = num(s, 7)?.filter(|_| valid).map(f64::to_radians);
                Ok(Decoded::Context)
            }
            "VTG" => {
                if let Some(kmh) = num(s, 6)? {
                    self.speed_mps = Some(kmh / 3.6);
                }
                if let Some(c) = num(s, 0)? {
                    self.course_rad = Some(c.to_radians());
                }
                Ok(Decoded::Context)
            }
            "GSA" => {
                self.no_fix_mode = num(s, 1)? == Some(1.0);
                Ok(Decoded::Context)
            }
            "GST" => {
                if let (Some(a), Some(b), Some(c)) = (num(s, 5)?, num(s, 6)?, num(s, 7)?) {
                    self.sigmas = Some((a, b, c));
                }
                Ok(Decoded::Context)
            }
            _ => Ok(Decoded::Skipped),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fix_is_assembled_from_rmc_gst_and_gga() {
        let mut a = FixAssembler::default();
        for line in [
            "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F",
            "$GNGST,083559.00,0.45,0.020,0.015,77.4,0.018,0.017,0.031*45",
        ] {
            let s = parse(line).unwrap_or_else(|e| panic!("{line}: {e}"));
            assert_eq!(a.feed(&s, None).unwrap(), Decoded::Context);
        }
        let gga = "$GNGGA,083559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*5B";
        assert_eq!(a.feed(&parse(gga).unwrap(), None).unwrap(), Decoded::Fix);
        let f = a.next_fix().unwrap();
        assert_eq!(f.fix_type, FixType::RtkFixed);
        assert_eq!(f.stamp_ns, 1_666_254_959 * 1_000_000_000);
        assert!((f.latitude_deg.unwrap() - 44.655110666).abs() < 1e-8);
        assert!((f.longitude_deg.unwrap() - 10.929730333).abs() < 1e-8);
        assert!((f.altitude_m.unwrap() - 79.3).abs() < 1e-9);
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
    }

    const GGA: &str =
        "$GNGGA,083559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*5B";
    const STAMP: u64 = 1_666_254_959 * 1_000_000_000; // 2022-10-20 08:35:59 UTC

    #[test]
    fn a_fix_before_the_date_waits_for_it_and_is_never_stamped_1970() {
        let mut a = FixAssembler::default();
        assert_eq!(a.feed(&parse(GGA).unwrap(), None).unwrap(), Decoded::Held);
        assert!(a.next_fix().is_none());
        let rmc = "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F";
        a.feed(&parse(rmc).unwrap(), None).unwrap();
        assert_eq!(a.next_fix().unwrap().stamp_ns, STAMP);
        // ZDA gives the date too.
        let mut z = FixAssembler::default();
        z.feed(&parse(GGA).unwrap(), None).unwrap();
        let zda = "$GNZDA,083559.00,20,10,2022,00,00*7B";
        z.feed(&parse(zda).unwrap(), None).unwrap();
        assert_eq!(z.next_fix().unwrap().stamp_ns, STAMP);
        // Never dated: dropped and counted at the end, not stamped 1970.
        let mut n = FixAssembler::default();
        n.feed(&parse(GGA).unwrap(), None).unwrap();
        assert_eq!((n.finish(), n.next_fix()), (1, None));
        // A date given up front, or a live clock near the fix (just after midnight UTC).
        let mut d = FixAssembler::with_date(Some((2022, 10, 20)));
        d.feed(&parse(GGA).unwrap(), None).unwrap();
        assert_eq!(d.next_fix().unwrap().stamp_ns, STAMP);
        let mut c = FixAssembler::default();
        c.feed(&parse(GGA).unwrap(), Some(STAMP + 3_000_000_000))
            .unwrap();
        assert_eq!(c.next_fix().unwrap().stamp_ns, STAMP);
        let late =
            "$GNGGA,235959.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*58";
        let after_midnight = 1_666_310_400 * 1_000_000_000 + 2_000_000_000; // 2022-10-21 00:00:02
        c.feed(&parse(late).unwrap(), Some(after_midnight)).unwrap();
        assert_eq!(
            c.next_fix().unwrap().stamp_ns,
            after_midnight - 3_000_000_000
        );
    }
}
