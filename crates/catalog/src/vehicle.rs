//! The train's geometry, one model for the simulator and every measurement model: the body
//! frame at the front end, the train's length, and each sensor's lever arm and mounting
//! ([`Vehicle`], [`SensorMount`]); where a sensor is and how it is turned when the front end
//! is at a chainage of a [`TrackMap`] ([`SensorMount::pose`]).
//!
//! The train follows the track: a sensor `x` metres behind the front end is on the track `x`
//! metres of chainage back, and its `y` (left) and `z` (up) are taken in the frame of the car
//! body there, turned by the track's heading, gradient and cant and by the body's lean
//! ([`Vehicle::body_roll`]). A car's body is a chord of the curve its bogies stand on, not
//! the arc: a sensor half way between the bogies of a 25 m car on a 1 200 m curve is 6 cm
//! inside the track's centre line, which this model leaves out.
//!
//! The front end leads towards increasing chainage; a run the other way round is the issue of
//! the track network's direction of travel, not of this model.

use nalgebra::{Rotation3, Vector3};

use crate::messages::{SensorMount, TrackMap, Vehicle};
use crate::track_profile::TrackPose;

/// A mounting is a small misalignment of axes that are meant to be the body's: more than
/// this is axes given wrongly (a sensor on its side is an axis mapping, not a mounting).
pub const MAX_MOUNTING_DEG: f64 = 45.0;
/// No loading gauge is wider than 2 × 1.7 m: further out is not on the train.
pub const MAX_LATERAL_M: f64 = 2.0;
/// Under the top of rail by more than this is under the rail (balise and eddy-current
/// antennas hang some 0.1–0.2 m above it).
pub const MIN_HEIGHT_M: f64 = -0.3;
/// Above a raised pantograph.
pub const MAX_HEIGHT_M: f64 = 6.5;
/// Longer than any train that runs (the longest freight trains are some 3.5 km).
pub const MAX_LENGTH_M: f64 = 4_000.0;
/// Looser than any installation drawing's tolerance, m (1σ): a sensor known no better is not
/// placed.
pub const MAX_INSTALLATION_STD_M: f64 = 0.5;
/// Gravity, m/s² (standard).
pub const GRAVITY_MPS2: f64 = 9.80665;

/// A sensor's place when the front end is at a chainage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorPose {
    /// The track's frame at the sensor's chainage.
    pub track: TrackPose,
    /// Where the sensor is, local east/north/up, m.
    pub position: Vector3<f64>,
    /// From the car body's axes there to east/north/up.
    pub body_to_enu: Rotation3<f64>,
    /// From the sensor's own axes to east/north/up.
    pub sensor_to_enu: Rotation3<f64>,
}

/// Where the train stands, for moving a position measured at one of its points to another
/// ([`SensorMount::offset_from`]).
#[derive(Debug, Clone, Copy)]
pub enum TrainPlace<'a> {
    /// On a map's main line: the front end at a chainage, the body leaning by a roll
    /// ([`Vehicle::lean_on`]).
    Map {
        map: &'a TrackMap,
        front_chainage_m: f64,
        body_roll_rad: f64,
    },
    /// No map: on a straight, level line at a heading (clockwise from north).
    Straight { heading_rad: f64 },
}

impl SensorMount {
    /// A sensor at the front end with the body's axes: every sensor of a point train.
    pub fn at_front(topic: &str) -> SensorMount {
        SensorMount {
            topic: topic.to_owned(),
            frame_id: None,
            lever_arm_m: [0.0; 3],
            mounting_deg: [0.0; 3],
        }
    }

    /// The lever arm, m, in the body frame.
    pub fn lever_arm(&self) -> Vector3<f64> {
        Vector3::from(self.lever_arm_m)
    }

    /// From the sensor's axes to the body's: `Rz(yaw) Ry(pitch) Rx(roll)`.
    pub fn mounting(&self) -> Rotation3<f64> {
        let [r, p, y] = self.mounting_deg.map(f64::to_radians);
        Rotation3::from_euler_angles(r, p, y)
    }

