//! Track geometry for the simulator: straights, transition curves (clothoids) and circular
//! curves with their cant laid end to end from an origin, and a vertical alignment of
//! gradients joined by vertical curves. Sampled into the catalogue's [`TrackMap`] polyline
//! (heights and cant on its vertices where the line has them), with the exact geometry kept
//! for the sensors: heading, curvature, gradient, vertical curvature and cant at any chainage.

use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::messages::{Station, TrackBalise, TrackMap, TrackVertex, Tunnel};
use rand::RngExt;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Segment {
    Straight {
        length_m: f64,
    },
    /// A circular curve; positive angle turns right (clockwise seen from above). With
    /// `transition_m`, a clothoid of that length leads in and out (curvature linear from 0 to
    /// 1/R), inside the curve's total turn; the cant ramps linearly along it.
    Curve {
        radius_m: f64,
        angle_deg: f64,
        #[serde(default, skip_serializing_if = "is_zero")]
        transition_m: f64,
        /// Cant on the circular part, mm, raising the outer rail.
        #[serde(default, skip_serializing_if = "is_zero")]
        cant_mm: f64,
    },
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Segment {
    /// A circular curve without transitions or cant.
    pub fn curve(radius_m: f64, angle_deg: f64) -> Segment {
        Segment::Curve {
            radius_m,
            angle_deg,
            transition_m: 0.0,
            cant_mm: 0.0,
        }
    }

    /// Its pieces of linearly changing curvature: (length, curvature at the start, curvature
    /// rate per m, cant per unit of curvature).
    fn pieces(&self) -> Vec<(f64, f64, f64, f64)> {
        match *self {
            Segment::Straight { length_m } => vec![(length_m, 0.0, 0.0, 0.0)],
            Segment::Curve {
                radius_m,
                angle_deg,
                transition_m: l,
                cant_mm,
            } => {
                let k = angle_deg.signum() / radius_m;
                let cant_per_k = cant_mm / 1e3 * radius_m;
                // Each clothoid turns L/2R: the arc keeps what is left of the turn.
                let arc = radius_m * angle_deg.to_radians().abs() - l;
                match l > 0.0 {
                    false => vec![(arc, k, 0.0, cant_per_k)],
                    true => vec![
                        (l, 0.0, k / l, cant_per_k),
                        (arc, k, 0.0, cant_per_k),
                        (l, k, -k / l, cant_per_k),
                    ],
                }
            }
        }
    }
}

/// A gradient kept over a length, ‰ (positive rising towards increasing chainage).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GradientSection {
    pub length_m: f64,
    pub permille: f64,
}

/// The line's vertical alignment: gradients laid in order and repeated, each change of
/// gradient rounded by a vertical curve (a parabola) of radius `curve_radius_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VerticalParams {
    pub sections: Vec<GradientSection>,
    pub curve_radius_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackParams {
    pub name: String,
    pub origin: GeodeticOrigin,
    /// Initial heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Segments laid in order and repeated until the track is long enough.
    pub pattern: Vec<Segment>,
    pub station_spacing_m: f64,
    pub balise_spacing_m: f64,
    /// Random offset of each balise from its nominal place, ± m.
    pub balise_jitter_m: f64,
    pub tunnels: Vec<(f64, f64)>,
    pub sleeper_spacing_m: f64,
    pub loop_crossing_spacing_m: Option<f64>,
    /// Distance between polyline vertices along curves (straights have only their ends); the
    /// chord's sagitta is spacing² / 8R, 1 cm for 10 m on a 1200 m curve.
    pub vertex_spacing_m: f64,
    /// Stations at these chainages instead of every `station_spacing_m` (a yard's short
    /// moves, then the line).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub station_chainages_m: Vec<f64>,
    /// Gradients and vertical curves; None: a flat line at the origin's height.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertical: Option<VerticalParams>,
    /// Straight track behind chainage 0 (negative chainage), where a train whose front end
    /// starts at 0 has the rest of its length and its sensors; 0: none (a point train).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lead_in_m: f64,
}

/// One piece of the line in the plane: curvature changing linearly along it (a straight, an
/// arc or a clothoid), with the heading where it starts.
#[derive(Debug, Clone, Copy)]
struct Piece {
    start_m: f64,
    curvature: f64,
    /// Change of curvature per metre (a clothoid's), 1/m².
    curvature_rate: f64,
    heading_rad: f64,
    /// Cant, m, per unit of curvature: the cant follows the curvature along a transition.
    cant_per_curvature: f64,
}

/// One piece of the vertical alignment: a constant gradient, or a vertical curve along which
/// it changes linearly.
#[derive(Debug, Clone, Copy)]
struct VerticalPiece {
    start_m: f64,
    height_m: f64,
    gradient: f64,
    /// Change of gradient per metre: ±1/R_v on a vertical curve.
    gradient_rate: f64,
}

