//! The track in three dimensions: its vertical alignment (heights, gradients) and its cant,
//! read off the map's vertices, and the track's frame at a chainage ([`TrackPose`]): where the
//! centre line is and how a car body standing there is turned.
//!
//! Between two vertices the height is linear and the cant is linear (a cant ramp along a
//! transition curve is linear in the field too). The gradient is each segment's slope, blended
//! into the next one's around each vertex ([`gradient_on`]): a vertical curve sampled every
//! 10 m gives a gradient that changes smoothly, as the gravity an accelerometer sees on it
//! does, instead of in steps at every vertex.
//!
//! Chainage is measured in the plane (the alignment's kilometrage, as maps give it); the rail
//! is longer by `√(1 + G²)` per metre on a gradient `G` (0.06 % on 35 ‰), which wheels and
//! a Doppler radar measure ([`TrackPose::rail_per_chainage`]).
//!
//! A map without heights is flat and one without cant has none: every function here then
//! gives the flat line's answer.

use nalgebra::{Rotation3, Vector3};

use crate::messages::{TrackMap, TrackVertex};

/// The distance cant is measured over when a map does not say: standard gauge's 1 500 mm
/// between the rails' running circles.
pub const STANDARD_CANT_BASE_M: f64 = 1.5;
/// Steeper than any line adhesion trains run on (the steepest main lines are under 60 ‰):
/// a map steeper than this is wrong.
pub const MAX_GRADIENT: f64 = 0.100;
/// More than any line's cant (160–180 mm is the most on high-speed lines): a map with more is
/// wrong.
pub const MAX_CANT_M: f64 = 0.200;

/// The track's frame at a chainage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPose {
    pub chainage_m: f64,
    pub east_m: f64,
    pub north_m: f64,
    /// Top of rail on the centre line, m up in the local frame.
    pub up_m: f64,
    /// Clockwise from north, rad.
    pub heading_rad: f64,
    /// Rise per metre of chainage, positive uphill towards increasing chainage (35 ‰: 0.035).
    pub gradient: f64,
    /// The cant's roll of the track, rad, positive with the left rail higher.
    pub cant_rad: f64,
}

impl TrackPose {
    /// A flat track's frame at (east, north) heading `heading_rad`.
    pub fn flat(chainage_m: f64, east_m: f64, north_m: f64, heading_rad: f64) -> TrackPose {
        TrackPose {
            chainage_m,
            east_m,
            north_m,
            up_m: 0.0,
            heading_rad,
            gradient: 0.0,
            cant_rad: 0.0,
        }
    }

    /// The centre line's point, local east/north/up, m.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::new(self.east_m, self.north_m, self.up_m)
    }

    /// The rotation from a car body standing here (x forward towards increasing chainage, y
    /// left, z up) to local east/north/up, the body rolled `body_roll_rad` further than the
    /// cant (its suspension's lean, positive with the left side up).
    ///
    /// `R = Rz(π/2 − ψ) · Ry(−atan G) · Rx(φ_cant + φ_body)`: yaw from the heading ψ (clockwise
    /// from north, so east-north-up's yaw is π/2 − ψ), the nose up on a rising gradient
    /// (a negative rotation about the left axis), then the roll.
    pub fn body_to_enu(&self, body_roll_rad: f64) -> Rotation3<f64> {
        Rotation3::from_euler_angles(
            self.cant_rad + body_roll_rad,
            -self.gradient.atan(),
            std::f64::consts::FRAC_PI_2 - self.heading_rad,
        )
    }

    /// The rotation from a car body standing here to the level frame that turns with it (x
    /// forward and y left in the horizontal plane, z up): [`Self::body_to_enu`] without the
    /// heading, `Ry(−atan G) · Rx(φ_cant + φ_body)`. A reading turned so has gravity on z
    /// alone and the train's horizontal acceleration and turn rate on x, y and z.
    pub fn body_to_level(&self, body_roll_rad: f64) -> Rotation3<f64> {
        Rotation3::from_euler_angles(self.cant_rad + body_roll_rad, -self.gradient.atan(), 0.0)
    }

    /// Metres of rail per metre of chainage, `√(1 + G²)`: what a wheel rolls and a radar sees
    /// beyond the chainage's rate.
    pub fn rail_per_chainage(&self) -> f64 {
        (1.0 + self.gradient * self.gradient).sqrt()
    }

    /// Gravity's component along the track, m/s² per m/s² of g: what an accelerometer
    /// aligned with the rails reads at rest, `sin(atan G)`.
    pub fn along_track_gravity(&self) -> f64 {
        let pitch = self.gradient.atan();
        pitch.sin()
    }
}