    /// The chainage of the sensor's place on the track when the front end is at
    /// `front_chainage_m`.
    pub fn chainage(&self, front_chainage_m: f64) -> f64 {
        front_chainage_m + self.lever_arm_m[0]
    }

    /// The front end's chainage when the sensor is at `chainage_m` (a balise passed by its
    /// antenna, a GNSS antenna's place matched on the map).
    pub fn front_chainage(&self, chainage_m: f64) -> f64 {
        chainage_m - self.lever_arm_m[0]
    }

    /// The front end's chainage when the sensor's point, projected on the track map, is at
    /// `chainage_m` (a GNSS antenna's fix matched on the map): its lever arm's x, and the
    /// part of its height and side offset the body's gradient and cant turn along the track
    /// (a roof antenna 4 m up on 35 ‰ sits 14 cm behind its car's point on the rail).
    pub fn front_chainage_of_point(&self, map: &TrackMap, chainage_m: f64) -> f64 {
        let front = self.front_chainage(chainage_m);
        let Some(pose) = self.pose(map, front, 0.0) else {
            return front;
        };
        let offset = pose.position - pose.track.position();
        let heading = pose.track.heading_rad;
        let along = offset.x * heading.sin() + offset.y * heading.cos();
        front - along
    }

    /// The sensor's place less the centre line's point `x_m` along the body (0: the front
    /// end; negative: behind it), east/north/up, m: what to take off a position the sensor
    /// measured to have that point's. On a map the two places are each on the track (a roof
    /// antenna on a canted curve leans in by its height times the cant's and the body's
    /// roll); without one the train is a rigid straight body at the heading.
    pub fn offset_from(&self, place: TrainPlace<'_>, x_m: f64) -> Vector3<f64> {
        let straight = |heading: f64| {
            let [x, y, z] = self.lever_arm_m;
            let (s, c) = heading.sin_cos();
            // Forward is (sin ψ, cos ψ), left (−cos ψ, sin ψ).
            let dx = x - x_m;
            Vector3::new(dx * s - y * c, dx * c + y * s, z)
        };
        match place {
            TrainPlace::Map {
                map,
                front_chainage_m,
                body_roll_rad,
            } => {
                let sensor = self.pose(map, front_chainage_m, body_roll_rad);
                match (sensor, map.pose_at(front_chainage_m + x_m)) {
                    (Some(sensor), Some(point)) => sensor.position - point.position(),
                    _ => straight(0.0),
                }
            }
            TrainPlace::Straight { heading_rad } => straight(heading_rad),
        }
    }

    /// A reading of this sensor (a specific force, an angular rate) in the level frame that
    /// turns with the train (x forward and y left in the horizontal plane, z up): turned into
    /// the body by the mounting, then by the track's gradient and the cant's and the body's
    /// roll at `level` ([`TrackPose::body_to_level`]); without a track, in the body. What an
    /// along-track or planar pipeline, which has no attitude of its own, takes gravity out
    /// with (map-aided).
    pub fn to_level(&self, level: Option<Rotation3<f64>>, reading: [f64; 3]) -> Vector3<f64> {
        let body = self.mounting() * Vector3::from(reading);
        level.map_or(body, |r| r * body)
    }

    /// The rate at which the train's heading turns, counter-clockwise about up, from this
    /// gyro's reading: the body's rates `(p, q, r)` (turned by the mounting) at the level's roll
    /// `φ` and pitch `θ` give the Euler angles' yaw rate `(q sin φ + r cos φ) / cos θ`.
    ///
    /// Not the rate vector's vertical component ([`Self::to_level`]'s z), which is short of it
    /// by `φ̇ sin θ`: on a gradient the roll rate of a cant ramp has a vertical share that
    /// turns nothing. Taken as a turn it would leave the heading off by the cant's change times
    /// the gradient for the length of the curve (0.1 rad of cant on 35 ‰: 0.2°, 3 m across
    /// the track after a 900 m curve).
    pub fn heading_rate(&self, level: Option<Rotation3<f64>>, reading: [f64; 3]) -> f64 {
        let body = self.mounting() * Vector3::from(reading);
        let Some(level) = level else { return body.z };
        let (roll, pitch, _) = level.euler_angles();
        (body.y * roll.sin() + body.z * roll.cos()) / pitch.cos()
    }

