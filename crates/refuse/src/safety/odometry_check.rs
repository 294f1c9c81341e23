//! S5: the odometry check. Over windows of ΔT, the distance the filter travelled along the
//! track is compared with axle sensor 2's, which the filter never saw: they must agree within
//! `k σ`, σ the standard deviation of their difference,
//!
//! ```text
//! σ² = σ²(s_start) + σ²(s_end)       the filter's chainage at both ends (an upper bound:
//!                                     their correlation only shrinks it)
//!    + (ε D)² + (2 q)²                axle 2: its relative scale error ε over distance D,
//!                                     and a pulse quantum q at either end
//! ```
//!
//! The result holds until the next window ends.

use railfuse_catalog::messages::{Odometer, SafetyCheck};

use super::diagnosis::compared;

#[derive(Debug, Clone, Default)]
pub struct OdometryCheck {
    /// Start of the current window: stamp, filter chainage and its variance.
    start: Option<(u64, f64, f64)>,
    /// Axle 2's distance since then, and its pulse quantum.
    distance_m: f64,
    quantum_m: f64,
    last: Option<SafetyCheck>,
}

impl OdometryCheck {
    /// A sample of axle 2.
    pub fn axle_2(&mut self, m: &Odometer) {
        // An odometer that reports only its speed gives no distance to check against.
        if let (Some(_), Some(d)) = (self.start, m.distance_increment_m.filter(|d| d.is_finite())) {
            self.distance_m += d;
        }
        if let (Some(ppr @ 1..), Some(diameter)) = (m.pulses_per_revolution, m.wheel_diameter_m) {
            if diameter.is_finite() {
                self.quantum_m = std::f64::consts::PI * diameter / ppr as f64;
            }
        }
    }

    /// The filter's chainage (and its variance) at `t_ns`; ends the window when it is due.
    /// `window_s` is ΔT, `sigmas` k and `scale_std` ε.
    pub fn epoch(
        &mut self,
        t_ns: u64,
        chainage_m: f64,
        variance_m2: f64,
        window_s: f64,
        sigmas: f64,
        scale_std: f64,
    ) -> Option<&SafetyCheck> {
        let Some((t0, _, _)) = self.start else {
            self.start = Some((t_ns, chainage_m, variance_m2));
            return None;
        };
        if railfuse_catalog::seconds_between(t0, t_ns) >= window_s {
            self.last = self.judge(t_ns, chainage_m, variance_m2, sigmas, scale_std);
            self.start = Some((t_ns, chainage_m, variance_m2));
            self.distance_m = 0.0;
        }
        self.last.as_ref()
    }

    /// The comparison over the window so far, ending at `t_ns` (None before it has started).
    /// Before the first window ends, the degraded mode judges it as it grows.
    pub fn judge(
        &self,
        t_ns: u64,
        chainage_m: f64,
        variance_m2: f64,
        sigmas: f64,
        scale_std: f64,
    ) -> Option<SafetyCheck> {
        let (t0, s0, var0) = self.start?;
        let filter = chainage_m - s0;
        let axle = self.distance_m;
        let sigma =
            (var0 + variance_m2 + (scale_std * axle).powi(2) + (2.0 * self.quantum_m).powi(2))
                .sqrt();
        let limit = sigmas * sigma;
        let diff = (filter - axle).abs();
        Some(compared("s5_odometry", diff, limit, || {
            format!(
                "over {:.1} s the filter moved {filter:.2} m and axle 2 {axle:.2} m: {diff:.2} m \
                 apart, limit {limit:.2} m",
                railfuse_catalog::seconds_between(t0, t_ns)
            )
        }))
    }

    /// The check of the last window ended, if one has.
    /// Axle 2 left out (degraded): the window starts again with its next sample; the last
    /// verdict stands until then.
    pub fn restart(&mut self) {
        self.start = None;
        self.distance_m = 0.0;
    }

    pub fn last(&self) -> Option<&SafetyCheck> {
        self.last.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn odo(increment: f64) -> Odometer {
        Odometer {
            stamp_ns: 0,
            sensor_id: "2".into(),
            pulse_count: Some(0),
            pulses_per_revolution: Some(100),
            wheel_diameter_m: Some(0.9),
            distance_increment_m: Some(increment),
            speed_mps: 0.0,
        }
    }

    #[test]
    fn distances_that_agree_pass_and_a_slipping_filter_fails() {
        let s = 1_000_000_000u64;
        let run = |axle_per_step: f64| {
            let mut c = OdometryCheck::default();
            c.epoch(0, 0.0, 0.01, 5.0, 4.0, 0.01);
            for k in 1..=50u64 {
                c.axle_2(&odo(axle_per_step));
                c.epoch(k * s / 10, 2.0 * k as f64, 0.01, 5.0, 4.0, 0.01);
            }
            c.last().cloned().unwrap()
        };
        // The filter moved 100 m in 5 s; σ² = 0.02 + 1² + (2 × 0.0283)² → limit about 4.0 m.
        let fine = run(2.0);
        assert!(fine.passed, "{fine:?}");
        let off = run(1.9); // axle 2 says 95 m
        assert!(
            !off.passed && off.reason.unwrap().contains("axle 2 95.00 m"),
            "{fine:?}"
        );
    }
}
