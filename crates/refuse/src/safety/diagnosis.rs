//! S1: sensor diagnosis. Each sensor is judged on its own messages (a GNSS fix without a
//! usable position, non-finite or absurd coordinates, a jump the train cannot make; an axle
//! sensor out of range, stuck, or slipping against the other axle) and on staleness at every
//! epoch. A fault means no safe output while it lasts, with its reason.

use railfuse_catalog::messages::{Odometer, SafetyCheck};

use super::settings::SafetySettings;

/// The last usable fix: stamp, east, north and horizontal variance per axis.
#[derive(Debug, Clone, Copy)]
struct LastFix {
    stamp_ns: u64,
    east_m: f64,
    north_m: f64,
    variance_m2: f64,
}

/// One axle sensor's recent history.
#[derive(Debug, Clone, Default)]
pub struct AxleState {
    last_stamp_ns: Option<u64>,
    last_pulses: Option<u64>,
    unchanged: u32,
    pub speed_mps: Option<f64>,
    /// A fault of its latest sample (range, stuck, slip), until a sample clears it.
    fault: Option<String>,
}

/// What S1 knows of the sensors.
#[derive(Debug, Clone, Default)]
pub struct Diagnosis {
    last_fix: Option<LastFix>,
    /// A fault of the latest fix (non-finite, jump), until the next usable fix.
    gnss_fault: Option<String>,
    pub axles: [AxleState; 2],
    map_fault: Option<String>,
    first_fix_ns: Option<u64>,
    /// Why the latest fix without a usable position was refused, until a usable one comes.
    last_refusal: Option<String>,
}

/// How a fix was judged.
#[derive(Debug, Clone, PartialEq)]
pub enum FixVerdict {
    /// Usable at (east, north) with this variance per axis.
    Usable,
    /// No position of the required fix type: refused, not a fault (staleness decides).
    NoPosition(String),
    /// The receiver gave something impossible: refused, and a fault.
    Fault(String),
}

impl Diagnosis {
    /// Judges a fix whose position in the plane is `enu` (None when it has none) with
    /// variance `variance_m2` per axis.
    pub fn fix(
        &mut self,
        fix: &railfuse_catalog::messages::GnssFix,
        enu: Option<(f64, f64)>,
        variance_m2: Option<f64>,
        s: &SafetySettings,
    ) -> FixVerdict {
        if fix.fix_type < s.min_fix_type || !fix.fix_type.has_position() {
            let why = format!(
                "fix type {}, below {}",
                fix.fix_type.name(),
                s.min_fix_type.name()
            );
            self.last_refusal = Some(why.clone());
            return FixVerdict::NoPosition(why);
        }
        let (Some((e, n)), Some(var)) = (enu, variance_m2) else {
            return self.gnss_fails("a fix of its type without a position or its variance".into());
        };
        if !(e.is_finite() && n.is_finite() && var.is_finite() && var > 0.0) {
            return self.gnss_fails(format!(
                "a fix with non-finite or absurd values (east {e}, north {n}, variance {var})"
            ));
        }
        if let Some(last) = self.last_fix {
            let dt = railfuse_catalog::seconds_between(last.stamp_ns, fix.stamp_ns).max(0.0);
            let moved = (e - last.east_m).hypot(n - last.north_m);
            let allowed = s.max_speed_mps * dt + 5.0 * (2.0 * (var + last.variance_m2)).sqrt();
            if moved > allowed {
                return self.gnss_fails(format!(
                    "the fix jumped {moved:.1} m in {dt:.2} s, more than the {allowed:.1} m the \
                     train can move"
                ));
            }
        }
        self.first_fix_ns.get_or_insert(fix.stamp_ns);
        self.last_fix = Some(LastFix {
            stamp_ns: fix.stamp_ns,
            east_m: e,
            north_m: n,
            variance_m2: var,
        });
        self.gnss_fault = None;
        self.last_refusal = None;
        FixVerdict::Usable
    }

    fn gnss_fails(&mut self, reason: String) -> FixVerdict {
        self.gnss_fault = Some(reason.clone());
        FixVerdict::Fault(reason)
    }