    /// Where the sensor is and how it is turned with the front end at `front_chainage_m` of
    /// `map`'s main line and the body leaning `body_roll_rad` (see [`Vehicle::body_roll`]).
    pub fn pose(
        &self,
        map: &TrackMap,
        front_chainage_m: f64,
        body_roll_rad: f64,
    ) -> Option<SensorPose> {
        let track = map.pose_at(self.chainage(front_chainage_m))?;
        Some(self.pose_on(track, body_roll_rad))
    }

    /// [`Self::pose`] on the track's frame at the sensor's chainage.
    pub fn pose_on(&self, track: TrackPose, body_roll_rad: f64) -> SensorPose {
        let body_to_enu = track.body_to_enu(body_roll_rad);
        let across = Vector3::new(0.0, self.lever_arm_m[1], self.lever_arm_m[2]);
        SensorPose {
            track,
            position: track.position() + body_to_enu * across,
            body_to_enu,
            sensor_to_enu: body_to_enu * self.mounting(),
        }
    }
}

impl Vehicle {
    /// A train of no length with every sensor at its front end, aligned: the world railfuse
    /// assumed before it had a vehicle model, and what a log without one is read as.
    pub fn point() -> Vehicle {
        Vehicle {
            stamp_ns: 0,
            name: String::new(),
            length_m: 0.0,
            roll_per_lateral_mps2: 0.0,
            sensors: Vec::new(),
            installation_std_m: 0.0,
        }
    }

    /// The sensor on `topic`, if the vehicle places it.
    pub fn mount(&self, topic: &str) -> Option<&SensorMount> {
        self.sensors.iter().find(|s| s.topic == topic)
    }

    /// The sensor on `topic`, at the front end if the vehicle does not place it.
    pub fn mount_or_front(&self, topic: &str) -> SensorMount {
        self.mount(topic)
            .cloned()
            .unwrap_or_else(|| SensorMount::at_front(topic))
    }

    /// The variance the drawing's installation tolerance adds to the front end's chainage,
    /// m²: the front end is found through the sensors' lever arms, each known to
    /// `installation_std_m`, a constant error no filter averages away (a consider term added
    /// to what a pipeline reports, not to what it weighs its measurements with).
    pub fn installation_variance(&self) -> f64 {
        self.installation_std_m * self.installation_std_m
    }

    /// The rear end's chainage with the front end at `front_chainage_m`.
    pub fn rear_chainage(&self, front_chainage_m: f64) -> f64 {
        front_chainage_m - self.length_m
    }

    /// The body's lean in its suspension, rad (positive with the left side up): out of the
    /// curve by `roll_per_lateral_mps2` per m/s² of the lateral acceleration the cant does not
    /// balance, `v²κ − g sin φ_cant` (κ positive turning right).
    pub fn body_roll(&self, speed_mps: f64, curvature: f64, cant_rad: f64) -> f64 {
        let unbalanced = speed_mps * speed_mps * curvature - GRAVITY_MPS2 * cant_rad.sin();
        -self.roll_per_lateral_mps2 * unbalanced
    }

