//! What a sensor at its place on the train sees in the simulated world: the catalogue's
//! [`point_motion`] on the track's exact geometry with the train as installed, plus the body's
//! vibration, turned into the sensor's axes by its mounting.

use nalgebra::Vector3;
use railfuse_catalog::messages::SensorMount;
use railfuse_catalog::track_profile::TrackPose;
use railfuse_catalog::train_motion::{
    point_motion, AlongTrack, PointMotion, TrackGeometry, INSTANT_S,
};

use super::track::Track;
use super::world::World;

/// The track's exact frame: the published polyline's point, the exact heading, gradient and
/// cant.
impl TrackGeometry for Track {
    fn pose(&self, chainage_m: f64) -> TrackPose {
        let (east_m, north_m, _) = self
            .map
            .locate(chainage_m)
            .expect("a built track has vertices");
        TrackPose {
            chainage_m,
            east_m,
            north_m,
            up_m: self.height(chainage_m),
            heading_rad: self.heading(chainage_m),
            gradient: self.gradient(chainage_m),
            cant_rad: (self.cant_m(chainage_m) / self.map.cant_base())
                .clamp(-1.0, 1.0)
                .asin(),
        }
    }

    fn curvature(&self, chainage_m: f64) -> f64 {
        Track::curvature(self, chainage_m)
    }

    fn vertical_curvature(&self, chainage_m: f64) -> f64 {
        Track::vertical_curvature(self, chainage_m)
    }
}

/// The motion of the sensor mounted at `mount`, its specific force and rate in its own axes.
pub fn motion(w: &World, mount: &SensorMount) -> PointMotion {
    let along = AlongTrack {
        chainage_m: w.chainage_m,
        speed_mps: w.speed_mps,
        acceleration_mps2: w.acceleration_mps2,
    };
    let m = point_motion(w.track, w.vehicle, along, mount, INSTANT_S);
    let to_sensor = mount.mounting().inverse();
    PointMotion {
        specific_force: to_sensor * (m.specific_force + Vector3::from(w.ride.specific_force)),
        angular_rate: to_sensor * (m.angular_rate + Vector3::from(w.ride.angular_rate)),
        ..m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::ride::RideSample;
    use crate::simulator::track::{straight_line, GradientSection, Track, VerticalParams};
    use railfuse_catalog::geodesy::GeodeticOrigin;
    use railfuse_catalog::messages::Vehicle;
    use railfuse_catalog::vehicle::GRAVITY_MPS2;

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
