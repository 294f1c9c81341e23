//! Calendar time to Unix nanoseconds, for GNSS UTC fields. Every field is range-checked
//! against the calendar (month 1–12, the month's own days, 23:59:60 only as a leap second):
//! an impossible date is an error, never normalised into another day.

/// A UTC calendar date (year, month, day).
pub type Date = (i64, u32, u32);

/// Days from 1970-01-01 to a proleptic Gregorian date (Howard Hinnant's algorithm).
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let m = month as i64;
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + day as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Days in `month` of `year` (0 for a month that does not exist).
pub fn days_in_month(year: i64, month: u32) -> u32 {
    let leap = year % 4 == 0 && (year % 100 != 0 || year % 400 == 0);
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => 0,
    }
}

/// True for a date on the calendar (no 31 February, no month 13, no day 0).
pub fn is_date(year: i64, month: u32, day: u32) -> bool {
    (1..=days_in_month(year, month)).contains(&day)
}

/// True for a UTC time of day: second 60 only at 23:59 (a leap second).
pub fn is_time_of_day(hour: u32, minute: u32, second: u32) -> bool {
    hour <= 23 && minute <= 59 && (second <= 59 || (second == 60 && hour == 23 && minute == 59))
}

/// Unix time in nanoseconds of a UTC date and time; None when any field is off the calendar,
/// `nanos` is outside ±1 s (UBX's own range) or the instant is before 1970. A leap second
/// (23:59:60) is the same Unix instant as the midnight after it, as POSIX counts.
pub fn unix_ns(
    year: i64,
    month: u32,
    day: u32,
    hour: u32,
    minute: u32,
    second: u32,
    nanos: i64,
) -> Option<u64> {
    if !is_date(year, month, day)
        || !is_time_of_day(hour, minute, second)
        || nanos.abs() > 1_000_000_000
    {
        return None;
    }
    let secs =
        days_from_civil(year, month, day) * 86_400 + (hour * 3600 + minute * 60 + second) as i64;
    let ns = secs.checked_mul(1_000_000_000)?.checked_add(nanos)?;
    u64::try_from(ns).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_dates() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(
            unix_ns(2026, 6, 1, 8, 0, 0, 0),
            Some(1_780_300_800 * 1_000_000_000)
        );
        assert_eq!(
            unix_ns(2022, 10, 20, 8, 24, 35, -5),
            Some(1_666_254_275 * 1_000_000_000 - 5)
        );
    }

    #[test]
    fn impossible_dates_and_times_are_refused_not_moved_to_another_day() {
        assert_eq!(unix_ns(2022, 13, 1, 0, 0, 0, 0), None);
        assert_eq!(unix_ns(2022, 2, 31, 0, 0, 0, 0), None);
        assert_eq!(unix_ns(2023, 2, 29, 0, 0, 0, 0), None);
        assert!(unix_ns(2024, 2, 29, 0, 0, 0, 0).is_some());
        assert_eq!(unix_ns(2022, 10, 0, 0, 0, 0, 0), None);
        assert_eq!(unix_ns(2022, 10, 20, 8, 24, 60, 0), None);
        assert_eq!(unix_ns(2022, 10, 20, 8, 24, 35, 2_000_000_000), None);
        // The leap second at the end of 2016 is the Unix instant of the new year's midnight.
        assert_eq!(
            unix_ns(2016, 12, 31, 23, 59, 60, 0),
            unix_ns(2017, 1, 1, 0, 0, 0, 0)
        );
    }
}
