//! A fitted centre line as a dense polyline with its chainage (arc length), and where points
//! of a run lie on it.

use railfuse_catalog::map_matching::nearest_on;
use railfuse_catalog::messages::TrackVertex;

use crate::spline::PlaneSpline;

/// Spacing of the dense polyline, m: at 1 m a chord leaves a 300 m radius curve by 0.4 mm.
pub const DENSE_STEP_M: f64 = 1.0;

/// A point this far past an end of the line, along it, still counts as on it, m.
pub const REACH_M: f64 = 10.0;

/// Half-width of the chainage window a run's next fix is searched in, m.
const SEARCH_WINDOW_M: f64 = 300.0;

/// A centre line: vertices every [`DENSE_STEP_M`], chainage the length along them.
#[derive(Debug, Clone)]
pub struct Line {
    pub vertices: Vec<TrackVertex>,
}

/// Where a point lies against the line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnLine {
    pub chainage_m: f64,
    /// Right of the direction of increasing chainage positive.
    pub lateral_m: f64,
    /// Beyond an end: not beside the line at all.
    pub beyond_end: bool,
}

impl Line {
    /// The spline sampled from `from_m` to `to_m` of its parameter, chainage the length
    /// along the samples from `from_m`.
    pub fn from_spline(spline: &PlaneSpline, from_m: f64, to_m: f64) -> Self {
        let steps = ((to_m - from_m) / DENSE_STEP_M).ceil().max(1.0) as usize;
        let points: Vec<(f64, f64)> = (0..=steps)
            .map(|i| spline.at(from_m + (to_m - from_m) * i as f64 / steps as f64))
            .collect();
        Self::through_from(&points, from_m)
    }

    /// A polyline through points in order, chainage the length along it.
    pub fn through(points: &[(f64, f64)]) -> Self {
        Self::through_from(points, 0.0)
    }

    /// The same, chainage starting at `start_m`.
    fn through_from(points: &[(f64, f64)], start_m: f64) -> Self {
        let mut chainage = start_m;
        let mut vertices: Vec<TrackVertex> = Vec::with_capacity(points.len());
        for &(e, n) in points {
            if let Some(last) = vertices.last() {
                chainage += (e - last.east_m).hypot(n - last.north_m);
            }
            vertices.push(TrackVertex::at(chainage, e, n));
        }
        Self { vertices }
    }

    pub fn start_m(&self) -> f64 {
        self.vertices.first().map_or(0.0, |v| v.chainage_m)
    }

    pub fn end_m(&self) -> f64 {
        self.vertices.last().map_or(0.0, |v| v.chainage_m)
    }

    /// The point on the line nearest (east, north), searched within the window around
    /// `near_m` when given (a run's last match: a line that passes near itself is not
    /// jumped across), else along the whole line.
    pub fn locate(&self, east_m: f64, north_m: f64, near_m: Option<f64>) -> Option<OnLine> {
        let v = &self.vertices;
        let all = 0..v.len();
        let segments = match near_m {
            Some(c) => {
                let a = v.partition_point(|p| p.chainage_m < c - SEARCH_WINDOW_M);
                let b = v.partition_point(|p| p.chainage_m <= c + SEARCH_WINDOW_M);
                a.saturating_sub(1)..b.max(a + 1)
            }
            None => all,
        };
        let m = nearest_on(v, segments, east_m, north_m)?;
        // Clamped to the end of the window searched, not of the line: the point lies further
        // along, where the window does not reach.
        let distance = (east_m - m.east_m).hypot(north_m - m.north_m);
        let at_end = m.chainage_m <= self.start_m() || m.chainage_m >= self.end_m();
        if near_m.is_some() && !at_end && distance > m.lateral_m.abs() + 0.01 {
            return None;
        }
        if !(m.beyond_end || at_end) {
            return Some(OnLine {
                chainage_m: m.chainage_m,
                lateral_m: m.lateral_m,
                beyond_end: false,
            });
        }
        self.beyond(east_m, north_m)
    }