    /// Judges a sample of axle `k` (0 or 1) with speed variance `variance`; `filter_speed`
    /// is the filter's along-track speed, to tell which axle slips when they disagree.
    pub fn axle(
        &mut self,
        k: usize,
        m: &Odometer,
        variances: [f64; 2],
        filter_speed: Option<f64>,
        s: &SafetySettings,
    ) {
        let other_speed = self.axles[1 - k].speed_mps;
        let a = &mut self.axles[k];
        a.last_stamp_ns = Some(m.stamp_ns);
        // A stuck pulse generator shows in its count; one that reports only speed cannot.
        a.unchanged = match (a.last_pulses, m.pulse_count) {
            (Some(p), Some(now)) if p == now => a.unchanged + 1,
            _ => 0,
        };
        a.last_pulses = m.pulse_count;
        a.fault = None;
        if !m.speed_mps.is_finite() || m.speed_mps < -0.5 || m.speed_mps > s.max_speed_mps {
            a.fault = Some(format!("speed {} m/s out of range", m.speed_mps));
            a.speed_mps = None;
            return;
        }
        a.speed_mps = Some(m.speed_mps);
        let moving = other_speed.is_some_and(|v| v > 1.0);
        if a.unchanged >= s.stuck_samples && moving {
            a.fault = Some(format!(
                "stuck: pulse count {} unchanged for {} samples while the other axle moves",
                m.pulse_count.unwrap_or_default(),
                a.unchanged
            ));
            return;
        }
        // Slip (traction) or slide (braking): the axles disagree beyond their noise and wear;
        // the one further from the filter is the one that slips.
        let (Some(v0), Some(v1)) = (self.axles[0].speed_mps, self.axles[1].speed_mps) else {
            return;
        };
        let tolerance = s.slip_sigmas * (variances[0] + variances[1]).sqrt()
            + s.slip_fraction * v0.abs().max(v1.abs());
        if (v0 - v1).abs() > tolerance {
            let worse = match filter_speed {
                Some(f) if (v1 - f).abs() > (v0 - f).abs() => 1,
                Some(_) => 0,
                None => k,
            };
            // A driven wheel that slips turns faster than the train; a braked one that slides,
            // slower.
            let (vw, vo) = if worse == 0 { (v0, v1) } else { (v1, v0) };
            let word = if vw > filter_speed.unwrap_or(vo) {
                "slip"
            } else {
                "slide"
            };
            self.axles[worse].fault = Some(format!(
                "{word}: axles read {v0:.2} and {v1:.2} m/s, {:.2} m/s apart (tolerance {tolerance:.2})",
                (v0 - v1).abs()
            ));
        }
    }

    /// Axle `k` has no sensor in the pipeline: it fails S1 for the whole run, and says so.
    pub fn absent_axle(&mut self, k: usize, role: &str) {
        self.axles[k].fault = Some(format!("no axle sensor configured (safety.{role})"));
    }

    /// The map matching of a fix failed or put it too far from every track; `None` clears.
    pub fn map(&mut self, fault: Option<String>) {
        self.map_fault = fault;
    }

    /// S1's checks at time `t_ns`: the latched faults and staleness.
    pub fn checks(&self, t_ns: u64, s: &SafetySettings) -> [SafetyCheck; 4] {
        let stale = |last: Option<u64>, timeout_s: f64, what: &str| {
            let age = last.map(|l| railfuse_catalog::seconds_between(l, t_ns));
            match age {
                Some(a) if a > timeout_s => Some(format!(
                    "no usable {what} for {a:.1} s (limit {timeout_s} s)"
                )),
                None => Some(format!("no usable {what} yet")),
                _ => None,
            }
        };
        let gnss = self.gnss_fault.clone().or_else(|| {
            let why = stale(self.last_fix.map(|f| f.stamp_ns), s.gnss_timeout_s, "fix")?;
            Some(match &self.last_refusal {
                Some(r) => format!("{why} (the latest: {r})"),
                None => why,
            })
        });
        let axle = |k: usize| {
            let a = &self.axles[k];
            a.fault
                .clone()
                .or_else(|| stale(a.last_stamp_ns, s.axle_timeout_s, "sample"))
        };
        // The accuracy the receiver reported for the fix S1 last accepted, to read beside it.
        let gnss = SafetyCheck {
            value: self.last_fix.map(|f| f.variance_m2.sqrt()),
            ..verdict("s1_gnss", gnss)
        };
        [
            gnss,
            verdict("s1_axle_1", axle(0)),
            verdict("s1_axle_2", axle(1)),
            verdict("s1_map", self.map_fault.clone()),
        ]
    }
}

