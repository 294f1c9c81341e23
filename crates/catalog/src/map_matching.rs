//! Map matching: where a position in the local east/north plane lies on a [`TrackMap`]
//! (which track, the chainage, the signed lateral offset, the heading), and the map's own
//! sanity checks (enough vertices, finite coordinates, chainage increasing, no
//! self-intersection).
//!
//! A point is matched to the nearest point of a track's centre line. Along a run,
//! [`MapMatcher`] keeps to the track it matched last and searches only a window of chainage
//! around the expected position: a fix pulled a few metres sideways by multipath near a
//! station is then reported as a large lateral offset from the train's own track, not as a
//! jump to the parallel track beside it (trains change tracks at turnouts, which a fix alone
//! cannot tell from an error).
//!
//! Conventions: heading clockwise from north (`atan2(Δe, Δn)`), lateral offset positive to
//! the right of the direction of increasing chainage.

use std::ops::Range;

use crate::messages::{TrackMap, TrackVertex};

/// Where a point lies relative to one track of the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapMatch {
    /// 0 the main line, `i` the map's `other_tracks[i - 1]`.
    pub track: usize,
    pub chainage_m: f64,
    /// Signed distance of the point from the centre line, positive to the right of the
    /// direction of increasing chainage.
    pub lateral_m: f64,
    /// Heading of the track there, clockwise from north.
    pub heading_rad: f64,
    /// The matched point on the centre line.
    pub east_m: f64,
    pub north_m: f64,
    /// Index of the segment (vertices `segment`, `segment + 1`) it lies on.
    pub segment: usize,
    /// The point lies beyond an end of the track (its match is the end vertex): it is not
    /// beside this track at all.
    pub beyond_end: bool,
}