    /// Checks the drawing: a length a train has, every sensor on the train and turned less
    /// than [`MAX_MOUNTING_DEG`], no topic placed twice.
    pub fn check(&self) -> Result<(), VehicleProblem> {
        if !(self.length_m.is_finite() && (0.0..=MAX_LENGTH_M).contains(&self.length_m)) {
            return Err(VehicleProblem::Length(self.length_m));
        }
        if !(self.roll_per_lateral_mps2.is_finite()
            && (0.0..0.2).contains(&self.roll_per_lateral_mps2))
        {
            return Err(VehicleProblem::Roll(self.roll_per_lateral_mps2));
        }
        if !(self.installation_std_m.is_finite()
            && (0.0..=MAX_INSTALLATION_STD_M).contains(&self.installation_std_m))
        {
            return Err(VehicleProblem::Installation(self.installation_std_m));
        }
        for (i, s) in self.sensors.iter().enumerate() {
            if self.sensors[..i].iter().any(|o| o.topic == s.topic) {
                return Err(VehicleProblem::Twice(s.topic.clone()));
            }
            self.check_mount(s)?;
        }
        Ok(())
    }

    fn check_mount(&self, s: &SensorMount) -> Result<(), VehicleProblem> {
        let [x, y, z] = s.lever_arm_m;
        let outside = |why: String| VehicleProblem::Outside {
            topic: s.topic.clone(),
            lever_arm_m: s.lever_arm_m,
            why,
        };
        if !s
            .lever_arm_m
            .iter()
            .chain(&s.mounting_deg)
            .all(|v| v.is_finite())
        {
            return Err(outside("a value is not a finite number".into()));
        }
        if x > 0.0 || x < -self.length_m {
            return Err(outside(format!(
                "x must lie between the front end (0) and the rear end (-{} m, the train's \
                 length)",
                self.length_m
            )));
        }
        if y.abs() > MAX_LATERAL_M {
            return Err(outside(format!(
                "y is more than {MAX_LATERAL_M} m from the centre line"
            )));
        }
        if !(MIN_HEIGHT_M..=MAX_HEIGHT_M).contains(&z) {
            return Err(outside(format!(
                "z must lie between {MIN_HEIGHT_M} m (under the rail) and {MAX_HEIGHT_M} m \
                 (above a raised pantograph)"
            )));
        }
        let names = ["roll", "pitch", "yaw"];
        if let Some(i) = (0..3).find(|&i| s.mounting_deg[i].abs() > MAX_MOUNTING_DEG) {
            return Err(VehicleProblem::Mounting {
                topic: s.topic.clone(),
                angle: names[i],
                degrees: s.mounting_deg[i],
            });
        }
        Ok(())
    }
}

