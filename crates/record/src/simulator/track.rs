//! Track geometry for the simulator: straights and circular curves laid end to end from an
//! origin, sampled into the catalogue's [`TrackMap`] polyline, with the curvature kept exactly
//! for the inertial sensors.

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
    /// A circular curve; positive angle turns right (clockwise seen from above).
    Curve {
        radius_m: f64,
        angle_deg: f64,
    },
}

impl Segment {
    fn length_m(&self) -> f64 {
        match *self {
            Segment::Straight { length_m } => length_m,
            Segment::Curve {
                radius_m,
                angle_deg,
            } => radius_m * angle_deg.to_radians().abs(),
        }
    }
    fn curvature(&self) -> f64 {
        match *self {
            Segment::Straight { .. } => 0.0,
            Segment::Curve {
                radius_m,
                angle_deg,
            } => angle_deg.signum() / radius_m,
        }
    }
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
}

/// The simulator's track: the published map plus the exact curvature profile.
pub struct Track {
    pub map: TrackMap,
    /// (start chainage, curvature) of each laid segment.
    curvature: Vec<(f64, f64)>,
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
        let (vertices, curvature) = lay(p, length);
        let s = vertices.last().map_or(0.0, |v| v.chainage_m);
        let stations = station_chainages
            .iter()
            .enumerate()
            .map(|(k, &chainage_m)| Station {
                name: format!("S{k}"),
                chainage_m,
            })
            .collect();
        let balises = balises(p, s, rng);
        let tunnels = p
            .tunnels
            .iter()
            .filter(|(a, _)| *a < s)
            .enumerate()
            .map(|(i, &(a, z))| Tunnel {
                name: format!("T{}", i + 1),
                start_chainage_m: a,
                end_chainage_m: z.min(s),
            })
            .collect();
        Track {
            map: TrackMap {
                stamp_ns,
                name: p.name.clone(),
                origin: p.origin,
                vertices,
                balises,
                tunnels,
                stations,
                sleeper_spacing_m: p.sleeper_spacing_m,
                loop_crossing_spacing_m: p.loop_crossing_spacing_m,
                other_tracks: Vec::new(),
                sleeper_sections: Vec::new(),
                switches: Vec::new(),
            },
            curvature,
        }
    }

    /// Curvature (1/m, positive turning right) at a chainage.
    pub fn curvature(&self, chainage_m: f64) -> f64 {
        let i = self.curvature.partition_point(|&(s, _)| s <= chainage_m);
        if i == 0 {
            0.0
        } else {
            self.curvature[i - 1].1
        }
    }
}

/// The line laid from the pattern, repeated until it is `length` long: its vertices (a
/// straight's ends, a curve's every `vertex_spacing_m`) and each segment's curvature from
/// where it starts.
fn lay(p: &TrackParams, length: f64) -> (Vec<TrackVertex>, Vec<(f64, f64)>) {
    let mut curvature = Vec::new();
    let mut vertices = vec![TrackVertex {
        chainage_m: 0.0,
        east_m: 0.0,
        north_m: 0.0,
    }];
    let (mut s, mut e, mut n, mut psi) = (0.0f64, 0.0f64, 0.0f64, p.heading_deg.to_radians());
    'lay: loop {
        for seg in &p.pattern {
            curvature.push((s, seg.curvature()));
            let len = seg.length_m();
            // Straights need only their ends; curves a vertex every `vertex_spacing_m`.
            let steps = if seg.curvature() == 0.0 {
                1
            } else {
                (len / p.vertex_spacing_m).ceil().max(1.0) as usize
            };
            let ds = len / steps as f64;
            for _ in 0..steps {
                // Exact arc (or straight) step: advance along the chord of the arc.
                let dpsi = seg.curvature() * ds;
                let mid = psi + dpsi / 2.0;
                let chord = if dpsi.abs() > 1e-12 {
                    2.0 * (dpsi / 2.0).sin() / seg.curvature()
                } else {
                    ds
                };
                e += chord * mid.sin();
                n += chord * mid.cos();
                psi += dpsi;
                s += ds;
                vertices.push(TrackVertex {
                    chainage_m: s,
                    east_m: e,
                    north_m: n,
                });
            }
            if s >= length {
                break 'lay;
            }
        }
    }
    (vertices, curvature)
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
            pattern: vec![
                Segment::Curve {
                    radius_m: 500.0,
                    angle_deg: 90.0
                };
                4
            ],
            station_spacing_m: 500.0 * std::f64::consts::TAU - 300.0,
            balise_spacing_m: 1000.0,
            balise_jitter_m: 0.0,
            tunnels: vec![],
            sleeper_spacing_m: 0.6,
            loop_crossing_spacing_m: None,
            vertex_spacing_m: 5.0,
            station_chainages_m: vec![],
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
