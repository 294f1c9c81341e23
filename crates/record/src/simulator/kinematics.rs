//! What a sensor at its place on the train sees: its position, velocity, specific force and
//! angular rate, from the track's exact geometry, the train's motion along it, the body's
//! lean and vibration, and the sensor's lever arm and mounting ([`SensorMount`], the
//! catalogue's one vehicle model).
//!
//! The centre line's point at the sensor's chainage `s` moves with `ṡ = v` along the track:
//! velocity `v T` with `T = (sin ψ, cos ψ, G)` (chainage is measured in the plane, so `T`
//! is a little longer than 1 on a gradient), acceleration `a T + v² (κ cos ψ, −κ sin ψ, G')`.
//! The lever arm across the track, `(0, y, z)` in the body, turns with the body: its velocity
//! and acceleration are the body rotation's, taken by central differences of the exact
//! rotation 5 ms either side (smooth, small numbers: no cancellation). Specific force is
//! `Rᵀ (acc + g ẑ)` in the body, turned into the sensor's axes by its mounting.

use nalgebra::{Rotation3, Vector3};
use railfuse_catalog::messages::SensorMount;
use railfuse_catalog::track_profile::TrackPose;
use railfuse_catalog::vehicle::GRAVITY_MPS2;

use super::world::World;

/// One sensor's motion at one simulation step.
#[derive(Debug, Clone, Copy)]
pub struct Motion {
    /// The chainage of the sensor's place on the track.
    pub chainage_m: f64,
    /// Local east/north/up, m.
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    /// In the sensor's axes, m/s².
    pub specific_force: Vector3<f64>,
    /// In the sensor's axes, rad/s.
    pub angular_rate: Vector3<f64>,
    /// Speed along the rail at the sensor's place (what a wheel rolls), m/s.
    pub rail_speed_mps: f64,
}

/// Half the span of the central differences, s.
const H: f64 = 0.005;

/// The track's exact frame at `chainage_m` (the published polyline's point, the exact heading,
/// gradient and cant).
pub fn track_pose(w: &World, chainage_m: f64) -> TrackPose {
    let t = w.track;
    let (east_m, north_m, _) = t
        .map
        .locate(chainage_m)
        .expect("a built track has vertices");
    TrackPose {
        chainage_m,
        east_m,
        north_m,
        up_m: t.height(chainage_m),
        heading_rad: t.heading(chainage_m),
        gradient: t.gradient(chainage_m),
        cant_rad: (t.cant_m(chainage_m) / t.map.cant_base())
            .clamp(-1.0, 1.0)
            .asin(),
    }
}

/// The body's rotation to east/north/up at time offset `tau` from now, for the place `along`
/// metres of chainage from the front end.
fn body_to_enu(w: &World, along: f64, tau: f64) -> Rotation3<f64> {
    let s = w.chainage_m + along + w.speed_mps * tau + 0.5 * w.acceleration_mps2 * tau * tau;
    let v = w.speed_mps + w.acceleration_mps2 * tau;
    let pose = track_pose(w, s);
    let roll = w.vehicle.body_roll(v, w.track.curvature(s), pose.cant_rad);
    pose.body_to_enu(roll)
}

