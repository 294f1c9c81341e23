//! Where the GNSS/INS pipeline's points are on the train (the catalogue's
//! [`Vehicle`](railfuse_catalog::messages::Vehicle): each sensor's lever arm and mounting).
//!
//! - **The navigation point** is the centre line's point at the IMU's place, `x_imu` behind
//!   the front end: the point whose motion the IMU's readings integrate to. The track
//!   constraint holds there (it is on the centre line) and the non-holonomic one too (every
//!   point of a train on its rails moves along them).
//! - **A fix** is the antenna's: before it is fused it is moved to the navigation point by
//!   the offset between them ([`SensorMount::offset_from`]): on the map each at its own
//!   place on the track, the roof antenna leaning in with the cant and the body's roll; with
//!   no map, a rigid straight body at the navigation's heading. The antenna's extra velocity
//!   from the body's turn (`ω × l`, 0.01 m/s for the half metre between a roof antenna and
//!   an IMU under it on a 1 km curve at 30 m/s) is left in the fix's noise.
//! - **The IMU's readings** are turned into the body by its mounting and into the level frame
//!   by the map's gradient, cant and the body's lean where the navigation point is
//!   ([`SensorMount::to_level`], [`SensorMount::heading_rate`]): the planar navigation then
//!   sees the horizontal acceleration and the heading's turn, as on a flat line (map-aided:
//!   the pipeline has no attitude of its own; without a map only the mounting is taken out).
//!   Through a GNSS loss the map is looked up where the gyro's roll puts the cant ramps
//!   ([`GyroTilt`](crate::tilt::GyroTilt)), not at the drifting chainage.
//! - **The output** is the front end's: the navigation point moved forward by `−x_imu` along
//!   the track (on the map) or the heading, its covariance with the heading error's share of
//!   that lever arm; its velocity and heading the navigation's turned by the track's turn
//!   between the two points (on a curve the front end moves in another direction).

use nalgebra::{SMatrix, Vector3};
use railfuse_catalog::messages::{Imu, SensorMount, TrackMap};
use railfuse_catalog::vehicle::TrainPlace;

use super::error_state::{DIM, E, N, PSI};
use super::planar_ins::Navigation;
use super::GnssInsPipeline;
use crate::measurement::SensorContext;

