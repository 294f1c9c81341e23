//! How a point on the train moves when the train runs along the track: position, velocity,
//! specific force and angular rate at a sensor's place, from the track's geometry, the
//! along-track motion of the front end and the sensor's [`SensorMount`]. The simulator makes
//! its sensors' truth with it (on the track's exact geometry), and the mounting calibration
//! predicts what an IMU should read with it (on the track map): one model of the train for
//! both.
//!
//! The centre line's point at the sensor's chainage `s` moves with `ṡ = v` along the track:
//! velocity `v T` with `T = (sin ψ, cos ψ, G)` (chainage is measured in the plane, so `T` is a
//! little longer than 1 on a gradient), acceleration `a T + v² (κ cos ψ, −κ sin ψ, G')`. The
//! lever arm across the track, `(0, y, z)` in the body, turns with the body: its velocity and
//! acceleration are the body rotation's, taken by central differences of the rotation half a
//! span either side. Specific force is `Rᵀ (acc + g ẑ)` in the body; the body's rate is
//! `Ω× = Rᵀ Ṙ`.
//!
//! The span is what the motion is averaged over: [`INSTANT_S`] for the motion at an instant on
//! a smooth track (the simulator's), the length of a bin of readings for their mean (the
//! calibration's, on a map whose cant and curvature have kinks at its vertices: over a bin the
//! differences give the mean of the lever arm's acceleration, bounded, where an instant's would
//! jump at every kink).

use nalgebra::{Rotation3, Vector3};

use crate::messages::{SensorMount, TrackMap, Vehicle};
use crate::track_profile::{turning_heading_on, TrackPose};
use crate::vehicle::GRAVITY_MPS2;

/// A track's geometry at a chainage: what the motion of a point on the train follows.
pub trait TrackGeometry {
    /// The track's frame at `chainage_m`.
    fn pose(&self, chainage_m: f64) -> TrackPose;
    /// Horizontal curvature, 1/m, positive turning right (clockwise).
    fn curvature(&self, chainage_m: f64) -> f64;
    /// The gradient's rate of change per metre of chainage, 1/m (positive in a sag).
    fn vertical_curvature(&self, chainage_m: f64) -> f64;
}

/// The half span over which a map's curvatures are taken, m: long beside the survey's vertex
/// spacing, short beside a transition or a vertical curve.
const MAP_CURVATURE_HALF_SPAN_M: f64 = 10.0;

/// The map's polyline, its heading turning smoothly between segments
/// ([`turning_heading_on`]): what a rate can be taken from.
impl TrackGeometry for TrackMap {
    fn pose(&self, chainage_m: f64) -> TrackPose {
        let Some(mut pose) = self.pose_at(chainage_m) else {
            return TrackPose::flat(chainage_m, 0.0, 0.0, 0.0);
        };
        if let Some((heading, _)) = turning_heading_on(&self.vertices, chainage_m) {
            pose.heading_rad = heading;
        }
        pose
    }

    /// The turning heading's mean rate over the span either side: continuous, as the body's
    /// lean that follows it must be (a lean that jumped would shake the lever arms).
    fn curvature(&self, chainage_m: f64) -> f64 {
        let h = MAP_CURVATURE_HALF_SPAN_M;
        let heading = |s: f64| turning_heading_on(&self.vertices, s).map_or(0.0, |(h, _)| h);
        let turn = heading(chainage_m + h) - heading(chainage_m - h);
        let turn =
            (turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        turn / (2.0 * h)
    }

    fn vertical_curvature(&self, chainage_m: f64) -> f64 {
        let h = MAP_CURVATURE_HALF_SPAN_M;
        (self.gradient_at(chainage_m + h) - self.gradient_at(chainage_m - h)) / (2.0 * h)
    }
}

/// The body's lean and attitude on a map, for the pipelines without an attitude of their own.
impl Vehicle {
    /// The body's lean where the point `chainage_m` of `map` is, at `speed_mps`: from the
    /// map's curvature and cant ([`Self::body_roll`]).
    pub fn lean_on(&self, map: &TrackMap, chainage_m: f64, speed_mps: f64) -> f64 {
        if self.roll_per_lateral_mps2 == 0.0 {
            return 0.0;
        }
        let cant = map.pose_at(chainage_m).map_or(0.0, |p| p.cant_rad);
        self.body_roll(speed_mps, map.curvature(chainage_m), cant)
    }