/// The nearest point to (east, north) on the segments of `vertices` that start in `segments`
/// (segment `i` joins vertices `i` and `i + 1`); the first of equally near ones. `track` is
/// left 0.
pub fn nearest_on(
    vertices: &[TrackVertex],
    segments: Range<usize>,
    east_m: f64,
    north_m: f64,
) -> Option<MapMatch> {
    let end = segments.end.min(vertices.len().saturating_sub(1));
    // The nearest segment and the fraction along it; heading and offset only for that one.
    let mut best: Option<(f64, usize, f64)> = None;
    for i in segments.start..end {
        let (a, b) = (vertices[i], vertices[i + 1]);
        let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
        let len2 = de * de + dn * dn;
        let f = if len2 > 0.0 {
            (((east_m - a.east_m) * de + (north_m - a.north_m) * dn) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (pe, pn) = (a.east_m + f * de, a.north_m + f * dn);
        let d2 = (east_m - pe).powi(2) + (north_m - pn).powi(2);
        if best.is_none_or(|(bd, _, _)| d2 < bd) {
            best = Some((d2, i, f));
        }
    }
    let (_, i, f) = best?;
    let (a, b) = (vertices[i], vertices[i + 1]);
    let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
    let (pe, pn) = (a.east_m + f * de, a.north_m + f * dn);
    let heading = de.atan2(dn);
    // Right of the track direction (sin h, cos h) is (cos h, −sin h).
    let (sin, cos) = heading.sin_cos();
    Some(MapMatch {
        track: 0,
        chainage_m: a.chainage_m + f * (b.chainage_m - a.chainage_m),
        lateral_m: (east_m - pe) * cos - (north_m - pn) * sin,
        heading_rad: heading,
        east_m: pe,
        north_m: pn,
        segment: i,
        beyond_end: (i == 0 && f <= 0.0) || (i + 2 == vertices.len() && f >= 1.0),
    })
}

/// East, north and heading of a track at a chainage, interpolated along its polyline;
/// clamped to the ends.
pub fn locate_on(vertices: &[TrackVertex], chainage_m: f64) -> Option<(f64, f64, f64)> {
    crate::track_profile::plane_on(vertices, chainage_m)
}

/// Curvature of a track at a chainage (1/m, positive turning right, clockwise): the change of
/// heading over `half_span_m` either side, divided by the distance. Zero on a straight.
pub fn curvature_on(vertices: &[TrackVertex], chainage_m: f64, half_span_m: f64) -> f64 {
    let (Some((_, _, h0)), Some((_, _, h1))) = (
        locate_on(vertices, chainage_m - half_span_m),
        locate_on(vertices, chainage_m + half_span_m),
    ) else {
        return 0.0;
    };
    let turn =
        (h1 - h0 + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    turn / (2.0 * half_span_m)
}

/// The segments of `vertices` whose chainage span meets `[from, to]`.
fn segments_between(vertices: &[TrackVertex], from_m: f64, to_m: f64) -> Range<usize> {
    let start = vertices
        .partition_point(|v| v.chainage_m < from_m)
        .saturating_sub(1);
    let end = vertices.partition_point(|v| v.chainage_m <= to_m);
    start..end.max(start + 1)
}

/// Map matching along a run: remembers the track and chainage of the last match.
#[derive(Debug, Clone)]
pub struct MapMatcher {
    /// Half-width of the chainage window searched around the expected chainage, m.
    pub window_m: f64,
    last: Option<(usize, f64)>,
}

impl MapMatcher {
    pub fn new(window_m: f64) -> Self {
        Self {
            window_m,
            last: None,
        }
    }

    /// The track and chainage of the last match, if any.
    pub fn last(&self) -> Option<(usize, f64)> {
        self.last
    }

    /// Forgets the run so far (the next match searches the whole map).
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// Matches (east, north). `expected_m` is where the caller expects the train along the
    /// track (a filter's predicted chainage); without it the last match's chainage is used.
    /// After a first match only the same track within the window is searched. The main line
    /// is taken first, or when the window holds no segment or the point lies beyond the
    /// current track's end (a parallel track ends at its turnouts); another track only when
    /// the point lies beyond the main line's ends, the nearest then. A train is taken to be
    /// on the track it was on: a fix beside it is a deviation to check, not a change of track.
    pub fn match_point(
        &mut self,
        map: &TrackMap,
        east_m: f64,
        north_m: f64,
        expected_m: Option<f64>,
    ) -> Option<MapMatch> {
        if !(east_m.is_finite() && north_m.is_finite()) {
            return None;
        }
        let near = self.last.and_then(|(track, last_s)| {
            let vertices = map.track(track)?;
            let centre = expected_m.filter(|s| s.is_finite()).unwrap_or(last_s);
            let segs = segments_between(vertices, centre - self.window_m, centre + self.window_m);
            nearest_on(vertices, segs, east_m, north_m)
                .map(|m| MapMatch { track, ..m })
                .filter(|m| !m.beyond_end)
        });
        let on = |t: usize| {
            let v = map.track(t)?;
            nearest_on(v, 0..v.len(), east_m, north_m).map(|m| MapMatch { track: t, ..m })
        };
        let found = near
            .or_else(|| on(0).filter(|m| !m.beyond_end))
            .or_else(|| {
                (0..map.track_count()).filter_map(on).min_by(|a, b| {
                    let d = |m: &MapMatch| (m.east_m - east_m).hypot(m.north_m - north_m);
                    d(a).total_cmp(&d(b))
                })
            })?;
        self.last = Some((found.track, found.chainage_m));
        Some(found)
    }
}

/// Why a track map cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapProblem {
    #[error("track {track}: {vertices} vertices, at least 2 are needed")]
    TooFewVertices { track: String, vertices: usize },
    #[error("track {track}: vertex {index} is not a finite point")]
    NotFinite { track: String, index: usize },
    #[error(
        "track {track}: chainage does not increase at vertex {index} ({before} m, then {after} m)"
    )]
    ChainageNotIncreasing {
        track: String,
        index: usize,
        before: f64,
        after: f64,
    },
    #[error(
        "track {track} crosses itself: segment {first} (chainage {first_m:.1} m) and segment {second} (chainage {second_m:.1} m)"
    )]
    SelfIntersecting {
        track: String,
        first: usize,
        second: usize,
        first_m: f64,
        second_m: f64,
    },
    #[error("track {track}: {problem}")]
    Profile {
        track: String,
        problem: crate::track_profile::ProfileProblem,
    },
}

impl TrackMap {
    /// Checks every track: at least two finite vertices, chainage strictly increasing, no
    /// segment crossing another that it does not join.
    pub fn check(&self) -> Result<(), MapProblem> {
        for t in 0..self.track_count() {
            let name = match t {
                0 => format!("'{}' (main line)", self.name),
                i => format!("'{}'", self.other_tracks[i - 1].name),
            };
            check_track(&name, self.track(t).unwrap_or(&[]))?;
        }
        Ok(())
    }
}