/// The motion of the sensor mounted at `mount`.
pub fn motion(w: &World, mount: &SensorMount) -> Motion {
    let along = mount.lever_arm_m[0];
    let s = w.chainage_m + along;
    let pose = track_pose(w, s);
    let (v, a) = (w.speed_mps, w.acceleration_mps2);
    let (kappa, psi, g) = (w.track.curvature(s), pose.heading_rad, pose.gradient);
    let tangent = Vector3::new(psi.sin(), psi.cos(), g);
    let bend = Vector3::new(
        kappa * psi.cos(),
        -kappa * psi.sin(),
        w.track.vertical_curvature(s),
    );
    let centre_acceleration = a * tangent + v * v * bend;
    let (before, now, after) = (
        body_to_enu(w, along, -H),
        body_to_enu(w, along, 0.0),
        body_to_enu(w, along, H),
    );
    let across = Vector3::new(0.0, mount.lever_arm_m[1], mount.lever_arm_m[2]);
    let (r0, r1, r2) = (before * across, now * across, after * across);
    let lever_velocity = (r2 - r0) / (2.0 * H);
    let lever_acceleration = (r2 - 2.0 * r1 + r0) / (H * H);
    // Ω× = Rᵀ Ṙ, the body's rate in its own axes.
    let omega = now.matrix().transpose() * (after.matrix() - before.matrix()) / (2.0 * H);
    let body_rate = Vector3::new(omega[(2, 1)], omega[(0, 2)], omega[(1, 0)]);
    let acceleration = centre_acceleration + lever_acceleration;
    let body_force = now.inverse() * (acceleration + Vector3::new(0.0, 0.0, GRAVITY_MPS2))
        + Vector3::from(w.ride.specific_force);
    let to_sensor = mount.mounting().inverse();
    Motion {
        chainage_m: s,
        position: pose.position() + r1,
        velocity: v * tangent + lever_velocity,
        specific_force: to_sensor * body_force,
        angular_rate: to_sensor * (body_rate + Vector3::from(w.ride.angular_rate)),
        rail_speed_mps: v * pose.rail_per_chainage(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::ride::RideSample;
    use crate::simulator::track::{straight_line, GradientSection, Track, VerticalParams};
    use railfuse_catalog::geodesy::GeodeticOrigin;
    use railfuse_catalog::messages::Vehicle;

    fn world<'a>(track: &'a Track, vehicle: &'a Vehicle, s: f64, v: f64) -> World<'a> {
        World {
            t_ns: 0,
            dt: 1e-3,
            chainage_m: s,
            speed_mps: v,
            acceleration_mps2: 0.0,
            east_m: 0.0,
            north_m: s,
            heading_rad: 0.0,
            curvature: 0.0,
            in_tunnel: false,
            corrections: true,
            gnss_outage: false,
            sky_view: 1.0,
            gnss_multipath: (0.0, 0.0),
            track,
            vehicle,
            ride: RideSample::default(),
        }
    }

    /// Level for 1 km, then 35 ‰ (a vertical curve of 2 500 m between).
    fn climbing() -> Track {
        let origin = GeodeticOrigin {
            latitude_deg: 45.0,
            longitude_deg: 10.0,
            altitude_m: 100.0,
        };
        let g = |length_m, permille| GradientSection { length_m, permille };
        straight_line(
            origin,
            Some(VerticalParams {
                sections: vec![g(1000.0, 0.0), g(20_000.0, 35.0)],
                curve_radius_m: 2500.0,
            }),
        )
    }

    #[test]
    fn at_rest_on_a_gradient_an_accelerometer_reads_gravity_along_the_track() {
        let track = climbing();
        let point = Vehicle::point();
        let imu = SensorMount::at_front("/imu");
        let m = motion(&world(&track, &point, 2000.0, 0.0), &imu);
        let theta = 0.035f64.atan();
        let f = m.specific_force;
        assert!((f.x - GRAVITY_MPS2 * theta.sin()).abs() < 1e-9, "{f}");
        assert!(f.y.abs() < 1e-9 && (f.z - GRAVITY_MPS2 * theta.cos()).abs() < 1e-9);
        assert!(m.angular_rate.norm() < 1e-9);
        // Mounted pitched up by 1°, it reads a further g sin 1° forward.
        let pitched = SensorMount {
            mounting_deg: [0.0, -1.0, 0.0],
            ..imu
        };
        let m = motion(&world(&track, &point, 2000.0, 0.0), &pitched);
        let expected = GRAVITY_MPS2 * (theta + 1f64.to_radians()).sin();
        assert!((m.specific_force.x - expected).abs() < 1e-9);
    }

    #[test]
    fn over_a_vertical_curve_at_speed_the_body_pitches_and_feels_v_squared_over_r() {
        let track = climbing();
        let point = Vehicle::point();
        let imu = SensorMount::at_front("/imu");
        // Mid-curve (1 000 m, gradient 17.5 ‰) at 40 m/s: a sag curve pushes up by v²/R.
        let m = motion(&world(&track, &point, 1000.0, 40.0), &imu);
        let theta = 0.0175f64.atan();
        let up = GRAVITY_MPS2 * theta.cos() + 40.0 * 40.0 / 2500.0 * theta.cos().powi(2);
        assert!(
            (m.specific_force.z - up).abs() < 0.01,
            "{}",
            m.specific_force
        );
        // Pitching up at v/R (about the left axis, nose up: negative).
        let rate = 40.0 / 2500.0;
        assert!(
            (m.angular_rate.y + rate).abs() < 0.05 * rate,
            "{}",
            m.angular_rate
        );
        // Wheels roll the rail, longer than the chainage.
        assert!((m.rail_speed_mps - 40.0 * (1.0f64 + 0.0175 * 0.0175).sqrt()).abs() < 1e-6);
    }
}