impl TrackMap {
    /// Whether the main line has heights (then every vertex has one: [`TrackMap::check`]).
    pub fn has_heights(&self) -> bool {
        self.vertices.iter().any(|v| v.height_m.is_some())
    }

    /// Whether the main line has cant anywhere.
    pub fn has_cant(&self) -> bool {
        self.vertices
            .iter()
            .any(|v| v.cant_m.is_some_and(|c| c != 0.0))
    }

    /// The distance cant is measured over, m.
    pub fn cant_base(&self) -> f64 {
        self.cant_base_m.unwrap_or(STANDARD_CANT_BASE_M)
    }

    /// The main line's frame at a chainage (clamped to its ends); None for a map of fewer than
    /// two vertices.
    pub fn pose_at(&self, chainage_m: f64) -> Option<TrackPose> {
        pose_on(&self.vertices, self.cant_base(), chainage_m)
    }

    /// Height of the main line's top of rail at a chainage, m (0 on a map without heights).
    pub fn height_at(&self, chainage_m: f64) -> f64 {
        self.pose_at(chainage_m).map_or(0.0, |p| p.up_m)
    }

    /// The main line's gradient at a chainage (rise per metre; 0 on a map without heights).
    pub fn gradient_at(&self, chainage_m: f64) -> f64 {
        self.pose_at(chainage_m).map_or(0.0, |p| p.gradient)
    }

    /// The main line's cant at a chainage, m (0 where the map has none).
    pub fn cant_at(&self, chainage_m: f64) -> f64 {
        let v = &self.vertices;
        match span(v, chainage_m) {
            Some((i, f)) => lerp(cant(&v[i - 1]), cant(&v[i]), f),
            None => 0.0,
        }
    }
}

/// A track's frame at a chainage, from its vertices.
pub fn pose_on(v: &[TrackVertex], cant_base_m: f64, chainage_m: f64) -> Option<TrackPose> {
    let (east_m, north_m, heading_rad) = plane_on(v, chainage_m)?;
    let (i, f) = span(v, chainage_m)?;
    let (a, b) = (&v[i - 1], &v[i]);
    let up_m = lerp(a.height_m.unwrap_or(0.0), b.height_m.unwrap_or(0.0), f);
    let gradient = gradient_on(v, i, f);
    let cant_m = lerp(cant(a), cant(b), f);
    Some(TrackPose {
        chainage_m,
        east_m,
        north_m,
        up_m,
        heading_rad,
        gradient,
        cant_rad: (cant_m / cant_base_m).clamp(-1.0, 1.0).asin(),
    })
}

/// East, north and heading (clockwise from north) of a track at a chainage, interpolated
/// along its polyline; clamped to the ends.
pub(crate) fn plane_on(v: &[TrackVertex], chainage_m: f64) -> Option<(f64, f64, f64)> {
    let (i, f) = span(v, chainage_m)?;
    let (a, b) = (&v[i - 1], &v[i]);
    let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
    Some((a.east_m + f * de, a.north_m + f * dn, de.atan2(dn)))
}