/// The simulator's track: the published map plus the exact geometry.
pub struct Track {
    pub map: TrackMap,
    pieces: Vec<Piece>,
    vertical: Vec<VerticalPiece>,
}

impl Track {
    /// Lays the pattern until the track holds `stations` stations `station_spacing_m` apart.
    pub fn build(
        p: &TrackParams,
        stations: usize,
        stamp_ns: u64,
        rng: &mut impl rand::Rng,
    ) -> Track {
        let station_chainages: Vec<f64> = match p.station_chainages_m.is_empty() {
            true => (0..stations.max(2))
                .map(|k| k as f64 * p.station_spacing_m)
                .collect(),
            false => p.station_chainages_m.clone(),
        };
        let length = station_chainages.last().copied().unwrap_or(0.0) + 200.0;
        let (mut vertices, pieces) = lay(p, length);
        let s = vertices.last().map_or(0.0, |v| v.chainage_m);
        let vertical = p
            .vertical
            .as_ref()
            .map(|v| vertical_pieces(v, s))
            .unwrap_or_default();
        let mut track = Track {
            map: TrackMap {
                stamp_ns,
                balises: balises(p, s, rng),
                tunnels: tunnels(p, s),
                stations: station_chainages
                    .iter()
                    .enumerate()
                    .map(|(k, &chainage_m)| Station {
                        name: format!("S{k}"),
                        chainage_m,
                    })
                    .collect(),
                sleeper_spacing_m: p.sleeper_spacing_m,
                loop_crossing_spacing_m: p.loop_crossing_spacing_m,
                ..TrackMap::line(&p.name, p.origin, Vec::new())
            },
            pieces,
            vertical,
        };
        if !track.vertical.is_empty() {
            vertices = with_vertical_samples(vertices, &track.vertical, p.vertex_spacing_m);
        }
        let canted = track.pieces.iter().any(|q| q.cant_per_curvature != 0.0);
        for v in &mut vertices {
            if !track.vertical.is_empty() {
                v.height_m = Some(track.height(v.chainage_m));
            }
            if canted {
                v.cant_m = Some(track.cant_m(v.chainage_m));
            }
        }
        track.map.vertices = vertices;
        track
    }

    fn piece(&self, chainage_m: f64) -> (Piece, f64) {
        let i = self.pieces.partition_point(|q| q.start_m <= chainage_m);
        let q = self.pieces[i.max(1) - 1];
        (q, (chainage_m - q.start_m).max(0.0))
    }

    /// Curvature (1/m, positive turning right) at a chainage.
    pub fn curvature(&self, chainage_m: f64) -> f64 {
        let (q, x) = self.piece(chainage_m);
        q.curvature + q.curvature_rate * x
    }

    /// The exact heading, clockwise from north, rad.
    pub fn heading(&self, chainage_m: f64) -> f64 {
        let (q, x) = self.piece(chainage_m);
        q.heading_rad + q.curvature * x + 0.5 * q.curvature_rate * x * x
    }

    /// Cant, m, positive with the left rail higher.
    pub fn cant_m(&self, chainage_m: f64) -> f64 {
        let (q, _) = self.piece(chainage_m);
        q.cant_per_curvature * self.curvature(chainage_m)
    }

    fn vertical_piece(&self, chainage_m: f64) -> Option<(VerticalPiece, f64)> {
        let i = self.vertical.partition_point(|q| q.start_m <= chainage_m);
        let q = *self.vertical.get(i.max(1) - 1)?;
        Some((q, (chainage_m - q.start_m).max(0.0)))
    }

    /// Height of the top of rail above the origin, m.
    pub fn height(&self, chainage_m: f64) -> f64 {
        self.vertical_piece(chainage_m).map_or(0.0, |(q, x)| {
            q.height_m + q.gradient * x + 0.5 * q.gradient_rate * x * x
        })
    }

    /// Rise per metre of chainage.
    pub fn gradient(&self, chainage_m: f64) -> f64 {
        self.vertical_piece(chainage_m)
            .map_or(0.0, |(q, x)| q.gradient + q.gradient_rate * x)
    }

    /// Change of gradient per metre (1/R_v on a vertical curve, 0 elsewhere).
    pub fn vertical_curvature(&self, chainage_m: f64) -> f64 {
        self.vertical_piece(chainage_m)
            .map_or(0.0, |(q, _)| q.gradient_rate)
    }
}

