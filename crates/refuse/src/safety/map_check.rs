//! S4: the map check. A train is on its track: a fix's lateral deviation from the matched
//! centre line must be below `λ σ`. σ is the standard deviation that deviation has when all
//! is well: the filter's position uncertainty across the track, the fix's own, and the map's
//! survey error, `σ² = n̂ᵀ (P + R) n̂ + σ_map²` with `n̂` the track's normal. The source
//! writes σ_kalman; the fix's own noise is added because the deviation tested is the fix's,
//! and without it every single-point fix would fail against an RTK-tight filter.

use std::collections::VecDeque;

use nalgebra::Matrix2;
use railfuse_catalog::messages::SafetyCheck;

use super::diagnosis::compared;
use super::settings::BiasSettings;

/// The check for a fix `lateral_m` beside the track at heading `heading_rad`, with filter
/// position covariance `p`, fix covariance `r` and map survey σ `map_std_m`.
pub fn map_check(
    lateral_m: f64,
    heading_rad: f64,
    p: &Matrix2<f64>,
    r: &Matrix2<f64>,
    map_std_m: f64,
    lambda: f64,
) -> SafetyCheck {
    let sigma = lateral_std(heading_rad, p, r, map_std_m);
    let limit = lambda * sigma;
    compared("s4_map", lateral_m.abs(), limit, || {
        format!(
            "fix {:.2} m beside the track, limit {limit:.2} m (λ {lambda} × σ {sigma:.2} m)",
            lateral_m.abs()
        )
    })
}

/// σ of a fix's lateral deviation: `√(n̂ᵀ (P + R) n̂ + σ_map²)`.
pub fn lateral_std(heading_rad: f64, p: &Matrix2<f64>, r: &Matrix2<f64>, map_std_m: f64) -> f64 {
    (across(heading_rad, &(p + r)) + map_std_m * map_std_m).sqrt()
}

/// S4's step test (railfuse's, `map_step_window_s`). A map that is off over a stretch (a
/// survey blunder, the wrong track's geometry) moves every fix's lateral deviation where the
/// train enters it, faster than the receiver's bias can move, and by less than S4's λσ when
/// σ holds the bias's whole spread. So the deviation now is compared with the deviation a
/// window earlier: when all is well their difference has the variance
///
/// ```text
/// 2 σ_b² (1 − e^(−Δt/τ))     the receiver's bias (first-order Gauss–Markov, σ_b and τ of
///                             `gnss_bias`) decorrelating over Δt
/// + r_now + r_then            both fixes' noise across the track
/// + 2 σ_map²                  the survey error at both places (their correlation only
///                             shrinks it)
/// ```
///
/// and must stay within λ of its σ.
#[derive(Debug, Clone, Default)]
pub struct MapStepTest {
    /// (stamp, matched track, lateral deviation, its variance from the fix) of recent fixes,
    /// oldest first.
    history: VecDeque<(u64, usize, f64, f64)>,
}

impl MapStepTest {
    /// The test of a fix `lateral_m` beside track `track` (variance `lateral_var_m2` across
    /// it) against the last fix given at least `window_s` before it; None until there is one,
    /// or when that one matched another track (a station's parallel track). Give it only the
    /// fixes that passed S4: the references must fit the map.
    #[allow(clippy::too_many_arguments)]
    pub fn check(
        &mut self,
        t_ns: u64,
        track: usize,
        lateral_m: f64,
        lateral_var_m2: f64,
        window_s: f64,
        bias: Option<BiasSettings>,
        map_std_m: f64,
        lambda: f64,
    ) -> Option<SafetyCheck> {
        let window_ns = (window_s * 1e9) as u64;
        // Keep the newest fix at least a window old, and everything after it.
        while self
            .history
            .get(1)
            .is_some_and(|&(t, ..)| t.saturating_add(window_ns) <= t_ns)
        {
            self.history.pop_front();
        }
        let then = self
            .history
            .front()
            .copied()
            .filter(|&(t, on, ..)| t.saturating_add(window_ns) <= t_ns && on == track);
        self.history
            .push_back((t_ns, track, lateral_m, lateral_var_m2));
        let (t0, _, lateral_then, var_then) = then?;
        let dt = railfuse_catalog::seconds_between(t0, t_ns);
        let bias_var = bias.map_or(0.0, |b| {
            2.0 * b.std * b.std * (1.0 - (-dt / b.time_constant_s).exp())
        });
        let sigma = (bias_var + lateral_var_m2 + var_then + 2.0 * map_std_m * map_std_m).sqrt();
        let limit = lambda * sigma;
        let moved = lateral_m - lateral_then;
        Some(compared("s4_map", moved.abs(), limit, || {
            format!(
                "the fix's deviation from the track moved {moved:+.2} m in {dt:.1} s, limit \
                 {limit:.2} m (λ {lambda} × σ {sigma:.2} m of its change): the map is off here, \
                 or the fix"
            )
        }))
    }
}

