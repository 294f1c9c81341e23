//! S4: the map check. A train is on its track: a fix's lateral deviation from the matched
//! centre line must be below `λ σ`. σ is the standard deviation that deviation has when all
//! is well: the filter's position uncertainty across the track, the fix's own, and the map's
//! survey error, `σ² = n̂ᵀ (P + R) n̂ + σ_map²` with `n̂` the track's normal. The source
//! writes σ_kalman; the fix's own noise is added because the deviation tested is the fix's,
//! and without it every single-point fix would fail against an RTK-tight filter.

use nalgebra::Matrix2;
use railfuse_catalog::messages::SafetyCheck;

use super::diagnosis::compared;

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
    // The right-hand normal of heading h (clockwise from north) is (cos h, −sin h).
    let n = nalgebra::Vector2::new(heading_rad.cos(), -heading_rad.sin());
    ((n.transpose() * (p + r) * n)[0] + map_std_m * map_std_m).sqrt()
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
}