fn check_track(name: &str, v: &[TrackVertex]) -> Result<(), MapProblem> {
    if v.len() < 2 {
        return Err(MapProblem::TooFewVertices {
            track: name.to_owned(),
            vertices: v.len(),
        });
    }
    if let Some(index) = v
        .iter()
        .position(|p| !(p.east_m.is_finite() && p.north_m.is_finite() && p.chainage_m.is_finite()))
    {
        return Err(MapProblem::NotFinite {
            track: name.to_owned(),
            index,
        });
    }
    if let Some(i) = v
        .windows(2)
        .position(|w| w[1].chainage_m <= w[0].chainage_m)
    {
        return Err(MapProblem::ChainageNotIncreasing {
            track: name.to_owned(),
            index: i + 1,
            before: v[i].chainage_m,
            after: v[i + 1].chainage_m,
        });
    }
    if let Some(problem) = crate::track_profile::profile_problem(v) {
        return Err(MapProblem::Profile {
            track: name.to_owned(),
            problem,
        });
    }
    if let Some((first, second)) = self_intersection(v) {
        return Err(MapProblem::SelfIntersecting {
            track: name.to_owned(),
            first,
            second,
            first_m: v[first].chainage_m,
            second_m: v[second].chainage_m,
        });
    }
    Ok(())
}

/// The first pair of non-adjacent segments that touch or cross, by a sweep over east: each
/// segment is compared only with those whose east extent overlaps its own, so a line that
/// does not double back costs about `n log n`.
fn self_intersection(v: &[TrackVertex]) -> Option<(usize, usize)> {
    let extent = |i: usize| {
        let (a, b) = (v[i].east_m, v[i + 1].east_m);
        (a.min(b), a.max(b))
    };
    let mut order: Vec<usize> = (0..v.len() - 1).collect();
    order.sort_by(|&i, &j| extent(i).0.total_cmp(&extent(j).0));
    let mut active: Vec<usize> = Vec::new();
    let mut found: Option<(usize, usize)> = None;
    for &i in &order {
        let (lo, _) = extent(i);
        active.retain(|&j| extent(j).1 >= lo);
        for &j in &active {
            let (a, b) = (i.min(j), i.max(j));
            if b - a > 1 && segments_touch(v[a], v[a + 1], v[b], v[b + 1]) {
                found = Some(found.map_or((a, b), |f| f.min((a, b))));
            }
        }
        active.push(i);
    }
    found
}

