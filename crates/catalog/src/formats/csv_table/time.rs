//! A row's time from its cells: a number in a unit, or a civil time in a zone; and the rows
//! of one whole second spread over it.

use jiff::fmt::strtime;
use jiff::tz::TimeZone;

use super::mapping::{Spread, TimeSpec};

/// How a row's time is read, its columns found in the header.
#[derive(Debug, Clone)]
pub(super) enum Clock {
    /// A number of `unit_ns` nanoseconds.
    Number {
        column: usize,
        unit_ns: i128,
        offset_ns: i128,
    },
    /// Text in one or more columns, joined by a space, read with `format` in `zone`.
    Civil {
        columns: Vec<usize>,
        format: String,
        zone: TimeZone,
        offset_ns: i128,
    },
}

impl Clock {
    /// The clock a time spec states, its columns looked up with `column`; or why not.
    pub fn new(
        spec: &TimeSpec,
        mut column: impl FnMut(&str) -> Result<usize, String>,
    ) -> Result<Self, String> {
        let offset_ns = i128::from(spec.offset_ns);
        let names: Vec<&String> = spec.column.iter().chain(&spec.columns).collect();
        if names.is_empty() {
            return Err("time: give `column` or `columns`".into());
        }
        let columns = names
            .iter()
            .map(|n| column(n))
            .collect::<Result<Vec<_>, _>>()?;
        match (&spec.format, &spec.unit) {
            (Some(_), Some(_)) => Err("time: a `format` or a `unit`, not both".into()),
            (Some(format), None) => Ok(Clock::Civil {
                columns,
                format: format.clone(),
                zone: zone(spec.zone.as_deref().unwrap_or("UTC"))?,
                offset_ns,
            }),
            (None, unit) => {
                if columns.len() != 1 {
                    return Err("time: several `columns` need a `format` to join them".into());
                }
                if spec.zone.is_some() {
                    return Err("time: a `zone` is for a civil time (`format`), not a number of seconds since the epoch".into());
                }
                let unit_ns = match unit.as_deref().unwrap_or("s") {
                    "s" => 1_000_000_000,
                    "ms" => 1_000_000,
                    "us" => 1_000,
                    "ns" => 1,
                    u => return Err(format!("time unit '{u}': s, ms, us or ns")),
                };
                Ok(Clock::Number {
                    column: columns[0],
                    unit_ns,
                    offset_ns,
                })
            }
        }
    }

    /// A row's time in ns since the Unix epoch, or the text that is not one.
    pub fn stamp(&self, record: &csv::StringRecord, decimal_comma: bool) -> Result<i128, String> {
        let cell = |i: usize| record.get(i).unwrap_or("").trim();
        match self {
            Clock::Number {
                column,
                unit_ns,
                offset_ns,
            } => {
                let text = cell(*column);
                let t = number_ns(text, *unit_ns, decimal_comma)
                    .ok_or_else(|| format!("'{text}' is not a time"))?;
                Ok(t + offset_ns)
            }
            Clock::Civil {
                columns,
                format,
                zone,
                offset_ns,
            } => {
                let text: Vec<&str> = columns.iter().map(|&i| cell(i)).collect();
                let mut text = text.join(" ");
                if decimal_comma {
                    text = text.replace(',', ".");
                }
                let t = civil_ns(&text, format, zone)
                    .map_err(|e| format!("'{text}' is not a time as '{format}': {e}"))?;
                Ok(t + offset_ns)
            }
        }
    }
}

/// A zone by name: `UTC`, an offset (`+02:00`, `-0530`), or an IANA name.
fn zone(name: &str) -> Result<TimeZone, String> {
    if name.eq_ignore_ascii_case("utc") || name == "Z" {
        return Ok(TimeZone::UTC);
    }
    if name.starts_with(['+', '-']) {
        let digits: String = name[1..].chars().filter(|c| *c != ':').collect();
        let (h, m) = match digits.len() {
            2 => (digits.parse::<i32>().ok(), Some(0)),
            4 => (digits[..2].parse().ok(), digits[2..].parse().ok()),
            _ => (None, None),
        };
        if let (Some(h), Some(m)) = (h, m) {
            let sign = if name.starts_with('-') { -1 } else { 1 };
            let offset = jiff::tz::Offset::from_seconds(sign * (h * 3600 + m * 60))
                .map_err(|e| format!("zone '{name}': {e}"))?;
            return Ok(TimeZone::fixed(offset));
        }
        return Err(format!("zone '{name}': an offset is written +HH:MM"));
    }
    TimeZone::get(name).map_err(|e| format!("zone '{name}': {e}"))
}

