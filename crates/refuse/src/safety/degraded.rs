//! Degraded modes (railfuse's, `degraded = true`): where the source's rule gives no position
//! at all (any fault), a position from what is left, when what is left still bounds the
//! error. Each follows a branch of the fault tree (docs/safety.md):
//!
//! | fault | what is left out | why the interval still holds |
//! |---|---|---|
//! | axle 1 faulty (S1: stuck, slipping, out of range), axle 2 healthy | axle 1's speeds and the acceleration input | the filter predicts with the train's whole acceleration range, so its σ, and `U_safe` with it, widens to what the fixes alone support; S3 and S5 (against axle 2) still watch it |
//! | axle 2 faulty, axle 1 healthy | axle 2, and with it S5 (its window starts again when axle 2 is back) | axle 2 never drives the filter; axle 1's error is a state whose σ is in `U_safe` |
//! | a fix beside the track (S4), or off the map (S1 map: beyond its ends, far from every track) while the filter is on it, for at most `max_dropped_fix_s` | the fix: not fused | the filter goes on from the fixes and axles before it; a reflection near a station lasts seconds, and beyond the bound the check fails as in the source (the map or the receiver is wrong) |
//!
//! Both axles faulty, a diverging filter (S3: its σ beyond the useful, its innovations
//! inconsistent), a stale or bad receiver (S1) and a failing S5 give no position, as in the
//! source.

use railfuse_catalog::messages::SafetyCheck;

/// The epoch's checks with the failures a degraded mode covers passed, each with what it
/// left out. `fix_dropped`: the last fix failed S4 and was not fused.
pub fn degrade(checks: &mut [SafetyCheck], fix_dropped: bool) {
    let failed =
        |checks: &[SafetyCheck], name: &str| checks.iter().any(|c| c.check == name && !c.passed);
    let (axle_1, axle_2) = (failed(checks, "s1_axle_1"), failed(checks, "s1_axle_2"));
    for c in checks.iter_mut().filter(|c| !c.passed) {
        let left_out = match c.check.as_str() {
            "s1_axle_1" if !axle_2 => {
                "axle 1 left out: its speeds and the acceleration input are not used, and the \
                 filter predicts with the train's whole acceleration range (σ and U_safe widen)"
            }
            "s1_axle_2" | "s5_odometry" if axle_2 && !axle_1 => {
                "axle 2 left out: it drives nothing, and S5 starts its window again when it is \
                 back"
            }
            "s4_map" if fix_dropped => {
                "the fix beside the track was not fused (a reflection near buildings); the \
                 filter goes on without it"
            }
            "s1_map" if fix_dropped => {
                "the fix that does not fit the map (beyond its ends, or far from every track) \
                 was not fused; the filter, on the map, goes on without it"
            }
            _ => continue,
        };
        c.passed = true;
        c.degraded = Some(left_out.into());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::diagnosis::verdict;

    fn checks(failing: &[&str]) -> Vec<SafetyCheck> {
        [
            "s1_gnss",
            "s1_axle_1",
            "s1_axle_2",
            "s3a_variance",
            "s4_map",
        ]
        .iter()
        .map(|c| verdict(c, failing.contains(c).then(|| "broken".to_owned())))
        .collect()
    }

    fn still_failing(c: &[SafetyCheck]) -> Vec<&str> {
        c.iter()
            .filter(|c| !c.passed)
            .map(|c| c.check.as_str())
            .collect()
    }

    #[test]
    fn one_faulty_axle_is_left_out_but_not_both_and_nothing_else_is_covered() {
        let mut c = checks(&["s1_axle_1"]);
        degrade(&mut c, false);
        assert!(still_failing(&c).is_empty());
        assert!(c[1]
            .degraded
            .as_deref()
            .unwrap()
            .starts_with("axle 1 left out"));
        assert_eq!(
            c[1].reason.as_deref(),
            Some("broken"),
            "why it failed stays"
        );
        let mut c = checks(&["s1_axle_2"]);
        c.push(verdict(
            "s5_odometry",
            Some("its window held axle 2's fault".into()),
        ));
        degrade(&mut c, false);
        assert!(still_failing(&c).is_empty() && c[2].degraded.is_some() && c[5].degraded.is_some());
        let mut c = vec![verdict("s5_odometry", Some("off".into()))];
        degrade(&mut c, true);
        assert_eq!(
            still_failing(&c),
            ["s5_odometry"],
            "S5 alone is not covered"
        );
        let mut c = checks(&["s1_axle_1", "s1_axle_2"]);
        degrade(&mut c, false);
        assert_eq!(still_failing(&c), ["s1_axle_1", "s1_axle_2"]);
        let mut c = checks(&["s1_gnss", "s3a_variance"]);
        degrade(&mut c, true);
        assert_eq!(still_failing(&c), ["s1_gnss", "s3a_variance"]);
    }

    #[test]
    fn a_fix_beside_the_track_is_covered_only_when_it_was_dropped() {
        let mut c = checks(&["s4_map"]);
        degrade(&mut c, false);
        assert_eq!(still_failing(&c), ["s4_map"]);
        degrade(&mut c, true);
        assert!(still_failing(&c).is_empty() && c[4].degraded.is_some());
    }
}
