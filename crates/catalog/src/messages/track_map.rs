use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::geodesy::GeodeticOrigin;

/// A point of the track's centre line with its chainage.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackVertex {
    pub chainage_m: f64,
    pub east_m: f64,
    pub north_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackBalise {
    pub balise_id: String,
    pub chainage_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Tunnel {
    pub name: String,
    pub start_chainage_m: f64,
    pub end_chainage_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Station {
    pub name: String,
    pub chainage_m: f64,
}

/// The static track map: centre line as a polyline in local east/north around `origin`, with
/// chainage at every vertex, and the surveyed infrastructure. Written once, at the start of a
/// log, so the map travels inside the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackMap {
    pub stamp_ns: u64,
    pub name: String,
    pub origin: GeodeticOrigin,
    /// Vertices in increasing chainage.
    pub vertices: Vec<TrackVertex>,
    pub balises: Vec<TrackBalise>,
    pub tunnels: Vec<Tunnel>,
    pub stations: Vec<Station>,
    /// Sleeper (rail clamp) spacing, m.
    pub sleeper_spacing_m: f64,
    /// Distance between cross-induction loop crossings, m, where the line has a loop.
    #[serde(default)]
    pub loop_crossing_spacing_m: Option<f64>,
}

impl TrackMap {
    /// East, north and heading (clockwise from north) at a chainage, interpolated along the
    /// polyline; clamped to the ends.
    pub fn locate(&self, chainage_m: f64) -> Option<(f64, f64, f64)> {
        let v = &self.vertices;
        if v.len() < 2 {
            return None;
        }
        let i = v
            .partition_point(|p| p.chainage_m <= chainage_m)
            .clamp(1, v.len() - 1);
        let (a, b) = (v[i - 1], v[i]);
        let len = b.chainage_m - a.chainage_m;
        let f = if len > 0.0 {
            ((chainage_m - a.chainage_m) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (de, dn) = (b.east_m - a.east_m, b.north_m - a.north_m);
        Some((a.east_m + f * de, a.north_m + f * dn, de.atan2(dn)))
    }

    /// Chainage and track heading of the point of the centre line nearest to (east, north):
    /// map matching of a position fix. Clamped to the ends of the line.
    pub fn project(&self, east_m: f64, north_m: f64) -> Option<(f64, f64)> {
        let mut best: Option<(f64, f64, f64)> = None;
        for w in self.vertices.windows(2) {
            let (a, b) = (w[0], w[1]);
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
                best = Some((
                    d2,
                    a.chainage_m + f * (b.chainage_m - a.chainage_m),
                    de.atan2(dn),
                ));
            }
        }
        best.map(|(_, s, h)| (s, h))
    }

    pub fn length_m(&self) -> f64 {
        self.vertices.last().map_or(0.0, |v| v.chainage_m)
    }

    pub fn in_tunnel(&self, chainage_m: f64) -> Option<&Tunnel> {
        self.tunnels
            .iter()
            .find(|t| (t.start_chainage_m..=t.end_chainage_m).contains(&chainage_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_inverts_locate_on_a_bent_line() {
        let origin = GeodeticOrigin {
            latitude_deg: 44.6,
            longitude_deg: 10.9,
            altitude_m: 30.0,
        };
        let vertices = vec![
            TrackVertex {
                chainage_m: 0.0,
                east_m: 0.0,
                north_m: 0.0,
            },
            TrackVertex {
                chainage_m: 100.0,
                east_m: 100.0,
                north_m: 0.0,
            },
            TrackVertex {
                chainage_m: 200.0,
                east_m: 100.0,
                north_m: 100.0,
            },
        ];
        let map = TrackMap {
            stamp_ns: 0,
            name: "t".into(),
            origin,
            vertices,
            balises: vec![],
            tunnels: vec![],
            stations: vec![],
            sleeper_spacing_m: 0.6,
            loop_crossing_spacing_m: None,
        };
        for s in [5.0, 99.0, 150.0, 199.0] {
            let (e, n, h) = map.locate(s).unwrap();
            let (s2, h2) = map.project(e + 0.5 * h.cos(), n - 0.5 * h.sin()).unwrap();
            assert!((s2 - s).abs() < 1e-9 && (h2 - h).abs() < 1e-12, "{s}: {s2}");
        }
    }
}