/// A civil time's text as ns since the epoch: its own offset (`%z`) where it has one, else
/// the zone's (the earlier of the two instants in a fall-back hour, as `compatible` does).
fn civil_ns(text: &str, format: &str, zone: &TimeZone) -> Result<i128, String> {
    let broken = strtime::parse(format, text).map_err(|e| e.to_string())?;
    let timestamp = if broken.offset().is_some() {
        broken.to_timestamp().map_err(|e| e.to_string())?
    } else {
        let civil = broken.to_datetime().map_err(|e| e.to_string())?;
        zone.to_timestamp(civil).map_err(|e| e.to_string())?
    };
    Ok(timestamp.as_nanosecond())
}

/// A decimal number of `unit_ns` nanoseconds, exact to the nanosecond (an epoch in ns does
/// not fit an f64's 53 bits): `1780300800.25` s, `1780300800250000000` ns, `1.5e3` ms.
pub(super) fn number_ns(text: &str, unit_ns: i128, decimal_comma: bool) -> Option<i128> {
    let text = if decimal_comma {
        std::borrow::Cow::Owned(text.replace(',', "."))
    } else {
        std::borrow::Cow::Borrowed(text)
    };
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.as_ref()),
    };
    let plain = digits.bytes().all(|b| b.is_ascii_digit() || b == b'.') && !digits.is_empty();
    let ns = if plain {
        let (whole, fraction) = digits.split_once('.').unwrap_or((digits, ""));
        let fraction_ok = fraction.bytes().all(|b| b.is_ascii_digit());
        if whole.len() > 30 || !fraction_ok || whole.is_empty() && fraction.is_empty() {
            return None;
        }
        let whole: i128 = if whole.is_empty() {
            0
        } else {
            whole.parse().ok()?
        };
        // Eighteen digits of fraction: past a nanosecond of any unit here, and within i128.
        let (mut part, mut denominator) = (0i128, 1i128);
        for b in fraction.bytes().take(18) {
            part = part * 10 + i128::from(b - b'0');
            denominator *= 10;
        }
        whole.checked_mul(unit_ns)? + part * unit_ns / denominator
    } else {
        let x: f64 = digits.parse().ok().filter(|x: &f64| x.is_finite())?;
        let ns = x * unit_ns as f64;
        (ns.abs() < 1e30).then_some(ns as i128)?
    };
    Some(if negative { -ns } else { ns })
}

/// Rows held until their whole second is known to be complete, then given their fractions.
#[derive(Debug)]
pub(super) struct SecondSpreader {
    rule: Spread,
    rate_hz: f64,
    /// The whole second the held rows share, and the rows (line, cells).
    second: Option<i128>,
    held: Vec<(u64, csv::StringRecord)>,
}

/// Most rows one whole second may hold (a table whose time column is not the second at all
/// would otherwise be held whole).
pub(super) const MAX_ROWS_PER_SECOND: usize = 100_000;

impl SecondSpreader {
    pub fn new(rule: Spread, rate_hz: Option<f64>) -> Result<Self, String> {
        let rate_hz = match (rule, rate_hz) {
            (Spread::Rate, Some(r)) if r > 0.0 && r.is_finite() => r,
            (Spread::Rate, _) => return Err("time: spread = \"rate\" needs rate_hz > 0".into()),
            (Spread::Evenly, None) => 0.0,
            (Spread::Evenly, Some(_)) => {
                return Err("time: rate_hz is for spread = \"rate\"".into())
            }
        };
        Ok(Self {
            rule,
            rate_hz,
            second: None,
            held: Vec::new(),
        })
    }

