//! The input U of source 002's filter: axle 1's acceleration, smoothed, resolved onto east and
//! north with the map's heading and curvature.
//!
//! The smoothing is the least-squares slope of the axle's speed over the last window (its
//! pulse quantisation makes a difference of two samples useless). On a curve the velocity
//! vector turns at `v κ` (κ the track's curvature), so each axis also sees the centripetal
//! part: with heading h clockwise from north,
//!
//! ```text
//! U_e = a sin h + v² κ cos h
//! U_n = a cos h − v² κ sin h
//! ```

use std::collections::VecDeque;

/// Axle 1's recent speeds, for their slope.
#[derive(Debug, Clone, Default)]
pub struct AxleAcceleration {
    samples: VecDeque<(u64, f64)>,
}

impl AxleAcceleration {
    /// A speed sample; keeps the last `window_s`.
    pub fn push(&mut self, stamp_ns: u64, speed_mps: f64, window_s: f64) {
        if !speed_mps.is_finite() {
            return;
        }
        self.samples.push_back((stamp_ns, speed_mps));
        while let Some(&(t0, _)) = self.samples.front() {
            if railfuse_catalog::seconds_between(t0, stamp_ns) > window_s {
                self.samples.pop_front();
            } else {
                break;
            }
        }
    }

    /// Forgets the samples (the axle was diagnosed faulty: its recent speeds are suspect).
    pub fn clear(&mut self) {
        self.samples.clear();
    }

    /// The least-squares slope of speed over the window (m/s²); None with fewer than three
    /// samples or no spread in time.
    pub fn acceleration(&self) -> Option<f64> {
        if self.samples.len() < 3 {
            return None;
        }
        let t0 = self.samples[0].0;
        let n = self.samples.len() as f64;
        let ts = |t: u64| railfuse_catalog::seconds_between(t0, t);
        let (mt, mv) = self
            .samples
            .iter()
            .fold((0.0, 0.0), |(a, b), &(t, v)| (a + ts(t) / n, b + v / n));
        let (mut stt, mut stv) = (0.0, 0.0);
        for &(t, v) in &self.samples {
            let dt = ts(t) - mt;
            stt += dt * dt;
            stv += dt * (v - mv);
        }
        (stt > 0.0).then(|| stv / stt)
    }
}

/// `(U_e, U_n)` for along-track acceleration `a`, speed `v`, heading `h` and curvature `κ`.
pub fn resolve(a: f64, v: f64, heading_rad: f64, curvature: f64) -> (f64, f64) {
    let (s, c) = heading_rad.sin_cos();
    let centripetal = v * v * curvature;
    (a * s + centripetal * c, a * c - centripetal * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slope_of_a_steady_acceleration_is_exact_and_a_curve_adds_the_centripetal_part() {
        let mut u = AxleAcceleration::default();
        for k in 0..50u64 {
            u.push(k * 40_000_000, 10.0 + 0.8 * k as f64 * 0.04, 1.0);
        }
        assert!((u.acceleration().unwrap() - 0.8).abs() < 1e-9);
        // Heading north at 20 m/s on a right-hand curve of 400 m: 1 m/s² towards the east.
        let (ue, un) = resolve(0.0, 20.0, 0.0, 1.0 / 400.0);
        assert!((ue - 1.0).abs() < 1e-12 && un.abs() < 1e-12);
        let (ue, un) = resolve(0.5, 0.0, std::f64::consts::FRAC_PI_2, 0.0);
        assert!((ue - 0.5).abs() < 1e-12 && un.abs() < 1e-12);
    }
}