/// A check that passed (no reason) or failed (with it).
pub fn verdict(check: &str, failure: Option<String>) -> SafetyCheck {
    SafetyCheck {
        check: check.to_owned(),
        passed: failure.is_none(),
        value: None,
        limit: None,
        reason: failure,
        degraded: None,
    }
}

/// A check comparing `value` with `limit` (passes when `value ≤ limit`).
pub fn compared(check: &str, value: f64, limit: f64, what: impl FnOnce() -> String) -> SafetyCheck {
    let passed = value <= limit; // a NaN fails
    SafetyCheck {
        check: check.to_owned(),
        passed,
        value: value.is_finite().then_some(value),
        limit: Some(limit),
        reason: (!passed).then(what),
        degraded: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::messages::{FixType, GnssFix};

    fn fix(stamp_ns: u64, fix_type: FixType) -> GnssFix {
        GnssFix {
            stamp_ns,
            fix_type,
            satellites: 12,
            hdop: Some(0.8),
            latitude_deg: Some(44.6),
            longitude_deg: Some(10.9),
            altitude_m: Some(40.0),
            altitude_msl_m: None,
            position_covariance_enu_m2: None,
            speed_mps: None,
            course_rad: None,
        }
    }

    fn odo(stamp_ns: u64, pulses: u64, speed: f64) -> Odometer {
        Odometer {
            stamp_ns,
            sensor_id: "a".into(),
            pulse_count: Some(pulses),
            pulses_per_revolution: Some(100),
            wheel_diameter_m: Some(0.9),
            distance_increment_m: Some(0.1),
            speed_mps: speed,
        }
    }

    #[test]
    fn fixes_without_position_are_refused_and_jumps_are_faults() {
        let s = SafetySettings::default();
        let mut d = Diagnosis::default();
        assert!(matches!(
            d.fix(&fix(0, FixType::None), None, None, &s),
            FixVerdict::NoPosition(_)
        ));
        assert_eq!(
            d.fix(&fix(0, FixType::RtkFixed), Some((0.0, 0.0)), Some(0.01), &s),
            FixVerdict::Usable
        );
        // 0.1 s later, 50 m away: at most 10 m at 100 m/s.
        let v = d.fix(
            &fix(100_000_000, FixType::RtkFixed),
            Some((50.0, 0.0)),
            Some(0.01),
            &s,
        );
        assert!(
            matches!(&v, FixVerdict::Fault(r) if r.contains("jumped 50.0 m")),
            "{v:?}"
        );
        assert!(!d.checks(100_000_000, &s)[0].passed);
        let nan = d.fix(
            &fix(200_000_000, FixType::Single),
            Some((f64::NAN, 0.0)),
            Some(1.0),
            &s,
        );
        assert!(matches!(nan, FixVerdict::Fault(_)));
        // A usable fix clears the fault; 61 s without one is stale.
        assert_eq!(
            d.fix(
                &fix(300_000_000, FixType::Single),
                Some((1.0, 0.0)),
                Some(1.0),
                &s
            ),
            FixVerdict::Usable
        );
        assert!(d.checks(300_000_000, &s)[0].passed);
        let late = &d.checks(61_400_000_000, &s)[0];
        let why = late.reason.clone().unwrap_or_default();
        assert!(
            !late.passed && why.contains("no usable fix for 61.1 s"),
            "{why}"
        );
    }

    #[test]
    fn a_stuck_axle_and_a_slipping_axle_are_named() {
        let s = SafetySettings::default();
        let mut d = Diagnosis::default();
        let var = [0.01, 0.01];
        for k in 0..12u64 {
            let t = k * 40_000_000;
            d.axle(1, &odo(t, 1000 + 8 * k, 20.0), var, Some(20.0), &s);
            d.axle(0, &odo(t, 500, 0.0), var, Some(20.0), &s);
        }
        let c = d.checks(12 * 40_000_000, &s);
        let reason = c[1].reason.clone().unwrap_or_default();
        assert!(!c[1].passed && reason.contains("stuck"), "{c:?}");
        assert!(c[2].passed, "{c:?}");

        let mut d = Diagnosis::default();
        d.axle(1, &odo(0, 0, 20.0), var, Some(20.0), &s);
        d.axle(0, &odo(0, 0, 23.0), var, Some(20.0), &s); // 3 m/s above the train: slip
        let c = d.checks(0, &s);
        assert!(
            !c[1].passed && c[1].reason.as_ref().unwrap().starts_with("slip"),
            "{c:?}"
        );
        assert!(c[2].passed);
    }
}
