//! What stands beside the line, for source 002's safety experiment (`--scenario seed002`):
//! parallel tracks through the stations, GNSS multipath near station buildings and in
//! cuttings (fixes pulled sideways, towards the parallel track, without the receiver knowing;
//! no RTK corrections in a cutting), and the published map's own survey error.
//!
//! The simulator drives the true track; the log's `/track/map` is the surveyed one: the
//! centre line resampled every `map_survey_spacing_m` with a lateral error that wanders along
//! the line (first-order Gauss–Markov in chainage: σ, correlation length), and the parallel
//! tracks beside each station.

use railfuse_catalog::messages::{TrackLine, TrackMap, TrackVertex};
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::sensors::gauss;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SiteParams {
    /// A parallel track beside each station: this far either side of it (m), offset this
    /// far to the left of the direction of increasing chainage (m).
    pub station_track_half_length_m: f64,
    pub station_track_offset_m: f64,
    /// Multipath near station buildings: within this distance of a station (m), fixes are
    /// pulled up to this far to the left (m), rising and falling smoothly.
    pub station_multipath_m: f64,
    pub station_multipath_bias_m: f64,
    /// Cuttings (start, end chainage, m): no RTK corrections reach the receiver, and fixes
    /// are pulled up to `cutting_multipath_bias_m` to the left.
    pub cuttings: Vec<(f64, f64)>,
    pub cutting_multipath_bias_m: f64,
    /// The share of the sky a receiver sees at the deepest point of a cutting (1: all of it,
    /// as in source 002's line); the satellites in view fall with it and HDOP rises.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub cutting_sky_view: f64,
    /// The published map's survey error, lateral: σ (m), correlation length along the line
    /// (m), and the spacing of the surveyed vertices (m).
    pub map_survey_std_m: f64,
    pub map_survey_correlation_m: f64,
    pub map_survey_spacing_m: f64,
}

/// What the site does to a fix at one place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteEffect {
    /// The multipath pull, m to the left of the direction of increasing chainage.
    pub multipath_left_m: f64,
    /// In a cutting: no RTK corrections.
    pub in_cutting: bool,
    /// The share of the sky in view (1 in the open).
    pub sky_view: f64,
}

impl Default for SiteEffect {
    fn default() -> Self {
        Self {
            multipath_left_m: 0.0,
            in_cutting: false,
            sky_view: 1.0,
        }
    }
}

fn one() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// The point `left_m` to the left of `map`'s main line at `chainage_m`, with that chainage.
fn left_of(map: &TrackMap, chainage_m: f64, left_m: f64) -> TrackVertex {
    let (e, n, h) = map.locate(chainage_m).expect("a built track has vertices");
    // Left of heading h (clockwise from north) is (−cos h, sin h).
    TrackVertex::at(chainage_m, e - left_m * h.cos(), n + left_m * h.sin())
}

/// A smooth bump: 0 outside `[a, b]`, rising to 1 in the middle (a raised cosine).
fn bump(s: f64, a: f64, b: f64) -> f64 {
    if s <= a || s >= b || b <= a {
        return 0.0;
    }
    let x = (s - a) / (b - a);
    0.5 - 0.5 * (std::f64::consts::TAU * x).cos()
}

impl SiteParams {
    /// The site's effect at chainage `s`, with stations at `stations` (chainages).
    pub fn at(&self, s: f64, stations: &[f64]) -> SiteEffect {
        let near_station = stations
            .iter()
            .map(|&c| {
                bump(
                    s,
                    c - self.station_multipath_m,
                    c + self.station_multipath_m,
                )
            })
            .fold(0.0, f64::max);
        let cutting = self
            .cuttings
            .iter()
            .map(|&(a, b)| bump(s, a, b))
            .fold(0.0, f64::max);
        SiteEffect {
            multipath_left_m: near_station * self.station_multipath_bias_m
                + cutting * self.cutting_multipath_bias_m,
            in_cutting: self.cuttings.iter().any(|&(a, b)| s >= a && s < b),
            sky_view: 1.0 - cutting * (1.0 - self.cutting_sky_view),
        }
    }