impl GnssInsPipeline {
    fn mount<'c>(&self, ctx: &'c SensorContext, sensor: usize) -> Option<&'c SensorMount> {
        ctx.vehicle.mount(self.topic(sensor))
    }

    /// The navigation point's place along the body: the IMU's lever arm's x, m (≤ 0).
    pub(super) fn nav_x(&self, ctx: &SensorContext) -> f64 {
        self.mount(ctx, self.roles.imu)
            .map_or(0.0, |m| m.lever_arm_m[0])
    }

    /// The navigation point's chainage on the map's main line, as last matched (before the
    /// navigation starts: the last fix's).
    pub(super) fn nav_chainage(&self) -> Option<f64> {
        match (self.nav, self.matcher.last()) {
            (Some(_), Some((0, s))) => Some(s),
            _ => self.fix_chainage_m,
        }
    }

    /// Where the train stands: on the map with the front end at the navigation point's
    /// chainage less `x_imu`, or on a straight at `heading_rad`.
    fn place<'m>(&self, ctx: &'m SensorContext, heading_rad: f64) -> TrainPlace<'m> {
        let front = self.nav_chainage().map(|s| s - self.nav_x(ctx));
        let speed = self.nav.map_or(0.0, |n| n.speed_mps);
        ctx.place(ctx.track.as_ref(), front, speed, heading_rad)
    }

    /// A fix of the antenna at (east, north), moved to the navigation point. Before the
    /// navigation has a chainage the fix's own place on the map is taken (and kept for the
    /// IMU's readings).
    pub(super) fn antenna_to_nav(
        &mut self,
        ctx: &SensorContext,
        (e, n): (f64, f64),
        course_rad: Option<f64>,
    ) -> (f64, f64) {
        let (gnss, nav_x) = (self.topic(self.roles.gnss).to_owned(), self.nav_x(ctx));
        if self.nav.is_none() {
            self.fix_chainage_m = ctx.track.as_ref().and_then(|map| {
                let front = ctx.front_chainage_of_measured(map, &gnss, (e, n))?;
                Some(front + nav_x)
            });
        }
        let heading = self
            .nav
            .map(|v| v.heading_rad)
            .or(course_rad)
            .unwrap_or(0.0);
        ctx.move_measured(&gnss, (e, n), self.place(ctx, heading), nav_x)
    }

    /// The IMU's reading as the planar navigation takes it: forward and lateral specific
    /// force and the rate about the vertical, in the level frame where the navigation point
    /// is.
    pub(super) fn level_reading(&mut self, ctx: &SensorContext, m: &Imu) -> ([f64; 2], f64) {
        let mount = self.mount(ctx, self.roles.imu);
        let level = match (ctx.track.as_ref(), self.nav_chainage()) {
            (Some(map), Some(s)) => {
                let speed = self.nav.map_or(0.0, |n| n.speed_mps);
                let rate = Vector3::from(m.angular_rate_radps);
                let rate = mount.map_or(rate, |mount| mount.mounting() * rate);
                let level_at = |shift: f64| ctx.vehicle.level_on(map, s + shift, speed);
                self.tilt.level(m.stamp_ns, level_at, rate, self.in_loss)
            }
            _ => None,
        };
        if mount.is_none() && level.is_none() {
            let (f, w) = (m.specific_force_mps2, m.angular_rate_radps);
            return ([f[0], f[1]], w[2]);
        }
        // Borrowed: this runs for every IMU sample (200 a second).
        let at_front;
        let mount = match mount {
            Some(mount) => mount,
            None => {
                at_front = SensorMount::at_front(self.topic(self.roles.imu));
                &at_front
            }
        };
        let f = mount.to_level(level, m.specific_force_mps2);
        ([f.x, f.y], mount.heading_rate(level, m.angular_rate_radps))
    }

    /// The front end's chainage (the navigation point's, matched on `map`, plus `−x_imu`; the
    /// distance run without a map) and its place in the plane with the covariance rows: the
    /// navigation point's plus the lever arm turned by the heading error.
    pub(super) fn front_end(
        &mut self,
        ctx: &SensorContext,
        nav: &Navigation,
        map: Option<&TrackMap>,
    ) -> FrontEnd {
        let nav_x = self.nav_x(ctx);
        let matched = map.and_then(|m| self.matcher.match_point(m, nav.east_m, nav.north_m, None));
        let chainage_m = matched.map_or(self.distance_m, |m| m.chainage_m) - nav_x;
        // The track turns between the navigation point and the front end (13 m on a 900 m
        // curve: 0.8°), and the front end moves along the track where it is.
        let heading = |s: f64| map.and_then(|m| m.pose_at(s)).map(|p| p.heading_rad);
        let turn_rad = match (
            matched.and_then(|m| heading(m.chainage_m)),
            heading(chainage_m),
        ) {
            (Some(at_nav), Some(at_front)) => super::constraints::wrap(at_front - at_nav),
            _ => 0.0,
        };
        let front = SensorMount::at_front("");
        let offset = front.offset_from(self.place(ctx, nav.heading_rad), nav_x);
        // ∂(the lever arm along the heading)/∂ψ: forward (sin ψ, cos ψ) turns to (cos ψ, −sin ψ).
        let (s, c) = nav.heading_rad.sin_cos();
        let mut rows = SMatrix::<f64, 2, DIM>::zeros();
        rows[(0, E)] = 1.0;
        rows[(1, N)] = 1.0;
        rows[(0, PSI)] = -nav_x * c;
        rows[(1, PSI)] = nav_x * s;
        FrontEnd {
            chainage_m,
            east_m: nav.east_m + offset.x,
            north_m: nav.north_m + offset.y,
            rows,
            turn_rad,
        }
    }
}

/// The front end as the output gives it.
pub(super) struct FrontEnd {
    pub chainage_m: f64,
    pub east_m: f64,
    pub north_m: f64,
    /// Its (east, north) error in terms of the error state's.
    pub rows: SMatrix<f64, 2, DIM>,
    /// How far the track's heading at the front end is turned from the navigation point's,
    /// clockwise, rad (0 without a map: a rigid straight body): the front end's velocity and
    /// heading are the navigation's turned by it.
    pub turn_rad: f64,
}

impl FrontEnd {
    /// The front end's velocity (east, north) and its covariance, from the navigation
    /// point's: turned by [`FrontEnd::turn_rad`] (every point of a train on its rails has
    /// the same speed along them).
    pub fn velocity(
        &self,
        (ve, vn): (f64, f64),
        covariance: SMatrix<f64, 2, 2>,
    ) -> ((f64, f64), SMatrix<f64, 2, 2>) {
        // A heading clockwise from north: v (sin ψ, cos ψ) turned to v (sin(ψ+Δ), cos(ψ+Δ)).
        let (s, c) = self.turn_rad.sin_cos();
        let j = SMatrix::<f64, 2, 2>::new(c, s, -s, c);
        (
            (c * ve + s * vn, c * vn - s * ve),
            j * covariance * j.transpose(),
        )
    }
}
