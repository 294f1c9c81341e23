//! The level an IMU's readings are turned into where the train is: the map's gradient, cant
//! and body lean, looked up where the gyro's roll says the train is on a cant ramp.
//!
//! A pipeline with no attitude of its own takes gravity out of the IMU's readings with the
//! map's level at its estimated chainage (map-aided,
//! [`Vehicle::level_on`](railfuse_catalog::messages::Vehicle::level_on)). That is right
//! while the chainage is. Through a GNSS loss it drifts, and a cant ramp taken out some metres
//! from where the train meets it leaves `g Δφ` across the track for as long as the two
//! differ: 100 mm of cant (0.067 rad) met 20 m late at 20 m/s leaves 0.65 m/s² for a second,
//! 0.65 m/s of lateral velocity the planar INS keeps until the other end of the curve.
//!
//! Carrying the roll on the gyro instead does not help a MEMS IMU: its angle random walk
//! (source 003's: 2.4 °/√h, 0.7 mrad/√s) is 9 mrad after a 161 s loss, `g` times that across
//! the track, integrated twice. The map's roll is good to about 1 mrad where the chainage is
//! right; what a loss spoils is *where* to look it up. So the gyro places the lookup:
//!
//! - `δ`, the gyro's roll less the map's at the lookup, high-passed with `τ` (what the gyro
//!   says changed that the map did not): `δ̇ = (φ̇_gyro − φ̇_map) − δ/τ`, with the Euler rate
//!   `φ̇_gyro = p + (q sin φ + r cos φ) tan θ`. A constant gyro bias leaves `b τ` in it.
//! - On a ramp, where the map's roll changes with chainage by `H = ∂φ_map/∂s`, a lookup `Δs`
//!   short shows as `δ ≈ H Δs`: a measurement of the lookup's shift, fused every
//!   [`UPDATE_S`] (the samples of `δ` in between are one measurement: its noise is the gyro's
//!   walk over `τ`) into a Kalman filter on the shift and its rate (the dead reckoning's
//!   chainage drifts steadily, by the speed error the loss began with). Off the ramps `H` is
//!   about zero and the shift runs on at its rate, so the next ramp is looked for where the
//!   last one put it.
//! - While the pipeline's chainage is held by its fixes the shift is zero: it is estimated
//!   through a loss only, from the loss's start.
//!
//! Measured on source 003's railway (`--scenario seed003_3d`, seed 3, its 150 s loss, `kf`
//! with `calibrate`'s mounting): the level's roll error through the loss 3.1 → 1.5 mrad RMS
//! (13.4 → 7.9 max; 0.9 with the fixes), the error across the track 9.1 → 7.8 m RMS (7.6 on
//! the flat twin). What is left is along the track (docs/vehicle.md).

use nalgebra::{Matrix2, Rotation3, RowVector2, Vector2, Vector3};

use crate::filter::KalmanFilter;
use crate::model::ConstantVelocity;

/// The high-pass time constant of the gyro's roll against the map's, s: longer than a cant
/// ramp takes at line speed (64 m at 33 m/s: 2 s), short enough that the gyro's walk over it
/// (0.7 mrad/√s · √τ) stays under the map's roll error a ramp met late makes.
const TAU_S: f64 = 3.0;
/// The interval between the shift's updates, s (`δ`'s samples within `τ` are one
/// measurement).
const UPDATE_S: f64 = 1.0;
/// `δ`'s noise as a measurement of `H Δs`, rad: the gyro's walk over `τ` with the body's
/// vibration and the lean model's error (`δ` spreads 2 mrad RMS on source 003's railway
/// where the chainage is right).
const DELTA_SIGMA_RAD: f64 = 3.0e-3;
/// The lookup shift's rate (the dead reckoning's speed error) at a loss's start, m/s (1σ),
/// and how fast it wanders, m²/s³: the shift drifts steadily between ramps, by the speed
/// error the loss began with.
const SHIFT_RATE_SIGMA_MPS: f64 = 0.3;
const SHIFT_RATE_PSD: f64 = 1e-3;
/// The lookup's shift at a loss's start, m (1σ): the chainage the fixes left.
const SHIFT_SIGMA_M: f64 = 0.5;
/// The least roll slope that is a cant ramp, rad/m: a ramp of 1:400 over 1.5 m of gauge is
/// 1.7 mrad/m; the lean's change with the curvature and the vertices' rounding are far less.
const MIN_SLOPE_RAD_PER_M: f64 = 5e-4;
/// The chainage span `H` is taken over, m: a ramp's slope, not the vertices' steps.
const SLOPE_HALF_SPAN_M: f64 = 4.0;

