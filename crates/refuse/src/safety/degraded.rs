//! Degraded modes (railfuse's, `degraded = true`): where the source's rule gives no position
//! at all (any fault), a position from what is left, when what is left still bounds the
//! error. Each follows a branch of the fault tree (docs/safety.md):
//!
//! | fault | what is left out | why the interval still holds |
//! |---|---|---|
//! | axle 1 faulty (S1: stuck, slipping, out of range), axle 2 healthy | axle 1's speeds and the acceleration input | the filter predicts with the train's whole acceleration range, so its σ, and `U_safe` with it, widens to what the fixes alone support; S3 and S5 (against axle 2) still watch it |
//! | axle 2 faulty, axle 1 healthy | axle 2, and with it S5 (its window starts again when axle 2 is back) | axle 2 never drives the filter; axle 1's error is a state whose σ is in `U_safe` |
//! | a fix beside the track (S4), or off the map (S1 map: beyond its ends, far from every track) while the filter is on it, for at most `max_dropped_fix_s` | the fix: not fused | a dropped fix is as good as none: the filter coasts on the axles as it does in a tunnel, for no longer than the GNSS timeout allows one (60 s), S3c and S5 still watching it; beyond the bound the check fails as in the source (the map or the receiver is wrong) |
//!
//! | S3c: the position σ beyond `max_position_std_m` (dead reckoning in a tunnel) while the safe interval with the ellipse's largest σ has grown beyond S3c's own by at most 5 % of the distance since σ was last within the limit (ETCS's odometry accuracy is ±(5 m + 5 % s)) | nothing: the interval is wider, and says so | the interval is `η σ` wide with an honest σ (S3a, S3b and S5 still watch it); S3c's 2 m is a limit of usefulness, not of integrity, and an interlocking takes a train's odometry interval up to that allowance |
//! | S5 before its first window has ended | nothing: the first window is judged as it grows (a verdict like any window's, not marked degraded) | the comparison over part of a window has the same σ formula, so it is the same check, earlier |
//!
//! Both axles faulty, a diverging filter (S3a, S3b), a σ beyond the allowance, a stale or bad
//! receiver (S1) and a failing S5 give no position, as in the source.

use railfuse_catalog::messages::SafetyCheck;

/// What the degraded modes may use this epoch, beside the checks themselves.
#[derive(Debug, Clone, Default)]
pub struct Cover {
    /// The last fix failed S4 (or S1 map) and was not fused.
    pub fix_dropped: bool,
    /// The safe interval with the position ellipse's largest σ, against ETCS's allowance.
    pub wide_interval: Option<WideInterval>,
    /// S5 while its first window has not ended: the comparison over the window so far.
    pub odometry_so_far: Option<SafetyCheck>,
}

/// A safe interval's half-width against the odometry allowance at its distance from where the
/// position σ was last within S3c's limit (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WideInterval {
    pub half_width_m: f64,
    pub allowance_m: f64,
    pub since_useful_m: f64,
}