    /// The rotation from the body to the level frame at the point `chainage_m` of `map`, the
    /// train at `speed_mps` ([`TrackPose::body_to_level`] with the body's lean).
    pub fn level_on(
        &self,
        map: &TrackMap,
        chainage_m: f64,
        speed_mps: f64,
    ) -> Option<Rotation3<f64>> {
        let pose = map.pose_at(chainage_m)?;
        Some(pose.body_to_level(self.lean_on(map, chainage_m, speed_mps)))
    }
}

/// The front end's motion along the track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlongTrack {
    pub chainage_m: f64,
    /// The chainage's rate, m/s.
    pub speed_mps: f64,
    pub acceleration_mps2: f64,
}

/// One point's motion on the train: specific force and rate in the body's axes (x forward,
/// y left, z up), or a sensor's own where its mounting has turned them (the simulator's).
#[derive(Debug, Clone, Copy)]
pub struct PointMotion {
    /// The chainage of the point's place on the track.
    pub chainage_m: f64,
    /// Local east/north/up, m.
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    /// In the body's axes, m/s².
    pub specific_force: Vector3<f64>,
    /// In the body's axes, rad/s.
    pub angular_rate: Vector3<f64>,
    /// Speed along the rail at the point's place (what a wheel rolls), m/s.
    pub rail_speed_mps: f64,
    /// The body's rotation to east/north/up there.
    pub body_to_enu: Rotation3<f64>,
}

/// The span of an instant's motion, s: smooth, small numbers, no cancellation.
pub const INSTANT_S: f64 = 0.01;

/// The body's rotation to east/north/up at time offset `tau`, for the place `along` metres of
/// chainage from the front end.
fn body_to_enu(
    track: &impl TrackGeometry,
    vehicle: &Vehicle,
    m: AlongTrack,
    along: f64,
    tau: f64,
) -> Rotation3<f64> {
    let s = m.chainage_m + along + m.speed_mps * tau + 0.5 * m.acceleration_mps2 * tau * tau;
    let v = m.speed_mps + m.acceleration_mps2 * tau;
    let pose = track.pose(s);
    let roll = vehicle.body_roll(v, track.curvature(s), pose.cant_rad);
    pose.body_to_enu(roll)
}

/// The motion of the point at `mount`'s lever arm, the train's front end moving as `m`,
/// averaged over `span_s` around now (its rates and the lever arm's acceleration).
pub fn point_motion(
    track: &impl TrackGeometry,
    vehicle: &Vehicle,
    m: AlongTrack,
    mount: &SensorMount,
    span_s: f64,
) -> PointMotion {
    let h = 0.5 * span_s;
    let along = mount.lever_arm_m[0];
    let s = m.chainage_m + along;
    let pose = track.pose(s);
    let (v, a) = (m.speed_mps, m.acceleration_mps2);
    let (kappa, psi, g) = (track.curvature(s), pose.heading_rad, pose.gradient);
    let tangent = Vector3::new(psi.sin(), psi.cos(), g);
    let bend = Vector3::new(
        kappa * psi.cos(),
        -kappa * psi.sin(),
        track.vertical_curvature(s),
    );
    let centre_acceleration = a * tangent + v * v * bend;
    let [before, now, after] = [-h, 0.0, h].map(|tau| body_to_enu(track, vehicle, m, along, tau));
    let across = Vector3::new(0.0, mount.lever_arm_m[1], mount.lever_arm_m[2]);
    let (r0, r1, r2) = (before * across, now * across, after * across);
    let lever_velocity = (r2 - r0) / (2.0 * h);
    let lever_acceleration = (r2 - 2.0 * r1 + r0) / (h * h);
    let omega = now.matrix().transpose() * (after.matrix() - before.matrix()) / (2.0 * h);
    PointMotion {
        chainage_m: s,
        position: pose.position() + r1,
        velocity: v * tangent + lever_velocity,
        specific_force: now.inverse()
            * (centre_acceleration + lever_acceleration + Vector3::new(0.0, 0.0, GRAVITY_MPS2)),
        angular_rate: Vector3::new(omega[(2, 1)], omega[(0, 2)], omega[(1, 0)]),
        rail_speed_mps: v * pose.rail_per_chainage(),
        body_to_enu: now,
    }
}
