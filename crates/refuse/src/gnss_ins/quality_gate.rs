//! The GNSS state monitor (source 003, section 2): each fix is judged on what the receiver
//! reports about it (fix type, satellites in view, HDOP) before anything of it is fused.
//!
//! The source's rule is by satellite count: fewer than 4 and the solution "is not fit to be a
//! fusion source"; an RTK solution is the absolute reference, taken as it is; a single-point
//! solution is pre-filtered first. A receiver reports its fix type directly, so the gate reads
//! it instead of guessing it from the count, and keeps the count and HDOP as thresholds.

use railfuse_catalog::messages::{FixType, GnssFix};
use serde::{Deserialize, Serialize};

/// The gate's thresholds (`[pipeline.gnss_ins.gate]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GateSettings {
    /// Fewer satellites than this: not fused (the source: 4, the least a position needs).
    pub min_satellites: u8,
    /// A larger HDOP: not fused. 5 is where a single-point fix's geometry alone makes its
    /// error several times its range noise.
    pub max_hdop: f64,
    /// The weakest fix type fused at all.
    pub min_fix_type: FixType,
    /// The weakest fix type taken as the reference, unfiltered (the source: RTK).
    pub reference_fix_type: FixType,
}

impl Default for GateSettings {
    fn default() -> Self {
        Self {
            min_satellites: 4,
            max_hdop: 5.0,
            min_fix_type: FixType::Single,
            reference_fix_type: FixType::RtkFixed,
        }
    }
}

impl GateSettings {
    pub fn check(&self) -> Result<(), String> {
        if self.min_fix_type == FixType::None {
            return Err("gate.min_fix_type \"none\" gives no position".into());
        }
        if self.reference_fix_type < self.min_fix_type {
            return Err(format!(
                "gate.reference_fix_type {} is below gate.min_fix_type {}",
                self.reference_fix_type.name(),
                self.min_fix_type.name()
            ));
        }
        if !(self.max_hdop > 0.0) {
            return Err(format!(
                "gate.max_hdop = {}: must be positive",
                self.max_hdop
            ));
        }
        Ok(())
    }
}

/// How many fixes the gate took as the reference, sent through the pre-filter, or refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct GateTally {
    pub reference: u64,
    pub pre_filtered: u64,
    pub refused: u64,
}

impl GateTally {
    pub fn count(&mut self, v: &GateVerdict) {
        match v {
            GateVerdict::Reference => self.reference += 1,
            GateVerdict::PreFiltered => self.pre_filtered += 1,
            GateVerdict::Refused(_) => self.refused += 1,
        }
    }
}

/// What the gate made of a fix.
#[derive(Debug, Clone, PartialEq)]
pub enum GateVerdict {
    /// Fused as it is: the absolute reference (RTK fixed by default).
    Reference,
    /// Fused after the pre-filter (single point, DGPS, RTK float by default).
    PreFiltered,
    /// Not fused, and why.
    Refused(String),
}

impl GateVerdict {
    /// The verdict's name, as counted in the summary.
    pub fn name(&self) -> &'static str {
        match self {
            GateVerdict::Reference => "reference",
            GateVerdict::PreFiltered => "pre_filtered",
            GateVerdict::Refused(_) => "refused",
        }
    }
}

/// Judges one fix. Coordinates are checked where they are converted (they need the origin).
pub fn judge(fix: &GnssFix, s: &GateSettings) -> GateVerdict {
    if !fix.fix_type.has_position() || fix.fix_type < s.min_fix_type {
        return GateVerdict::Refused(format!(
            "fix type {}, below {}",
            fix.fix_type.name(),
            s.min_fix_type.name()
        ));
    }
    if fix.satellites < s.min_satellites {
        return GateVerdict::Refused(format!(
            "{} satellites, fewer than {}",
            fix.satellites, s.min_satellites
        ));
    }
    match fix.hdop {
        Some(h) if !(h <= s.max_hdop) => {
            return GateVerdict::Refused(format!("HDOP {h:.1}, above {}", s.max_hdop));
        }
        _ => {}
    }
    match fix.fix_type >= s.reference_fix_type {
        true => GateVerdict::Reference,
        false => GateVerdict::PreFiltered,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(fix_type: FixType, satellites: u8, hdop: Option<f64>) -> GnssFix {
        GnssFix {
            stamp_ns: 0,
            fix_type,
            satellites,
            hdop,
            latitude_deg: Some(46.0),
            longitude_deg: Some(7.0),
            altitude_m: Some(500.0),
            altitude_msl_m: None,
            position_covariance_enu_m2: None,
            speed_mps: None,
            course_rad: None,
        }
    }

    #[test]
    fn decisions_on_constructed_fixes() {
        let s = GateSettings::default();
        let cases = [
            (fix(FixType::RtkFixed, 12, Some(0.8)), "reference"),
            (fix(FixType::RtkFloat, 12, Some(0.8)), "pre_filtered"),
            (fix(FixType::Single, 9, Some(1.2)), "pre_filtered"),
            (fix(FixType::Single, 4, None), "pre_filtered"),
            (fix(FixType::Single, 3, Some(1.2)), "refused"),
            (fix(FixType::RtkFixed, 3, Some(1.2)), "refused"),
            (fix(FixType::Single, 9, Some(7.5)), "refused"),
            (fix(FixType::Single, 9, Some(f64::NAN)), "refused"),
            (fix(FixType::None, 0, None), "refused"),
        ];
        for (f, want) in cases {
            let v = judge(&f, &s);
            assert_eq!(v.name(), want, "{f:?}: {v:?}");
        }
        let GateVerdict::Refused(why) = judge(&fix(FixType::Single, 3, None), &s) else {
            panic!()
        };
        assert_eq!(why, "3 satellites, fewer than 4");
        let GateVerdict::Refused(why) = judge(&fix(FixType::None, 0, None), &s) else {
            panic!()
        };
        assert_eq!(why, "fix type none, below single");
        let strict = GateSettings {
            min_fix_type: FixType::RtkFloat,
            ..s
        };
        assert_eq!(
            judge(&fix(FixType::Single, 12, None), &strict).name(),
            "refused"
        );
        assert!(GateSettings {
            reference_fix_type: FixType::Single,
            min_fix_type: FixType::RtkFloat,
            ..s
        }
        .check()
        .is_err());
    }
}