/// The epoch's checks with the failures a degraded mode covers passed, each with what it
/// left out.
pub fn degrade(checks: &mut [SafetyCheck], cover: &Cover) {
    let failed =
        |checks: &[SafetyCheck], name: &str| checks.iter().any(|c| c.check == name && !c.passed);
    let (axle_1, axle_2) = (failed(checks, "s1_axle_1"), failed(checks, "s1_axle_2"));
    for c in checks.iter_mut().filter(|c| !c.passed) {
        let left_out = match c.check.as_str() {
            "s1_axle_1" if !axle_2 => "axle 1 left out: its speeds and the acceleration input \
                                       are not used, and the filter predicts with the train's \
                                       whole acceleration range (σ and U_safe widen)"
                .to_owned(),
            "s1_axle_2" | "s5_odometry" if axle_2 && !axle_1 => {
                "axle 2 left out: it drives nothing, and S5 starts its window again when it is \
                 back"
                    .to_owned()
            }
            "s4_map" if cover.fix_dropped => "the fix beside the track was not fused (a \
                                              reflection, or the map off here); the filter \
                                              coasts on the axles without it"
                .to_owned(),
            "s1_map" if cover.fix_dropped => "the fix that does not fit the map (beyond its \
                                              ends, or far from every track) was not fused; the \
                                              filter, on the map, goes on without it"
                .to_owned(),
            "s3c_covariance" => match cover.wide_interval {
                Some(w) if w.half_width_m <= w.allowance_m => format!(
                    "a wide interval: U_safe ±{:.1} m, within ±{:.1} m, S3c's interval and 5 % of \
                     the {:.0} m since σ was last within it (ETCS odometry)",
                    w.half_width_m, w.allowance_m, w.since_useful_m
                ),
                _ => continue,
            },
            // The comparison so far is a verdict like any window's: nothing left out.
            "s5_odometry" => {
                if let Some(so_far) = &cover.odometry_so_far {
                    *c = so_far.clone();
                }
                continue;
            }
            _ => continue,
        };
        c.passed = true;
        c.degraded = Some(left_out);
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

    fn dropped() -> Cover {
        Cover {
            fix_dropped: true,
            ..Cover::default()
        }
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
        degrade(&mut c, &Cover::default());
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
        degrade(&mut c, &Cover::default());
        assert!(still_failing(&c).is_empty() && c[2].degraded.is_some() && c[5].degraded.is_some());
        let mut c = vec![verdict("s5_odometry", Some("off".into()))];
        degrade(&mut c, &dropped());
        assert_eq!(
            still_failing(&c),
            ["s5_odometry"],
            "S5 alone is not covered"
        );
        let mut c = checks(&["s1_axle_1", "s1_axle_2"]);
        degrade(&mut c, &Cover::default());
        assert_eq!(still_failing(&c), ["s1_axle_1", "s1_axle_2"]);
        let mut c = checks(&["s1_gnss", "s3a_variance"]);
        degrade(&mut c, &dropped());
        assert_eq!(still_failing(&c), ["s1_gnss", "s3a_variance"]);
    }

    #[test]
    fn a_fix_beside_the_track_is_covered_only_when_it_was_dropped() {
        let mut c = checks(&["s4_map"]);
        degrade(&mut c, &Cover::default());
        assert_eq!(still_failing(&c), ["s4_map"]);
        degrade(&mut c, &dropped());
        assert!(still_failing(&c).is_empty() && c[4].degraded.is_some());
    }

    #[test]
    fn a_wide_interval_passes_only_within_the_odometry_allowance() {
        let sigma_check = || vec![verdict("s3c_covariance", Some("position σ 2.30 m".into()))];
        let wide = |half_width_m| Cover {
            wide_interval: Some(WideInterval {
                half_width_m,
                allowance_m: 7.9 + 0.05 * 600.0,
                since_useful_m: 600.0,
            }),
            ..Cover::default()
        };
        let mut c = sigma_check();
        degrade(&mut c, &wide(9.1));
        assert!(still_failing(&c).is_empty());
        assert!(c[0].degraded.as_deref().unwrap().contains("U_safe ±9.1 m"));
        let mut c = sigma_check();
        degrade(&mut c, &wide(38.0));
        assert_eq!(still_failing(&c), ["s3c_covariance"]);
        let mut c = sigma_check();
        degrade(&mut c, &Cover::default());
        assert_eq!(
            still_failing(&c),
            ["s3c_covariance"],
            "no fix yet: no allowance"
        );
    }

    #[test]
    fn the_first_odometry_window_is_judged_as_it_grows() {
        let waiting = || vec![verdict("s5_odometry", Some("no window yet".into()))];
        let so_far = |reason: Option<String>| Cover {
            odometry_so_far: Some(verdict("s5_odometry", reason)),
            ..Cover::default()
        };
        let mut c = waiting();
        degrade(&mut c, &so_far(None));
        assert!(still_failing(&c).is_empty() && c[0].degraded.is_none());
        let mut c = waiting();
        degrade(&mut c, &so_far(Some("12 m apart".into())));
        assert_eq!(still_failing(&c), ["s5_odometry"]);
        assert_eq!(
            c[0].reason.as_deref(),
            Some("12 m apart"),
            "the reason is the comparison's"
        );
    }
}
