//! Planar inertial navigation for a train: three IMU axes carry the motion in the plane, the
//! forward and lateral specific force (the train's acceleration, with each accelerometer's
//! bias) and the rate about the up axis (its turning, with the gyro's bias). The velocity is
//! kept in the body frame, forward `u` and lateral `w` (to the left):
//!
//! ```text
//! ω = ω_z − b_g                  (counter-clockwise, about up; a level track assumed)
//! u̇ = f_x − b_x + ω w            ẇ = f_y − b_y − ω u           ψ̇ = −ω
//! ė = u sin ψ − w cos ψ          ṅ = u cos ψ + w sin ψ          (ψ clockwise from north)
//! ```
//!
//! integrated at the midpoint of each IMU interval. On rails `w` stays zero (the centripetal
//! pull `f_y = ω u` is what keeps it there): the non-holonomic constraint the pipeline can
//! fuse as a pseudo-measurement. Without it a lateral accelerometer bias moves the train
//! sideways, as it would a car's INS.

/// The nominal (whole) navigation state the error-state filter corrects.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Navigation {
    pub east_m: f64,
    pub north_m: f64,
    /// Along the body's x axis (the heading), m/s (negative when the train backs).
    pub speed_mps: f64,
    /// Along the body's y axis (to the left), m/s.
    pub lateral_mps: f64,
    /// Clockwise from north, rad.
    pub heading_rad: f64,
    /// Forward accelerometer bias, m/s².
    pub accel_bias_mps2: f64,
    /// Lateral accelerometer bias, m/s².
    pub lateral_bias_mps2: f64,
    /// Gyro bias about the up axis, rad/s.
    pub gyro_bias_radps: f64,
}

impl Navigation {
    /// Dead-reckons over `dt` with forward and lateral specific force `f` and yaw rate `ω_z`;
    /// returns the forward acceleration used.
    pub fn propagate(&mut self, f: [f64; 2], yaw_rate_radps: f64, dt: f64) -> f64 {
        let omega = yaw_rate_radps - self.gyro_bias_radps;
        let a = f[0] - self.accel_bias_mps2 + omega * self.lateral_mps;
        let b = f[1] - self.lateral_bias_mps2 - omega * self.speed_mps;
        let u_mid = self.speed_mps + 0.5 * a * dt;
        let w_mid = self.lateral_mps + 0.5 * b * dt;
        let psi_mid = self.heading_rad - 0.5 * omega * dt;
        let (s, c) = psi_mid.sin_cos();
        self.east_m += (u_mid * s - w_mid * c) * dt;
        self.north_m += (u_mid * c + w_mid * s) * dt;
        self.speed_mps += a * dt;
        self.lateral_mps += b * dt;
        self.heading_rad = (self.heading_rad - omega * dt).rem_euclid(std::f64::consts::TAU);
        a
    }

    /// East and north velocity.
    pub fn velocity(&self) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        let (u, w) = (self.speed_mps, self.lateral_mps);
        (u * s - w * c, u * c + w * s)
    }

    pub fn is_finite(&self) -> bool {
        [
            self.east_m,
            self.north_m,
            self.speed_mps,
            self.lateral_mps,
            self.heading_rad,
            self.accel_bias_mps2,
            self.lateral_bias_mps2,
            self.gyro_bias_radps,
        ]
        .iter()
        .all(|x| x.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At the origin heading north at `v`, knowing a gyro bias `gyro_bias`.
    fn heading_north(v: f64, gyro_bias: f64) -> Navigation {
        Navigation {
            speed_mps: v,
            gyro_bias_radps: gyro_bias,
            ..Navigation::default()
        }
    }

    /// A train at 20 m/s through a right-hand curve of 1 km radius for 60 s, IMU at 200 Hz
    /// with a known gyro bias the navigation knows: it ends where the arc does.
    #[test]
    fn dead_reckons_a_curve_within_centimetres_when_the_bias_is_known() {
        let (v, radius, rate_hz, t_end) = (20.0, 1000.0, 200.0, 60.0);
        let bias = 0.007f64.to_radians();
        let mut nav = heading_north(v, bias);
        let omega = v / radius; // heading rate, clockwise
        let n = (t_end * rate_hz) as usize;
        for _ in 0..n {
            nav.propagate([0.0, -v * omega], -omega + bias, 1.0 / rate_hz);
        }
        // On a circle from (0, 0) heading north, turning right about (radius, 0).
        let angle = omega * t_end;
        let (e, north) = (radius * (1.0 - angle.cos()), radius * angle.sin());
        let miss = (nav.east_m - e).hypot(nav.north_m - north);
        assert!(miss < 0.01, "missed the arc by {miss} m");
        assert!((nav.heading_rad - angle).abs() < 1e-9);
    }

    /// A straight at constant speed with the gyro bias unknown (0.007 °/s, the source's bias
    /// stability): the heading turns as `b t`, but nothing pushes the train, so the free
    /// navigation keeps its velocity in the plane (the body turns under it, `w = −u sin bt`)
    /// and stays on the line. Only a constraint that ties the velocity to the heading (the
    /// NHC) turns the heading error into a cross-track one.
    #[test]
    fn an_unknown_gyro_bias_turns_the_heading_not_the_track() {
        let (v, rate_hz, t_end) = (20.0, 200.0, 60.0);
        let bias = 0.007f64.to_radians();
        let mut nav = heading_north(v, 0.0);
        for _ in 0..(t_end * rate_hz) as usize {
            nav.propagate([0.0, 0.0], bias, 1.0 / rate_hz);
        }
        let turned = bias * t_end;
        let heading = (nav.heading_rad + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!((heading + turned).abs() < 1e-9, "{heading} vs {}", -turned);
        assert!(nav.east_m.abs() < 1e-3, "{} m across", nav.east_m);
        assert!((nav.north_m - v * t_end).abs() < 1e-3);
        assert!((nav.lateral_mps + v * turned.sin()).abs() < 1e-6);
    }
}