    /// A point past an end: on the end segment carried on straight, within [`REACH_M`] of
    /// the end (a run that goes a little further than the line so far lengthens it), else
    /// beyond the end.
    fn beyond(&self, east_m: f64, north_m: f64) -> Option<OnLine> {
        let v = &self.vertices;
        let (first, last) = (v.first()?, v.last()?);
        let near_start = (east_m - first.east_m).hypot(north_m - first.north_m)
            < (east_m - last.east_m).hypot(north_m - last.north_m);
        let (end, inner, sign) = match near_start {
            true => (*first, *v.get(1)?, -1.0),
            false => (*last, v[v.len() - 2], 1.0),
        };
        // Unit vector pointing out of the line at this end.
        let (de, dn) = (end.east_m - inner.east_m, end.north_m - inner.north_m);
        let len = de.hypot(dn);
        let (ue, un) = (de / len, dn / len);
        let (pe, pn) = (east_m - end.east_m, north_m - end.north_m);
        let out = pe * ue + pn * un;
        // Right of the direction of increasing chainage: that direction is sign·(ue, un).
        let lateral = sign * (pe * un - pn * ue);
        Some(OnLine {
            chainage_m: end.chainage_m + sign * out,
            lateral_m: lateral,
            beyond_end: !(0.0..=REACH_M).contains(&out),
        })
    }

    /// Every vertex kept where the line bends enough to matter: a vertex is dropped while
    /// the chord that replaces it stays within `tolerance_m` of the dense line.
    pub fn thinned(&self, tolerance_m: f64) -> Vec<TrackVertex> {
        let v = &self.vertices;
        if v.len() <= 2 {
            return v.clone();
        }
        let mut kept = vec![v[0]];
        let mut anchor = 0;
        let mut i = 2;
        while i < v.len() {
            if !chord_holds(&v[anchor..=i], tolerance_m) {
                kept.push(v[i - 1]);
                anchor = i - 1;
            }
            i += 1;
        }
        kept.push(v[v.len() - 1]);
        kept
    }
}

/// Every inner vertex of `run` lies within `tolerance_m` of the chord joining its ends, in
/// the plane and, where the vertices have heights, in height along the chainage (a vertical
/// curve on a straight keeps its vertices).
fn chord_holds(run: &[TrackVertex], tolerance_m: f64) -> bool {
    let (a, b) = (run[0], run[run.len() - 1]);
    if let (Some(ha), Some(hb)) = (a.height_m, b.height_m) {
        let span = b.chainage_m - a.chainage_m;
        let off = |p: &TrackVertex| {
            let f = (p.chainage_m - a.chainage_m) / span;
            p.height_m.map_or(0.0, |h| h - (ha + f * (hb - ha)))
        };
        if span > 0.0
            && run[1..run.len() - 1]
                .iter()
                .any(|p| off(p).abs() > tolerance_m)
        {
            return false;
        }
    }
    let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
    let len = de.hypot(dn);
    if len == 0.0 {
        return true;
    }
    run[1..run.len() - 1].iter().all(|p| {
        let cross = (p.east_m - a.east_m) * dn - (p.north_m - a.north_m) * de;
        (cross / len).abs() <= tolerance_m
    })
}

/// Whether a run's fixes on the line mostly go towards increasing chainage.
pub fn increasing(placed: &[Option<OnLine>]) -> bool {
    let s: Vec<f64> = placed.iter().flatten().map(|m| m.chainage_m).collect();
    let up = s.windows(2).filter(|w| w[1] > w[0]).count();
    let down = s.windows(2).filter(|w| w[1] < w[0]).count();
    up >= down
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_line_thins_to_its_ends_and_a_curve_keeps_what_it_needs() {
        let straight = Line::through(&(0..=100).map(|i| (i as f64, 0.0)).collect::<Vec<_>>());
        assert_eq!(straight.thinned(0.002).len(), 2);
        let r = 300.0;
        let curve = Line::through(
            &(0..=300)
                .map(|i| {
                    let a = i as f64 / r;
                    (r * a.sin(), r - r * a.cos())
                })
                .collect::<Vec<_>>(),
        );
        let kept = curve.thinned(0.002);
        // A 2 mm sagitta on 300 m is a chord of about 2.2 m.
        assert!(
            kept.len() > 100 && kept.len() < 200,
            "{} vertices",
            kept.len()
        );
    }

    #[test]
    fn a_point_beside_the_line_is_located_with_its_side() {
        let line = Line::through(&[(0.0, 0.0), (100.0, 0.0)]);
        // Heading east: right is south.
        let m = line.locate(40.0, -2.0, None).unwrap();
        assert!((m.chainage_m - 40.0).abs() < 1e-9 && (m.lateral_m - 2.0).abs() < 1e-9);
        assert!(!m.beyond_end);
        assert!(line.locate(120.0, 0.0, None).unwrap().beyond_end);
    }
}