    /// The map as surveyed: the true centre line resampled with its lateral survey error,
    /// and a parallel track beside each station.
    pub fn surveyed(&self, truth: &TrackMap, rng: &mut impl Rng) -> TrackMap {
        let (start, length) = (first_chainage(truth), truth.length_m());
        let step = self.map_survey_spacing_m.max(1.0);
        let phi = (-step / self.map_survey_correlation_m.max(step)).exp();
        let mut error = gauss(rng, self.map_survey_std_m);
        let mut vertices = Vec::new();
        let mut s = start;
        loop {
            vertices.push(left_of(truth, s, error));
            if s >= length {
                break;
            }
            s = (s + step).min(length);
            error = phi * error + gauss(rng, self.map_survey_std_m * (1.0 - phi * phi).sqrt());
        }
        let other_tracks = truth
            .stations
            .iter()
            .map(|st| {
                let (a, b) = (
                    (st.chainage_m - self.station_track_half_length_m).max(start),
                    (st.chainage_m + self.station_track_half_length_m).min(length),
                );
                let n = ((b - a) / step).ceil().max(1.0) as usize;
                let vertices = (0..=n)
                    .map(|k| {
                        let c = a + (b - a) * k as f64 / n as f64;
                        left_of(truth, c, self.station_track_offset_m)
                    })
                    .collect();
                TrackLine {
                    name: format!("{} track 2", st.name),
                    vertices,
                }
            })
            .collect();
        let mut map = TrackMap {
            vertices,
            other_tracks,
            ..truth.clone()
        };
        with_profile_of(truth, &mut map);
        map
    }
}

/// Where `map`'s main line starts: a line with a lead-in starts before chainage 0.
fn first_chainage(map: &TrackMap) -> f64 {
    map.vertices.first().map_or(0.0, |v| v.chainage_m)
}

/// `map`'s vertices (each track's) given `truth`'s height and cant at their chainage where
/// `truth` has them: a survey errs across the track, and the line's gradient and cant are the
/// truth's (without them a pipeline would take a hilly, canted line for a flat one).
fn with_profile_of(truth: &TrackMap, map: &mut TrackMap) {
    let (heights, cant) = (truth.has_heights(), truth.has_cant());
    let tracks = std::iter::once(&mut map.vertices)
        .chain(map.other_tracks.iter_mut().map(|t| &mut t.vertices));
    for v in tracks.flatten() {
        v.height_m = heights.then(|| truth.height_at(v.chainage_m));
        v.cant_m = cant.then(|| truth.cant_at(v.chainage_m));
    }
}

/// `map` with each stretch `(from, to, left)` of its main line shifted `left` m to the left
/// (`map:offset` faults), easing in and out over [`OFFSET_RAMP_M`] at each end as a blunder
/// joined to the good survey would: the line resampled every `spacing_m`, and at the ends of
/// each stretch and its ramps.
pub fn with_offsets(map: &TrackMap, stretches: &[(f64, f64, f64)], spacing_m: f64) -> TrackMap {
    let (start, length) = (first_chainage(map), map.length_m());
    let r = OFFSET_RAMP_M;
    let mut marks: Vec<f64> = stretches
        .iter()
        .flat_map(|&(a, b, _)| [a - r, a, b, b + r])
        .collect();
    let n = ((length - start) / spacing_m).ceil() as usize;
    marks.extend((0..=n).map(|k| (start + k as f64 * spacing_m).min(length)));
    marks.retain(|s| (start..=length).contains(s));
    marks.sort_by(f64::total_cmp);
    marks.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let vertices = marks
        .iter()
        .map(|&s| {
            let left: f64 = stretches
                .iter()
                .map(|&(a, b, d)| d * ((s - (a - r)) / r).min(((b + r) - s) / r).clamp(0.0, 1.0))
                .sum();
            left_of(map, s, left)
        })
        .collect();
    let mut shifted = TrackMap {
        vertices,
        ..map.clone()
    };
    with_profile_of(map, &mut shifted);
    shifted
}