fn tunnels(p: &TrackParams, length: f64) -> Vec<Tunnel> {
    p.tunnels
        .iter()
        .filter(|(a, _)| *a < length)
        .enumerate()
        .map(|(i, &(a, z))| Tunnel {
            name: format!("T{}", i + 1),
            start_chainage_m: a,
            end_chainage_m: z.min(length),
        })
        .collect()
}

/// The line laid from the pattern, repeated until it is `length` long, after its lead-in
/// straight: its vertices (a straight's ends, a curve's every `vertex_spacing_m`) and its
/// pieces.
fn lay(p: &TrackParams, length: f64) -> (Vec<TrackVertex>, Vec<Piece>) {
    let start = -p.lead_in_m.max(0.0);
    let mut layer = Layer {
        pieces: Vec::new(),
        vertices: vec![TrackVertex::at(start, 0.0, 0.0)],
        at: (start, 0.0, 0.0, p.heading_deg.to_radians()),
        spacing: p.vertex_spacing_m,
    };
    if start < 0.0 {
        layer.segment(&Segment::Straight { length_m: -start });
    }
    'lay: loop {
        for seg in &p.pattern {
            layer.segment(seg);
            if layer.at.0 >= length {
                break 'lay;
            }
        }
    }
    (layer.vertices, layer.pieces)
}

/// The line as it is laid: its pieces and vertices so far, and where it has got to
/// (chainage, east, north, heading).
struct Layer {
    pieces: Vec<Piece>,
    vertices: Vec<TrackVertex>,
    at: (f64, f64, f64, f64),
    spacing: f64,
}

impl Layer {
    fn segment(&mut self, seg: &Segment) {
        for (len, k0, rate, cant_per_curvature) in seg.pieces() {
            let (mut s, mut e, mut n, mut psi) = self.at;
            self.pieces.push(Piece {
                start_m: s,
                curvature: k0,
                curvature_rate: rate,
                heading_rad: psi,
                cant_per_curvature,
            });
            // Straights need only their ends; curves a vertex every `spacing`.
            let steps = match k0 == 0.0 && rate == 0.0 {
                true => 1,
                false => (len / self.spacing).ceil().max(1.0) as usize,
            };
            let ds = len / steps as f64;
            for step in 0..steps {
                let x0 = step as f64 * ds;
                // An arc is stepped exactly in one chord; a clothoid in 1 m chords.
                let subs = match rate == 0.0 {
                    true => 1,
                    false => ds.ceil().max(1.0) as usize,
                };
                let h = ds / subs as f64;
                for k in 0..subs {
                    let curvature = k0 + rate * (x0 + (k as f64 + 0.5) * h);
                    let dpsi = curvature * h;
                    let mid = psi + dpsi / 2.0;
                    let chord = match dpsi.abs() > 1e-12 {
                        true => 2.0 * (dpsi / 2.0).sin() / curvature,
                        false => h,
                    };
                    e += chord * mid.sin();
                    n += chord * mid.cos();
                    psi += dpsi;
                }
                s += ds;
                self.vertices.push(TrackVertex::at(s, e, n));
            }
            self.at = (s, e, n, psi);
        }
    }
}

/// The vertical alignment's pieces over `length`: each section's gradient, each change of
/// gradient rounded by a parabola of the vertical curve's radius, centred on the change.
fn vertical_pieces(p: &VerticalParams, length: f64) -> Vec<VerticalPiece> {
    let mut out = Vec::new();
    let mut sections = p.sections.iter().cycle();
    let Some(first) = sections.next() else {
        return out;
    };
    let (mut at, mut height, mut gradient) = (0.0f64, 0.0f64, first.permille / 1e3);
    let mut change_at = first.length_m;
    for next in sections {
        let next_gradient = next.permille / 1e3;
        let half = p.curve_radius_m * (next_gradient - gradient).abs() / 2.0;
        let curve_start = change_at - half;
        out.push(VerticalPiece {
            start_m: at,
            height_m: height,
            gradient,
            gradient_rate: 0.0,
        });
        height += gradient * (curve_start - at);
        let rate = match half > 0.0 {
            true => (next_gradient - gradient) / (2.0 * half),
            false => 0.0,
        };
        out.push(VerticalPiece {
            start_m: curve_start,
            height_m: height,
            gradient,
            gradient_rate: rate,
        });
        height += gradient * 2.0 * half + 0.5 * rate * (2.0 * half).powi(2);
        (at, gradient) = (change_at + half, next_gradient);
        change_at += next.length_m;
        if at > length + 1000.0 {
            break;
        }
    }
    out.push(VerticalPiece {
        start_m: at,
        height_m: height,
        gradient,
        gradient_rate: 0.0,
    });
    out
}