    /// Takes a row at whole second `t`; returns the rows of the second before, with their
    /// times, once this row starts a new one (or the held rows are too many).
    pub fn push(
        &mut self,
        t: i128,
        line: u64,
        record: csv::StringRecord,
    ) -> Vec<(i128, u64, csv::StringRecord)> {
        let out = if self.second != Some(t) || self.held.len() >= MAX_ROWS_PER_SECOND {
            self.flush()
        } else {
            Vec::new()
        };
        self.second = Some(t);
        self.held.push((line, record));
        out
    }

    /// The held rows with their times: the k-th of n at `t + k/n s` (evenly) or
    /// `t + k/rate s` (a row past the rate's count keeps going at the rate and is counted
    /// by the caller as later than its second).
    pub fn flush(&mut self) -> Vec<(i128, u64, csv::StringRecord)> {
        let Some(t) = self.second.take() else {
            return Vec::new();
        };
        let n = self.held.len() as f64;
        let step = match self.rule {
            Spread::Evenly => 1e9 / n.max(1.0),
            Spread::Rate => 1e9 / self.rate_hz,
        };
        std::mem::take(&mut self.held)
            .into_iter()
            .enumerate()
            .map(|(k, (line, r))| (t + (k as f64 * step).round() as i128, line, r))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_exact_to_the_nanosecond_and_commas_are_decimal_marks_when_asked() {
        assert_eq!(
            number_ns("1780300800.123456789", 1_000_000_000, false),
            Some(1_780_300_800_123_456_789)
        );
        assert_eq!(
            number_ns("1780300800250000000", 1, false),
            Some(1_780_300_800_250_000_000)
        );
        assert_eq!(number_ns("2,5", 1_000_000, true), Some(2_500_000));
        assert_eq!(number_ns("1.5e3", 1_000_000, false), Some(1_500_000_000));
        assert_eq!(number_ns("-0.5", 1_000_000_000, false), Some(-500_000_000));
        assert_eq!(number_ns("2,5", 1, false), None);
        assert_eq!(number_ns("", 1, false), None);
        assert_eq!(number_ns(".", 1, false), None);
    }

    #[test]
    fn a_civil_time_takes_its_zone_with_daylight_saving() {
        let zurich = zone("Europe/Zurich").unwrap();
        let f = "%Y %m %d %H %M %S";
        // Summer: UTC+2; winter: UTC+1.
        let summer = civil_ns("2023 7 1 10 5 3", f, &zurich).unwrap();
        let winter = civil_ns("2023 1 1 10 5 3", f, &zurich).unwrap();
        let utc = |s: &str| civil_ns(s, f, &TimeZone::UTC).unwrap();
        assert_eq!(summer, utc("2023 7 1 8 5 3"));
        assert_eq!(winter, utc("2023 1 1 9 5 3"));
        assert_eq!(
            civil_ns("2023 7 1 10 5 3", f, &zone("+02:00").unwrap()).unwrap(),
            summer
        );
        // A time with its own offset keeps it, whatever the zone.
        let own = civil_ns(
            "2023-07-01 10:05:03 +0200",
            "%Y-%m-%d %H:%M:%S %z",
            &TimeZone::UTC,
        );
        assert_eq!(own.unwrap(), summer);
        assert!(zone("Mars/Olympus").is_err() && zone("+2:0:0").is_err());
    }

    #[test]
    fn the_rows_of_one_second_are_spread_by_the_rule() {
        let row = || csv::StringRecord::from(vec!["x"]);
        let mut even = SecondSpreader::new(Spread::Evenly, None).unwrap();
        for line in 0..4 {
            assert!(even.push(10_000_000_000, line, row()).is_empty());
        }
        let out = even.push(11_000_000_000, 9, row());
        let times: Vec<i128> = out.iter().map(|(t, _, _)| *t - 10_000_000_000).collect();
        assert_eq!(times, vec![0, 250_000_000, 500_000_000, 750_000_000]);
        let mut rate = SecondSpreader::new(Spread::Rate, Some(5.0)).unwrap();
        for line in 0..3 {
            rate.push(0, line, row());
        }
        let times: Vec<i128> = rate.flush().iter().map(|(t, _, _)| *t).collect();
        assert_eq!(times, vec![0, 200_000_000, 400_000_000]);
        assert!(SecondSpreader::new(Spread::Rate, None).is_err());
    }
}