/// The length over which a map offset eases in and out, m.
pub const OFFSET_RAMP_M: f64 = 100.0;

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::geodesy::GeodeticOrigin;
    use railfuse_catalog::messages::Station;
    use rand::SeedableRng;

    /// A track map of these vertices and stations near Modena.
    fn line(vertices: Vec<TrackVertex>, stations: Vec<Station>) -> TrackMap {
        let origin = GeodeticOrigin {
            latitude_deg: 44.6,
            longitude_deg: 10.9,
            altitude_m: 0.0,
        };
        TrackMap {
            stations,
            ..TrackMap::line("t", origin, vertices)
        }
    }

    fn params() -> SiteParams {
        SiteParams {
            station_track_half_length_m: 400.0,
            station_track_offset_m: 4.5,
            station_multipath_m: 300.0,
            station_multipath_bias_m: 3.0,
            cuttings: vec![(2000.0, 2600.0)],
            cutting_multipath_bias_m: 2.0,
            cutting_sky_view: 0.35,
            map_survey_std_m: 0.1,
            map_survey_correlation_m: 200.0,
            map_survey_spacing_m: 20.0,
        }
    }

    #[test]
    fn an_offset_stretch_moves_only_between_its_ends() {
        let v = |c: f64| TrackVertex::at(c, c, 0.0);
        let truth = line(vec![v(0.0), v(1000.0)], vec![]);
        let m = with_offsets(&truth, &[(300.0, 455.0, 5.0)], 50.0);
        let at = |c: f64| {
            m.vertices
                .iter()
                .find(|x| x.chainage_m == c)
                .unwrap()
                .north_m
        };
        // Eastbound: left is north; full offset from 300 to 455, easing over 100 m each side.
        assert_eq!(
            (at(200.0), at(250.0), at(300.0), at(400.0)),
            (0.0, 2.5, 5.0, 5.0)
        );
        assert_eq!((at(455.0), at(555.0), at(600.0)), (5.0, 0.0, 0.0));
        assert_eq!(m.check(), Ok(()));
    }

    /// Without the line's heights and cant a pipeline takes a hilly line for a flat one (and
    /// leaves a 40 ‰ gradient's 0.39 m/s² in its dead reckoning); without its lead-in a long
    /// train's rear sensors start off the map.
    #[test]
    fn the_surveyed_and_the_offset_maps_keep_the_lines_lead_in_heights_and_cant() {
        let v = |c: f64, up: f64, cant: f64| TrackVertex {
            height_m: Some(up),
            cant_m: Some(cant),
            ..TrackVertex::at(c, c, 0.0)
        };
        let station = Station {
            name: "A".into(),
            chainage_m: 500.0,
        };
        // A lead-in before chainage 0, as the railway's (room behind the start for the train).
        let truth = line(
            vec![v(-100.0, -2.0, 0.0), v(1000.0, 20.0, 0.15)],
            vec![station],
        );
        let surveyed = params().surveyed(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        let offset = with_offsets(&truth, &[(300.0, 455.0, 5.0)], 50.0);
        for m in [&surveyed, &offset] {
            assert_eq!(m.check(), Ok(()));
            assert_eq!(m.vertices[0].chainage_m, -100.0, "the lead-in is kept");
            for c in [110.0, 500.0, 930.0] {
                assert!((m.height_at(c) - truth.height_at(c)).abs() < 1e-9, "at {c}");
                assert!((m.cant_at(c) - truth.cant_at(c)).abs() < 1e-9, "at {c}");
            }
        }
        let side = &surveyed.other_tracks[0].vertices[0];
        assert_eq!(side.height_m, Some(2.0));
    }

    #[test]
    fn multipath_peaks_at_stations_and_in_cuttings_and_vanishes_elsewhere() {
        let p = params();
        let stations = [0.0, 5000.0];
        assert!((p.at(5000.0, &stations).multipath_left_m - 3.0).abs() < 1e-9);
        assert_eq!(p.at(1000.0, &stations), SiteEffect::default());
        let c = p.at(2300.0, &stations);
        assert!((c.multipath_left_m - 2.0).abs() < 1e-9 && c.in_cutting);
    }

    #[test]
    fn the_surveyed_map_wanders_by_its_survey_error_and_has_station_tracks() {
        let truth = line(
            vec![
                TrackVertex::at(0.0, 0.0, 0.0),
                TrackVertex::at(20_000.0, 0.0, 20_000.0),
            ],
            vec![Station {
                name: "A".into(),
                chainage_m: 10_000.0,
            }],
        );
        let m = params().surveyed(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        assert_eq!(m.check(), Ok(()));
        // Due north: the survey error is all in east.
        let err: Vec<f64> = m.vertices.iter().map(|v| v.east_m).collect();
        let rms = (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt();
        assert!((0.05..0.2).contains(&rms), "{rms}");
        let side = &m.other_tracks[0];
        assert!(
            (side.vertices[0].east_m + 4.5).abs() < 1e-9,
            "left of north is west"
        );
        assert_eq!(side.vertices[0].chainage_m, 9600.0);
    }
}