/// The vertices with more where the vertical alignment needs them: every `spacing` along
/// vertical curves and at their ends, where no vertex is already within half that.
fn with_vertical_samples(
    vertices: Vec<TrackVertex>,
    vertical: &[VerticalPiece],
    spacing: f64,
) -> Vec<TrackVertex> {
    let last = vertices.last().map_or(0.0, |v| v.chainage_m);
    let mut wanted = Vec::new();
    for (i, q) in vertical.iter().enumerate() {
        wanted.push(q.start_m);
        if q.gradient_rate != 0.0 {
            let end = vertical.get(i + 1).map_or(q.start_m, |n| n.start_m);
            let steps = ((end - q.start_m) / spacing).ceil() as usize;
            let step = (end - q.start_m) / steps.max(1) as f64;
            wanted.extend((1..steps).map(|k| q.start_m + k as f64 * step));
        }
    }
    let mut out = Vec::with_capacity(vertices.len() + wanted.len());
    let mut w = wanted
        .into_iter()
        .filter(|&c| c > 0.0 && c < last)
        .peekable();
    for pair in vertices.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        out.push(a);
        while let Some(&c) = w.peek().filter(|&&c| c < b.chainage_m) {
            w.next();
            if c - a.chainage_m < spacing / 2.0 || b.chainage_m - c < spacing / 2.0 {
                continue;
            }
            let f = (c - a.chainage_m) / (b.chainage_m - a.chainage_m);
            out.push(TrackVertex::at(
                c,
                a.east_m + f * (b.east_m - a.east_m),
                a.north_m + f * (b.north_m - a.north_m),
            ));
        }
    }
    out.extend(vertices.last());
    out
}

/// A balise every `balise_spacing_m` (from half a spacing in), each jittered.
fn balises(p: &TrackParams, length: f64, rng: &mut impl rand::Rng) -> Vec<TrackBalise> {
    let mut balises = Vec::new();
    let mut b = p.balise_spacing_m / 2.0;
    while b < length - 50.0 {
        let jitter = if p.balise_jitter_m > 0.0 {
            rng.random_range(-p.balise_jitter_m..p.balise_jitter_m)
        } else {
            0.0
        };
        balises.push(TrackBalise {
            balise_id: format!("BG{:04}", balises.len() + 1),
            chainage_m: b + jitter,
        });
        b += p.balise_spacing_m;
    }
    balises
}

/// A straight line heading north from `origin`, for the sensors' tests.
#[cfg(test)]
pub(crate) fn straight_line(origin: GeodeticOrigin, vertical: Option<VerticalParams>) -> Track {
    use rand::SeedableRng;
    let p = TrackParams {
        name: "straight".into(),
        origin,
        heading_deg: 0.0,
        pattern: vec![Segment::Straight { length_m: 5000.0 }],
        station_spacing_m: 4000.0,
        balise_spacing_m: 1000.0,
        balise_jitter_m: 0.0,
        tunnels: vec![],
        sleeper_spacing_m: 0.6,
        loop_crossing_spacing_m: None,
        vertex_spacing_m: 10.0,
        station_chainages_m: vec![],
        vertical,
        lead_in_m: 0.0,
    };
    Track::build(&p, 2, 0, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_full_circle_of_curves_closes_on_itself() {
        let p = TrackParams {
            name: "circle".into(),
            origin: GeodeticOrigin {
                latitude_deg: 45.0,
                longitude_deg: 10.0,
                altitude_m: 0.0,
            },
            heading_deg: 0.0,
            pattern: vec![Segment::curve(500.0, 90.0); 4],
            station_spacing_m: 500.0 * std::f64::consts::TAU - 300.0,
            balise_spacing_m: 1000.0,
            balise_jitter_m: 0.0,
            tunnels: vec![],
            sleeper_spacing_m: 0.6,
            loop_crossing_spacing_m: None,
            vertex_spacing_m: 5.0,
            station_chainages_m: vec![],
            vertical: None,
            lead_in_m: 0.0,
        };
        let t = Track::build(&p, 2, 0, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1));
        let last = t.map.vertices.last().unwrap();
        assert!((last.chainage_m - 500.0 * std::f64::consts::TAU).abs() < 1e-6);
        assert!(
            last.east_m.abs() < 1e-6 && last.north_m.abs() < 1e-6,
            "{last:?}"
        );
        // Quarter way round a right-hand circle starting north: due east of the centre's top.
        let (e, n, psi) = t.map.locate(500.0 * std::f64::consts::FRAC_PI_2).unwrap();
        assert!(
            (e - 500.0).abs() < 0.1 && (n - 500.0).abs() < 0.1,
            "{e} {n}"
        );
        assert!((psi - std::f64::consts::FRAC_PI_2).abs() < 0.02);
        assert_eq!(t.curvature(10.0), 1.0 / 500.0);
    }
}