/// A heading that turns smoothly along a polyline, and its rate (curvature, 1/m, positive
/// turning clockwise): each segment's heading holds at its middle and turns linearly to the
/// next one's. A polyline's own heading jumps at every vertex, which a rate or a second
/// derivative (an IMU's yaw rate, a lever arm's acceleration) cannot be taken from.
pub fn turning_heading_on(v: &[TrackVertex], chainage_m: f64) -> Option<(f64, f64)> {
    let (i, _) = span(v, chainage_m)?;
    let heading = |k: usize| {
        let (a, b) = (&v[k - 1], &v[k]);
        (b.east_m - a.east_m).atan2(b.north_m - a.north_m)
    };
    let middle = |k: usize| 0.5 * (v[k - 1].chainage_m + v[k].chainage_m);
    let (j, k) = match chainage_m < middle(i) {
        true if i > 1 => (i - 1, i),
        false if i + 1 < v.len() => (i, i + 1),
        _ => return Some((heading(i), 0.0)),
    };
    let length = middle(k) - middle(j);
    if length <= 0.0 {
        return Some((heading(i), 0.0));
    }
    let turn = (heading(k) - heading(j) + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    let f = ((chainage_m - middle(j)) / length).clamp(0.0, 1.0);
    Some((heading(j) + f * turn, turn / length))
}

fn cant(v: &TrackVertex) -> f64 {
    v.cant_m.unwrap_or(0.0)
}

fn lerp(a: f64, b: f64, f: f64) -> f64 {
    a + f * (b - a)
}

/// The segment a chainage lies on (its end vertex's index, at least 1) and how far along it
/// (0 to 1, clamped at the line's ends).
fn span(v: &[TrackVertex], chainage_m: f64) -> Option<(usize, f64)> {
    if v.len() < 2 {
        return None;
    }
    let i = v
        .partition_point(|p| p.chainage_m <= chainage_m)
        .clamp(1, v.len() - 1);
    let len = v[i].chainage_m - v[i - 1].chainage_m;
    let f = match len > 0.0 {
        true => ((chainage_m - v[i - 1].chainage_m) / len).clamp(0.0, 1.0),
        false => 0.0,
    };
    Some((i, f))
}

/// The slope of segment `i` (from vertex `i` to `i + 1`) and its length.
fn segment_slope(v: &[TrackVertex], i: usize) -> (f64, f64) {
    let d = v[i + 1].chainage_m - v[i].chainage_m;
    let rise = v[i + 1].height_m.unwrap_or(0.0) - v[i].height_m.unwrap_or(0.0);
    (if d > 0.0 { rise / d } else { 0.0 }, d)
}

/// The gradient on segment `i − 1 .. i`, `f` of the way along it: the segment's slope, blended
/// linearly into its neighbour's over half the shorter segment's length either side of each
/// inner vertex. The blend takes as much rise as it gives, so the gradient integrates to the
/// map's heights; and on a vertical curve sampled evenly the gradient is linear between the
/// segments' midpoints, where each segment's slope is the parabola's exactly.
fn gradient_on(v: &[TrackVertex], i: usize, f: f64) -> f64 {
    let (m, d) = segment_slope(v, i - 1);
    let x = f * d;
    if i >= 2 {
        let (m0, d0) = segment_slope(v, i - 2);
        let w = d0.min(d) / 2.0;
        if x < w {
            return m0 + (m - m0) * (0.5 + x / (2.0 * w));
        }
    }
    if i + 1 < v.len() {
        let (m1, d1) = segment_slope(v, i);
        let w = d1.min(d) / 2.0;
        if d - x < w {
            return m + (m1 - m) * (0.5 - (d - x) / (2.0 * w));
        }
    }
    m
}

/// What is wrong with a track's heights or cant, if anything: heights on some vertices but
/// not all, a gradient over [`MAX_GRADIENT`], a cant over [`MAX_CANT_M`] or not finite.
pub fn profile_problem(v: &[TrackVertex]) -> Option<ProfileProblem> {
    let with = v.iter().filter(|p| p.height_m.is_some()).count();
    if with > 0 && with < v.len() {
        let index = v.iter().position(|p| p.height_m.is_none()).unwrap_or(0);
        return Some(ProfileProblem::HeightMissing {
            index,
            chainage_m: v[index].chainage_m,
        });
    }
    if let Some(i) = v.iter().position(|p| {
        !p.height_m.is_none_or(f64::is_finite) || !p.cant_m.is_none_or(f64::is_finite)
    }) {
        return Some(ProfileProblem::NotFinite { index: i });
    }
    if let Some(p) = v.iter().find(|p| cant(p).abs() > MAX_CANT_M) {
        return Some(ProfileProblem::Cant {
            chainage_m: p.chainage_m,
            cant_mm: cant(p) * 1e3,
        });
    }
    (0..v.len().saturating_sub(1))
        .map(|i| (i, segment_slope(v, i).0))
        .find(|(_, g)| g.abs() > MAX_GRADIENT)
        .map(|(i, g)| ProfileProblem::Gradient {
            from_m: v[i].chainage_m,
            to_m: v[i + 1].chainage_m,
            permille: g * 1e3,
        })
}

/// Why a track's heights or cant were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileProblem {
    #[error("vertex {index} (chainage {chainage_m:.1} m) has no height while others have one")]
    HeightMissing { index: usize, chainage_m: f64 },
    #[error("vertex {index}'s height or cant is not a finite number")]
    NotFinite { index: usize },
    #[error(
        "a gradient of {permille:.1} ‰ between chainage {from_m:.1} m and {to_m:.1} m, over the \
         100 ‰ no adhesion railway has (heights in feet, or a wrong vertex?)"
    )]
    Gradient {
        from_m: f64,
        to_m: f64,
        permille: f64,
    },
    #[error(
        "a cant of {cant_mm:.0} mm at chainage {chainage_m:.1} m, over the 200 mm no track has \
         (cant in mm where metres are meant?)"
    )]
    Cant { chainage_m: f64, cant_mm: f64 },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geodesy::GeodeticOrigin;

    fn vertex(s: f64, h: f64, cant_m: f64) -> TrackVertex {
        TrackVertex {
            height_m: Some(h),
            cant_m: Some(cant_m),
            ..TrackVertex::at(s, s, 0.0)
        }
    }

    fn map(v: Vec<TrackVertex>) -> TrackMap {
        TrackMap::line(
            "t",
            GeodeticOrigin {
                latitude_deg: 45.0,
                longitude_deg: 10.0,
                altitude_m: 0.0,
            },
            v,
        )
    }

    #[test]
    fn a_vertical_curve_sampled_every_ten_metres_gives_a_smooth_gradient() {
        // From level to 20 ‰ on a vertical curve of 2 500 m: G = (s − 100)/2 500 on 100..150.
        let mut v = vec![vertex(0.0, 0.0, 0.0)];
        for k in 0..=5 {
            let x = 10.0 * k as f64;
            v.push(vertex(100.0 + x, x * x / 5000.0, 0.0));
        }
        v.push(vertex(1000.0, 50.0 * 50.0 / 5000.0 + 850.0 * 0.02, 0.0));
        let m = map(v);
        assert!(m.has_heights());
        for s in [110.0, 125.0, 140.0] {
            let exact = (s - 100.0) / 2500.0;
            assert!((m.gradient_at(s) - exact).abs() < 3e-4, "{s}");
        }
        assert!((m.gradient_at(600.0) - 0.02).abs() < 1e-9);
        assert!((m.height_at(1000.0) - 17.5).abs() < 1e-9);
        assert!(profile_problem(&m.vertices).is_none());
    }

    #[test]
    fn the_body_frame_noses_up_on_a_rising_gradient_and_leans_with_the_cant() {
        // Heading east, rising 35 ‰, 150 mm of cant (left rail higher).
        let p = TrackPose {
            gradient: 0.035,
            cant_rad: (0.15f64 / 1.5).asin(),
            ..TrackPose::flat(0.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2)
        };
        let r = p.body_to_enu(0.0);
        let forward = r * Vector3::x();
        assert!((forward.x - 0.035f64.atan().cos()).abs() < 1e-12);
        assert!(forward.y.abs() < 1e-12 && (forward.z - 0.035f64.atan().sin()).abs() < 1e-12);
        // Left is north; with the left rail higher the left axis points up a little.
        let left = r * Vector3::y();
        assert!(left.y > 0.99 && (left.z - 0.1).abs() < 1e-3, "{left}");
        // At rest an accelerometer reads gravity's reaction in the body: g sin θ forward.
        let f = r.inverse() * Vector3::new(0.0, 0.0, 9.80665);
        assert!((f.x - 9.80665 * p.along_track_gravity()).abs() < 1e-12);
        assert!((f.x - 0.3431).abs() < 1e-3, "{f}");
        // Towards the high side, the rail that the centripetal force of a curve taken at speed
        // pushes away from.
        assert!((f.y - 0.98).abs() < 0.01, "{f}");
    }

    #[test]
    fn steep_gradients_large_cant_and_half_heighted_maps_are_refused() {
        let steep = vec![vertex(0.0, 0.0, 0.0), vertex(100.0, 12.0, 0.0)];
        let e = profile_problem(&steep).unwrap();
        assert!(e.to_string().contains("120.0 ‰"), "{e}");
        let canted = vec![vertex(0.0, 0.0, 0.0), vertex(100.0, 0.0, 160.0)];
        let e = profile_problem(&canted).unwrap();
        assert!(e.to_string().contains("160000 mm"), "{e}");
        let mut half = vec![vertex(0.0, 0.0, 0.0), vertex(100.0, 1.0, 0.0)];
        half[1].height_m = None;
        assert!(matches!(
            profile_problem(&half),
            Some(ProfileProblem::HeightMissing { index: 1, .. })
        ));
        let flat = vec![
            TrackVertex::at(0.0, 0.0, 0.0),
            TrackVertex::at(9.0, 9.0, 0.0),
        ];
        assert!(profile_problem(&flat).is_none());
        assert_eq!(map(flat).gradient_at(3.0), 0.0);
    }
}
