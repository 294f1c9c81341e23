//! S6: the safe interval. When every check passes, the position is given as
//! `U_safe = [d − ησ − m, d + ησ + m]` along the track: d the estimated chainage, σ its standard
//! deviation, η the inflation factor (3.89 holds a Gaussian error 99.99 % of the time), and
//! m = 1…1.5 σ_map the margin for the map's own survey error (the source calls it β).

use railfuse_catalog::messages::SafeInterval;

pub fn safe_interval(chainage_m: f64, std_m: f64, eta: f64, margin_m: f64) -> SafeInterval {
    let half = eta * std_m + margin_m;
    SafeInterval {
        chainage_m,
        chainage_std_m: std_m,
        low_m: chainage_m - half,
        high_m: chainage_m + half,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_interval_is_eta_sigma_plus_the_margin_each_side() {
        let u = safe_interval(1000.0, 0.5, 3.89, 0.15);
        assert!((u.low_m - (1000.0 - 1.945 - 0.15)).abs() < 1e-12);
        assert!((u.high_m - (1000.0 + 1.945 + 0.15)).abs() < 1e-12);
        assert!(u.contains(1002.0) && !u.contains(1002.1));
    }
}