/// Whether segments pq and rs share a point (orientation test, collinear overlaps included).
fn segments_touch(p: TrackVertex, q: TrackVertex, r: TrackVertex, s: TrackVertex) -> bool {
    let orient = |a: TrackVertex, b: TrackVertex, c: TrackVertex| {
        let x = (b.east_m - a.east_m) * (c.north_m - a.north_m)
            - (b.north_m - a.north_m) * (c.east_m - a.east_m);
        if x.abs() < 1e-12 {
            0
        } else {
            x.signum() as i8
        }
    };
    let within = |a: TrackVertex, b: TrackVertex, c: TrackVertex| {
        c.east_m >= a.east_m.min(b.east_m)
            && c.east_m <= a.east_m.max(b.east_m)
            && c.north_m >= a.north_m.min(b.north_m)
            && c.north_m <= a.north_m.max(b.north_m)
    };
    let (o1, o2, o3, o4) = (
        orient(p, q, r),
        orient(p, q, s),
        orient(r, s, p),
        orient(r, s, q),
    );
    (o1 != o2 && o3 != o4)
        || (o1 == 0 && within(p, q, r))
        || (o2 == 0 && within(p, q, s))
        || (o3 == 0 && within(r, s, p))
        || (o4 == 0 && within(r, s, q))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geodesy::GeodeticOrigin;
    use crate::messages::TrackLine;

    fn vertex(chainage_m: f64, east_m: f64, north_m: f64) -> TrackVertex {
        TrackVertex::at(chainage_m, east_m, north_m)
    }

    fn map(vertices: Vec<TrackVertex>, other_tracks: Vec<TrackLine>) -> TrackMap {
        let origin = GeodeticOrigin {
            latitude_deg: 44.6,
            longitude_deg: 10.9,
            altitude_m: 30.0,
        };
        TrackMap {
            other_tracks,
            ..TrackMap::line("t", origin, vertices)
        }
    }

    #[test]
    fn on_a_straight_line_due_east_lateral_is_the_distance_south() {
        // Heading east (π/2): right of the direction of travel is south.
        let m = map(
            vec![vertex(0.0, 0.0, 0.0), vertex(1000.0, 1000.0, 0.0)],
            vec![],
        );
        let mut matcher = MapMatcher::new(100.0);
        let r = matcher.match_point(&m, 250.0, -3.0, None).unwrap();
        assert!((r.chainage_m - 250.0).abs() < 1e-12);
        assert!((r.lateral_m - 3.0).abs() < 1e-12, "{r:?}");
        assert!((r.heading_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let r = matcher.match_point(&m, 260.0, 2.5, None).unwrap();
        assert!(
            (r.lateral_m + 2.5).abs() < 1e-12,
            "north of an eastbound track is left"
        );
    }

    #[test]
    fn on_a_curve_the_offset_is_the_distance_from_the_circle() {
        // A quarter circle of radius 500 m turning right from north, in 1° chords, chainage
        // along the chords.
        let r = 500.0;
        let mut v = Vec::new();
        let mut s = 0.0;
        for k in 0..=90 {
            let a = (k as f64).to_radians();
            let (e, n) = (r - r * a.cos(), r * a.sin());
            if let Some(last) = v.last() {
                let last: &TrackVertex = last;
                s += (e - last.east_m).hypot(n - last.north_m);
            }
            v.push(vertex(s, e, n));
        }
        let m = map(v, vec![]);
        // 45° round, 2 m outside the circle (outside a right-hand curve is left: negative).
        let a = 45.5f64.to_radians(); // mid-chord, where the chord is nearest the arc
        let (e, n) = (r - (r + 2.0) * a.cos(), (r + 2.0) * a.sin());
        let got = MapMatcher::new(50.0).match_point(&m, e, n, None).unwrap();
        // The chord lies inside the arc by r(1 − cos 0.5°) = 19 mm.
        let sagitta = r * (1.0 - 0.5f64.to_radians().cos());
        assert!(
            (got.lateral_m + 2.0 + sagitta).abs() < 1e-6,
            "{} vs {}",
            got.lateral_m,
            -(2.0 + sagitta)
        );
        let chord = 2.0 * r * 0.5f64.to_radians().sin();
        assert!(
            (got.chainage_m - 45.5 * chord).abs() < 1e-6,
            "{}",
            got.chainage_m
        );
        assert!((got.heading_rad - a).abs() < 1e-9);
    }

    #[test]
    fn curvature_is_the_turn_over_the_distance() {
        // 90° right over a quarter circle of 500 m in 0.1° chords (each chord's heading is
        // its middle's: within a chord of the true value).
        let r = 500.0;
        let v: Vec<TrackVertex> = (0..=900)
            .map(|k| {
                let a = (k as f64 / 10.0).to_radians();
                vertex(r * a, r - r * a.cos(), r * a.sin())
            })
            .collect();
        let k = curvature_on(&v, r * 45f64.to_radians(), 20.0);
        assert!((k * r - 1.0).abs() < 0.03, "{k}");
        let straight = [vertex(0.0, 0.0, 0.0), vertex(100.0, 0.0, 100.0)];
        assert_eq!(curvature_on(&straight, 50.0, 10.0), 0.0);
    }

    #[test]
    fn a_run_keeps_to_its_track_when_fixes_drift_towards_the_parallel_one() {
        // A parallel track 4.5 m to the left (north) of an eastbound main line.
        let main = vec![vertex(0.0, 0.0, 0.0), vertex(2000.0, 2000.0, 0.0)];
        let side = TrackLine {
            name: "platform 2".into(),
            vertices: vec![vertex(500.0, 500.0, 4.5), vertex(1500.0, 1500.0, 4.5)],
        };
        let m = map(main, vec![side]);
        let mut matcher = MapMatcher::new(200.0);
        assert_eq!(matcher.match_point(&m, 400.0, 0.3, None).unwrap().track, 0);
        // Multipath pulls a fix 3.5 m north: nearer the parallel track, still the main line.
        let r = matcher.match_point(&m, 700.0, 3.5, Some(700.0)).unwrap();
        assert_eq!(r.track, 0);
        assert!((r.lateral_m + 3.5).abs() < 1e-12);
        // Without memory too: the main line comes first while the fix is beside it.
        let fresh = MapMatcher::new(200.0)
            .match_point(&m, 700.0, 3.5, None)
            .unwrap();
        assert_eq!(fresh.track, 0);
        // Beyond the main line's end, the other track that is there.
        let short_main = map(
            vec![vertex(0.0, 0.0, 0.0), vertex(600.0, 600.0, 0.0)],
            m.other_tracks.clone(),
        );
        let r = MapMatcher::new(200.0)
            .match_point(&short_main, 900.0, 4.0, None)
            .unwrap();
        assert_eq!(r.track, 1, "{r:?}");
    }

    #[test]
    fn the_window_keeps_a_match_near_the_expected_chainage_where_the_line_passes_itself() {
        // A hairpin: out east 1000 m, round, back west 10 m further north.
        let v = vec![
            vertex(0.0, 0.0, 0.0),
            vertex(1000.0, 1000.0, 0.0),
            vertex(1010.0, 1000.0, 10.0),
            vertex(2010.0, 0.0, 10.0),
        ];
        let m = map(v, vec![]);
        let mut matcher = MapMatcher::new(100.0);
        matcher.match_point(&m, 100.0, 0.0, None);
        // A fix at (300, 6): nearer the return leg, but the train is on the outward leg.
        let r = matcher.match_point(&m, 300.0, 6.0, Some(300.0)).unwrap();
        assert!((r.chainage_m - 300.0).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn projection_inverts_locate_on_a_bent_line() {
        let v = vec![
            vertex(0.0, 0.0, 0.0),
            vertex(100.0, 100.0, 0.0),
            vertex(200.0, 100.0, 100.0),
        ];
        let m = map(v, vec![]);
        for s in [5.0, 99.0, 150.0, 199.0] {
            let (e, n, h) = m.locate(s).unwrap();
            let (s2, h2) = m.project(e + 0.5 * h.cos(), n - 0.5 * h.sin()).unwrap();
            assert!((s2 - s).abs() < 1e-9 && (h2 - h).abs() < 1e-12, "{s}: {s2}");
        }
    }

    #[test]
    fn chainage_to_a_place_and_back() {
        let m = map(
            vec![vertex(100.0, 0.0, 0.0), vertex(1100.0, 0.0, 1000.0)],
            vec![],
        );
        let (e, n, h) = m.locate(600.0).unwrap();
        assert_eq!((e, n, h), (0.0, 500.0, 0.0));
        let (lat, lon) = m.lat_lon_at(600.0).unwrap();
        let (e2, n2, _) = m.origin.to_enu(lat, lon, m.origin.altitude_m);
        assert!(e2.abs() < 1e-3 && (n2 - 500.0).abs() < 1e-3, "{e2} {n2}");
    }

    #[test]
    fn bad_maps_are_refused_with_the_reason() {
        let empty = map(vec![vertex(0.0, 0.0, 0.0)], vec![]);
        assert!(matches!(
            empty.check(),
            Err(MapProblem::TooFewVertices { vertices: 1, .. })
        ));
        let nan = map(
            vec![vertex(0.0, 0.0, 0.0), vertex(1.0, f64::NAN, 0.0)],
            vec![],
        );
        assert!(matches!(
            nan.check(),
            Err(MapProblem::NotFinite { index: 1, .. })
        ));
        let back = map(vec![vertex(0.0, 0.0, 0.0), vertex(0.0, 1.0, 0.0)], vec![]);
        assert!(matches!(
            back.check(),
            Err(MapProblem::ChainageNotIncreasing { index: 1, .. })
        ));
        // A figure of eight: the fourth segment crosses the first.
        let crossing = map(
            vec![
                vertex(0.0, 0.0, 0.0),
                vertex(100.0, 100.0, 0.0),
                vertex(200.0, 100.0, 100.0),
                vertex(300.0, 50.0, 100.0),
                vertex(500.0, 50.0, -100.0),
            ],
            vec![],
        );
        let e = crossing.check().unwrap_err();
        assert!(
            matches!(
                e,
                MapProblem::SelfIntersecting {
                    first: 0,
                    second: 3,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("crosses itself"), "{e}");
        let fine = map(vec![vertex(0.0, 0.0, 0.0), vertex(10.0, 10.0, 0.0)], vec![]);
        assert_eq!(fine.check(), Ok(()));
    }
}