/// Where the map's level is looked up, and the gyro's roll that places it.
#[derive(Debug, Clone, Default)]
pub struct GyroTilt {
    /// The map's roll at the lookup at the last reading, rad.
    map_roll: Option<f64>,
    /// `δ`, rad.
    offset: f64,
    time_ns: Option<u64>,
    next_update_ns: u64,
    /// The lookup's shift from the pipeline's chainage and its rate, m and m/s, while the
    /// pipeline's chainage is free.
    shift: Option<KalmanFilter<2>>,
}

fn roll_of(level: &Rotation3<f64>) -> f64 {
    level.euler_angles().0
}

impl GyroTilt {
    /// The body-to-level rotation at `t_ns`: the map's, `level_at(shift)` giving it at the
    /// pipeline's chainage plus `shift` (`None` where there is no map, which forgets the
    /// gyro's roll), at the shift the gyro's roll places it; `rate` the gyro's body rates
    /// (turned by its mounting), rad/s; `free` while the pipeline's chainage is not held by
    /// its fixes.
    pub fn level(
        &mut self,
        t_ns: u64,
        level_at: impl Fn(f64) -> Option<Rotation3<f64>>,
        rate: Vector3<f64>,
        free: bool,
    ) -> Option<Rotation3<f64>> {
        let dt = match self.time_ns {
            Some(t) if t_ns > t => (t_ns - t) as f64 * 1e-9,
            _ => 0.0,
        };
        match (free, self.shift.as_mut()) {
            (false, _) => self.shift = None,
            (true, Some(shift)) => {
                let drift = ConstantVelocity {
                    acceleration_psd: SHIFT_RATE_PSD,
                };
                shift.predict(&drift, dt);
            }
            (true, None) => {
                let spread = Vector2::new(SHIFT_SIGMA_M, SHIFT_RATE_SIGMA_MPS);
                self.shift = Some(KalmanFilter::new(
                    Vector2::zeros(),
                    Matrix2::from_diagonal(&spread.component_mul(&spread)),
                ));
            }
        }
        let Some(mut level) = level_at(self.shift_m()) else {
            *self = Self::default();
            return None;
        };
        // Once per IMU sample: the map's roll and pitch at the lookup.
        let (roll, pitch, _) = level.euler_angles();
        if let (Some(before), true) = (self.map_roll, dt > 0.0) {
            let phi = before + self.offset;
            let (s, c) = phi.sin_cos();
            let gyro = rate.x + (rate.y * s + rate.z * c) * pitch.tan();
            self.offset = (self.offset + gyro * dt - (roll - before)) * (-dt / TAU_S).exp();
        }
        self.time_ns = Some(t_ns);
        self.map_roll = Some(roll);
        if free && t_ns >= self.next_update_ns {
            self.next_update_ns = t_ns + (UPDATE_S * 1e9) as u64;
            if let Some(shifted) = self.update_shift(&level_at) {
                level = shifted;
            }
        }
        Some(level)
    }

    /// The lookup's shift, m.
    fn shift_m(&self) -> f64 {
        self.shift.as_ref().map_or(0.0, |k| k.estimate.state[0])
    }