/// A covariance `r`'s variance across a track at heading `heading_rad`.
pub fn across(heading_rad: f64, r: &Matrix2<f64>) -> f64 {
    // The right-hand normal of heading h (clockwise from north) is (cos h, −sin h).
    let n = nalgebra::Vector2::new(heading_rad.cos(), -heading_rad.sin());
    (n.transpose() * r * n)[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_a_straight_line_the_limit_is_lambda_times_the_cross_track_sigma() {
        // Track due north: across it is east. σ_e² = 0.09 (filter) + 0.16 (fix) = 0.25, no map
        // error: σ = 0.5 m, limit 4 × 0.5 = 2 m.
        let p = Matrix2::new(0.09, 0.0, 0.0, 100.0);
        let r = Matrix2::new(0.16, 0.0, 0.0, 100.0);
        assert!(map_check(1.99, 0.0, &p, &r, 0.0, 4.0).passed);
        let c = map_check(-2.01, 0.0, &p, &r, 0.0, 4.0);
        assert!(!c.passed && c.limit == Some(2.0), "{c:?}");
        // The along-track variance (north, 100 m²) does not enter.
        assert!((lateral_std(0.0, &p, &r, 0.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn on_a_curve_the_normal_turns_with_the_heading() {
        // Heading 30°: n̂ = (cos 30°, −sin 30°); P + R = diag(1, 4), σ_map 0.3:
        // σ² = 0.75·1 + 0.25·4 + 0.09 = 1.84.
        let h = 30f64.to_radians();
        let p = Matrix2::new(0.5, 0.0, 0.0, 2.0);
        let sigma = lateral_std(h, &p, &p, 0.3);
        assert!((sigma - 1.84f64.sqrt()).abs() < 1e-12, "{sigma}");
        assert!(map_check(4.2 * sigma - 1e-9, h, &p, &p, 0.3, 4.2).passed);
        assert!(!map_check(4.2 * sigma + 1e-9, h, &p, &p, 0.3, 4.2).passed);
    }

    #[test]
    fn the_step_test_passes_a_drifting_bias_and_catches_a_map_that_steps() {
        let bias = Some(BiasSettings {
            std: 1.5,
            time_constant_s: 60.0,
        });
        // RTK fixes at 10 Hz, 2 cm across the track, map σ 0.1 m; window 5 s:
        // σ² = 2 · 2.25 · (1 − e^(−5/60)) + 2 · 0.0004 + 0.02 = 0.381, limit 4σ = 2.47 m.
        let run = |deviation: &dyn Fn(f64) -> f64| {
            let mut test = MapStepTest::default();
            (0..300u64)
                .filter_map(|k| {
                    let t = k as f64 / 10.0;
                    test.check(
                        k * 100_000_000,
                        0,
                        deviation(t),
                        0.0004,
                        5.0,
                        bias,
                        0.1,
                        4.0,
                    )
                })
                .collect::<Vec<_>>()
        };
        let drift = run(&|t| 0.1 * t); // 0.5 m in a window: a bias, not the map
        assert_eq!(
            drift.len(),
            300 - 50,
            "judged from the first fix a window old"
        );
        assert!(drift.iter().all(|c| c.passed));
        let expected = 4.0 * (4.5 * (1.0 - (-5.0f64 / 60.0).exp()) + 0.0008 + 0.02).sqrt();
        assert!((drift[0].limit.unwrap() - expected).abs() < 1e-9);
        // A 3 m offset entering over 3.7 s at 20 s, as a surveyed map's vertices bring it in.
        let step = run(&|t| 3.0 * ((t - 20.0) / 3.7).clamp(0.0, 1.0));
        let failed: Vec<&SafetyCheck> = step.iter().filter(|c| !c.passed).collect();
        assert!(!failed.is_empty());
        assert!(failed[0].reason.as_deref().unwrap().contains("moved +2."));
        // A window after the step has passed, the deviation is steady again and passes.
        assert!(step.last().unwrap().passed);
        // Without the bias model the same drift is far beyond the fixes' noise.
        let mut test = MapStepTest::default();
        test.check(0, 0, 0.0, 0.0004, 5.0, None, 0.1, 4.0);
        let c = test.check(5_000_000_000, 0, 1.0, 0.0004, 5.0, None, 0.1, 4.0);
        assert!(!c.unwrap().passed);
        // Deviations from two different tracks are not compared.
        assert!(test
            .check(10_000_000_000, 1, 5.5, 0.0004, 5.0, None, 0.1, 4.0)
            .is_none());
    }
}