/// Why a vehicle's geometry was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VehicleProblem {
    #[error("length_m = {0}: a train is between 0 and 4000 m long")]
    Length(f64),
    #[error("roll_per_lateral_mps2 = {0}: a body leans between 0 and 0.2 rad per m/s²")]
    Roll(f64),
    #[error("installation_std_m = {0}: an installation tolerance is between 0 and 0.5 m (1σ)")]
    Installation(f64),
    #[error("sensor '{0}' is placed twice")]
    Twice(String),
    #[error("sensor '{topic}' at lever arm {lever_arm_m:?} m is outside the train: {why}")]
    Outside {
        topic: String,
        lever_arm_m: [f64; 3],
        why: String,
    },
    #[error(
        "sensor '{topic}': mounting {angle} of {degrees}° is over 45°: a mounting is a small \
         misalignment; give a sensor turned further by its axes"
    )]
    Mounting {
        topic: String,
        angle: &'static str,
        degrees: f64,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geodesy::GeodeticOrigin;
    use crate::messages::TrackVertex;

    fn train() -> Vehicle {
        Vehicle {
            length_m: 75.0,
            roll_per_lateral_mps2: 0.015,
            sensors: vec![SensorMount {
                lever_arm_m: [-12.0, 0.0, 4.0],
                ..SensorMount::at_front("/gnss/fix")
            }],
            ..Vehicle::point()
        }
    }

    /// A straight line heading east with 150 mm of cant (left rail higher) and a rising 20 ‰.
    fn canted_line() -> TrackMap {
        let v = |s: f64| TrackVertex {
            height_m: Some(0.02 * s),
            cant_m: Some(0.15),
            ..TrackVertex::at(s, s, 0.0)
        };
        TrackMap::line(
            "t",
            GeodeticOrigin {
                latitude_deg: 45.0,
                longitude_deg: 10.0,
                altitude_m: 0.0,
            },
            vec![v(0.0), v(1000.0)],
        )
    }

    #[test]
    fn a_roof_antenna_sits_behind_the_front_end_and_leans_with_the_cant() {
        let map = canted_line();
        let pose = train().sensors[0].pose(&map, 500.0, 0.0).unwrap();
        assert_eq!(pose.track.chainage_m, 488.0);
        // 4 m up leaning by asin(0.1): 0.4 m to the right (south); tilted back by the
        // gradient's 0.02 rad, 8 cm behind the centre line's point.
        let (p, theta) = (pose.position, 0.02f64.atan());
        let up = 4.0 * 0.99f64.sqrt();
        assert!((p.x - (488.0 - up * theta.sin())).abs() < 1e-9, "{p}");
        assert!((p.y + 0.4).abs() < 1e-9, "{p}");
        assert!(
            (p.z - (0.02 * 488.0 + up * theta.cos())).abs() < 1e-9,
            "{p}"
        );
        assert_eq!(train().sensors[0].front_chainage(488.0), 500.0);
    }

    /// A fix of the roof antenna, moved by its offset, lands on the centre line's point asked
    /// for: on the map (leaning with the cant) and, without one, on a rigid straight body.
    #[test]
    fn a_measured_point_moves_to_any_point_of_the_train_by_the_offset_between_them() {
        let (map, antenna) = (canted_line(), &train().sensors[0]);
        let place = TrainPlace::Map {
            map: &map,
            front_chainage_m: 500.0,
            body_roll_rad: 0.0,
        };
        let fix = antenna.pose(&map, 500.0, 0.0).unwrap().position;
        let imu_point = map.pose_at(487.0).unwrap().position();
        assert!((fix - antenna.offset_from(place, -13.0) - imu_point).norm() < 1e-9);
        let front = fix - antenna.offset_from(place, 0.0);
        assert!((front - map.pose_at(500.0).unwrap().position()).norm() < 1e-9);
        // Heading north-east, no map: 12 m behind the front end along the heading.
        let h = std::f64::consts::FRAC_PI_4;
        let o = antenna.offset_from(TrainPlace::Straight { heading_rad: h }, 0.0);
        let back = 12.0 / 2f64.sqrt();
        assert!((o - Vector3::new(-back, -back, 4.0)).norm() < 1e-9, "{o}");
    }

    /// An IMU standing on a canted gradient, turned by its mounting: its readings in the level
    /// frame have gravity on z alone, whatever the mounting, cant and gradient.
    #[test]
    fn a_standing_imus_specific_force_in_the_level_frame_is_gravity_straight_up() {
        let map = canted_line();
        let imu = SensorMount {
            mounting_deg: [1.5, -2.0, 3.0],
            ..SensorMount::at_front("/imu")
        };
        // Standing, the body leans towards the low rail by the cant's unbalanced gravity.
        let lean = train().lean_on(&map, 300.0, 0.0);
        assert!((lean - 0.015 * 0.1 * GRAVITY_MPS2).abs() < 1e-9, "{lean}");
        let pose = imu.pose(&map, 300.0, lean).unwrap();
        let reading = pose.sensor_to_enu.inverse() * Vector3::new(0.0, 0.0, GRAVITY_MPS2);
        let level = train().level_on(&map, 300.0, 0.0);
        let f = imu.to_level(level, reading.into());
        assert!(
            (f - Vector3::new(0.0, 0.0, GRAVITY_MPS2)).norm() < 1e-9,
            "{f}"
        );
        // Without the track's attitude, the cant's and the lean's roll put gravity sideways.
        let f = imu.to_level(None, reading.into());
        assert!((f.y - (0.1 + lean) * GRAVITY_MPS2).abs() < 0.01, "{f}");
    }

    /// A train running up 35 ‰ through a cant ramp (0 to 150 mm over 60 m) on a straight: the
    /// body rolls and does not turn. The heading rate from its gyro is nil; the rate vector's
    /// vertical component is the roll rate's share `φ̇ sin θ`.
    #[test]
    fn a_cant_ramp_on_a_gradient_rolls_the_body_without_turning_it() {
        let v = |s: f64, cant: f64| TrackVertex {
            height_m: Some(0.035 * s),
            cant_m: Some(cant),
            ..TrackVertex::at(s, s, 0.0)
        };
        let map = TrackMap {
            vertices: vec![v(0.0, 0.0), v(500.0, 0.0), v(560.0, 0.15), v(1000.0, 0.15)],
            ..canted_line()
        };
        let imu = SensorMount {
            mounting_deg: [1.5, -2.0, 3.0],
            ..SensorMount::at_front("/imu")
        };
        let (speed, at) = (30.0, 530.0);
        let motion = crate::train_motion::AlongTrack {
            chainage_m: at,
            speed_mps: speed,
            acceleration_mps2: 0.0,
        };
        let m = crate::train_motion::point_motion(&map, &train(), motion, &imu, 0.01);
        // What the gyro reads: the body's rate turned into the misaligned sensor.
        let reading = imu.mounting().inverse() * m.angular_rate;
        let level = train().level_on(&map, at, speed);
        let turn = imu.heading_rate(level, reading.into());
        assert!(turn.abs() < 1e-6, "{turn} rad/s of turn on a straight");
        // The cant's roll, and the body's lean towards the low rail with it (0.015 rad per m/s²
        // of the cant's unbalanced gravity); the nose is up, a negative pitch.
        let roll_rate = (0.15f64 / 1.5).asin() / 60.0 * speed * (1.0 + 0.015 * GRAVITY_MPS2);
        let vertical = imu.to_level(level, reading.into()).z;
        let share = roll_rate * 0.035f64.atan().sin();
        assert!(
            (vertical - share).abs() < 0.02 * share,
            "{vertical} vs {share}"
        );
    }

    #[test]
    fn a_point_train_puts_every_sensor_at_the_front_end_on_the_centre_line() {
        let map = canted_line();
        let m = Vehicle::point().mount_or_front("/imu");
        let pose = m.pose(&map, 300.0, 0.0).unwrap();
        assert!((pose.position - Vector3::new(300.0, 0.0, 6.0)).norm() < 1e-9);
    }

    #[test]
    fn the_body_leans_out_of_the_curve_by_the_unbalanced_acceleration() {
        // A right-hand curve of 1 200 m at 44 m/s with 150 mm of cant: 0.63 m/s² unbalanced.
        let cant = (0.15f64 / 1.5).asin();
        let roll = train().body_roll(44.0, 1.0 / 1200.0, cant);
        let unbalanced = 44.0 * 44.0 / 1200.0 - 9.80665 * 0.1;
        assert!((roll + 0.015 * unbalanced).abs() < 1e-12);
        assert!(
            roll < 0.0,
            "leans left side down, out of a right-hand curve"
        );
    }

    #[test]
    fn sensors_off_the_train_or_turned_too_far_are_refused_by_name() {
        let mut v = train();
        v.sensors[0].lever_arm_m[0] = -80.0;
        let e = v.check().unwrap_err().to_string();
        assert!(
            e.contains("'/gnss/fix'") && e.contains("outside the train"),
            "{e}"
        );
        let mut v = train();
        v.sensors[0].lever_arm_m[0] = 1.0;
        assert!(v.check().is_err());
        let mut v = train();
        v.sensors[0].mounting_deg[2] = 90.0;
        let e = v.check().unwrap_err().to_string();
        assert!(e.contains("yaw of 90°"), "{e}");
        let mut v = train();
        v.sensors.push(v.sensors[0].clone());
        assert!(matches!(v.check(), Err(VehicleProblem::Twice(_))));
        assert!(train().check().is_ok());
    }
}