    /// Fuses `δ` as `H Δs`; the level at the new shift (its roll change taken out of `δ`, as
    /// the gyro saw no turn).
    fn update_shift(
        &mut self,
        level_at: &impl Fn(f64) -> Option<Rotation3<f64>>,
    ) -> Option<Rotation3<f64>> {
        let (h, shift) = (SLOPE_HALF_SPAN_M, self.shift_m());
        let ahead = roll_of(&level_at(shift + h)?);
        let behind = roll_of(&level_at(shift - h)?);
        let slope = (ahead - behind) / (2.0 * h);
        if slope.abs() < MIN_SLOPE_RAD_PER_M {
            return None;
        }
        let kf = self.shift.as_mut()?;
        let row = RowVector2::new(slope, 0.0);
        let r = DELTA_SIGMA_RAD * DELTA_SIGMA_RAD;
        // `δ` measures the shift still missing: `H (Δs − Δŝ)`, the innovation itself.
        let z = self.offset + slope * shift;
        if kf.innovation(&row, r, z).nis > 25.0 {
            return None;
        }
        kf.update(&row, r, z);
        let level = level_at(kf.estimate.state[0])?;
        let roll = roll_of(&level);
        self.offset -= roll - self.map_roll.unwrap_or(roll);
        self.map_roll = Some(roll);
        Some(level)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A curve's cant on the map: 0.1 rad, ramped over 64 m at chainage 500 m and off again
    /// at 900 m.
    fn cant(s: f64) -> f64 {
        0.1 * ((s - 500.0) / 64.0).clamp(0.0, 1.0) * ((964.0 - s) / 64.0).clamp(0.0, 1.0)
    }

    /// The train at 20 m/s from chainage 100 m into a loss, its dead reckoning falling behind
    /// at `drift` m/s; a gyro at 200 Hz with a bias of 0.007 °/s reads the true roll rate.
    /// Returns the roll error's RMS over both ramps (the level's, and the map's at the
    /// estimate) and the shift found against the drift at the end.
    fn through_the_curve(free: bool, drift: f64) -> (f64, f64, f64) {
        let (v, rate_hz) = (20.0, 200.0);
        let bias = 0.007f64.to_radians();
        let mut tilt = GyroTilt::default();
        let (mut sum, mut sum_map, mut n) = (0.0, 0.0, 0.0);
        let mut miss = 0.0;
        for k in 0..(50.0 * rate_hz) as u64 {
            let t = k as f64 / rate_hz;
            let s_true = 100.0 + v * t;
            let s_est = s_true - drift * t;
            let roll_rate = (cant(s_true + 0.05) - cant(s_true - 0.05)) / 0.1 * v;
            let level_at =
                |shift: f64| Some(Rotation3::from_euler_angles(cant(s_est + shift), 0.0, 0.0));
            let rate = Vector3::new(roll_rate + bias, 0.0, 0.0);
            let t_ns = (k as f64 * 1e9 / rate_hz) as u64;
            let level = tilt.level(t_ns, level_at, rate, free).unwrap();
            let near_a_ramp = |s: f64| (480.0..600.0).contains(&s) || (880.0..1000.0).contains(&s);
            if near_a_ramp(s_true) {
                sum += (roll_of(&level) - cant(s_true)).powi(2);
                sum_map += (cant(s_est) - cant(s_true)).powi(2);
                n += 1.0;
            }
            miss = tilt.shift_m() - drift * t;
        }
        ((sum / n).sqrt(), (sum_map / n).sqrt(), miss)
    }

    /// Through a loss the gyro's roll finds the ramps where the train meets them: the level's
    /// roll error is a fraction of the map's at the drifted chainage, and the shift follows
    /// the drift.
    #[test]
    fn cant_ramps_met_late_are_found_by_the_gyros_roll() {
        for drift in [0.3, 0.6] {
            let (rms, rms_map, miss) = through_the_curve(true, drift);
            assert!(rms_map > 0.01, "{rms_map}");
            assert!(
                rms < 0.4 * rms_map,
                "{drift} m/s: {rms} rad RMS, the map's {rms_map}"
            );
            assert!(
                miss.abs() < 3.0,
                "{drift} m/s: the shift misses the drift by {miss} m"
            );
        }
    }

    /// While the fixes hold the chainage the map's level is taken as it is.
    #[test]
    fn with_the_chainage_held_the_level_is_the_maps() {
        let (rms, rms_map, _) = through_the_curve(false, 0.6);
        assert_eq!(rms, rms_map);
    }
}
