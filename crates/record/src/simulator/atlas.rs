//! The sleeper layout and the switches of a simulated line: source 004's "electromagnetic
//! atlas". Machine-laid track keeps one sleeper spacing (0.60–0.65 m) over a section of a
//! few kilometres; switches sit near the stations (one either side of a platform) and
//! interrupt the regular layout. The simulator's true sleepers lie on each section's grid
//! with a small laying error ([`super::sensors::eddy_current`]); the map carries the grid.

use railfuse_catalog::messages::{SleeperSection, TrackMap, TrackSwitch};
use rand::RngExt;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AtlasParams {
    /// Length of a section of one spacing, m: drawn uniformly in this range.
    pub section_m: (f64, f64),
    /// Sleeper spacing of a section, m: drawn uniformly in this range.
    pub spacing_m: (f64, f64),
    /// Switches this far before and after each station, m (none at a line's ends).
    pub switch_offset_m: f64,
    pub switch_length_m: f64,
    /// More switches, at these chainages (a yard), m.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra_switches_m: Vec<f64>,
}

/// `map` with its atlas: switches near the stations (and any extra ones), and sleeper
/// sections covering the rest of the line in increasing chainage.
pub fn with_atlas(mut map: TrackMap, p: &AtlasParams, rng: &mut impl rand::Rng) -> TrackMap {
    let length = map.length_m();
    let mut at: Vec<f64> = map
        .stations
        .iter()
        .flat_map(|s| {
            [
                s.chainage_m - p.switch_offset_m,
                s.chainage_m + p.switch_offset_m,
            ]
        })
        .chain(p.extra_switches_m.iter().copied())
        .filter(|&c| c > 1.0 && c + p.switch_length_m < length - 1.0)
        .collect();
    at.sort_by(f64::total_cmp);
    at.dedup_by(|b, a| *b < *a + p.switch_length_m + 10.0);
    map.switches = at
        .iter()
        .enumerate()
        .map(|(i, &c)| TrackSwitch {
            name: format!("W{}", i + 1),
            start_chainage_m: c,
            end_chainage_m: c + p.switch_length_m,
        })
        .collect();
    let mut sections = Vec::new();
    let mut start = 0.0;
    let mut switches = map.switches.iter().peekable();
    while start < length {
        let mut end = (start + rng.random_range(p.section_m.0..p.section_m.1)).min(length);
        // A section ends where a switch begins; the next one starts after it.
        let next = switches
            .peek()
            .map(|w| (w.start_chainage_m, w.end_chainage_m));
        let resume = match next {
            Some((a, b)) if a < end => {
                end = a;
                switches.next();
                b
            }
            _ => end,
        };
        sections.push(SleeperSection {
            start_chainage_m: start,
            end_chainage_m: end,
            spacing_m: rng.random_range(p.spacing_m.0..p.spacing_m.1),
        });
        start = resume;
    }
    map.sleeper_sections = sections;
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::messages::{AnyMessage, MessageKind, Station, TrackVertex};
    use rand::SeedableRng;

    #[test]
    fn sections_tile_the_line_between_the_switches() {
        let AnyMessage::TrackMap(mut map) = MessageKind::TrackMap.example() else {
            panic!("a map example")
        };
        map.vertices.push(TrackVertex::at(12_000.0, 12_000.0, 0.0));
        map.stations = vec![
            Station {
                name: "A".into(),
                chainage_m: 0.0,
            },
            Station {
                name: "B".into(),
                chainage_m: 6000.0,
            },
        ];
        let p = AtlasParams {
            section_m: (800.0, 2500.0),
            spacing_m: (0.60, 0.65),
            switch_offset_m: 200.0,
            switch_length_m: 35.0,
            extra_switches_m: vec![3000.0],
        };
        let map = with_atlas(map, &p, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        let starts: Vec<f64> = map.switches.iter().map(|w| w.start_chainage_m).collect();
        assert_eq!(starts, [200.0, 3000.0, 5800.0, 6200.0]);
        let s = &map.sleeper_sections;
        assert_eq!(s[0].start_chainage_m, 0.0);
        assert_eq!(s.last().unwrap().end_chainage_m, 12_000.0);
        for pair in s.windows(2) {
            let gap = (pair[0].end_chainage_m, pair[1].start_chainage_m);
            // Contiguous, or a switch's length apart.
            assert!(
                gap.0 == gap.1
                    || map
                        .switches
                        .iter()
                        .any(|w| (w.start_chainage_m, w.end_chainage_m) == gap),
                "{gap:?}"
            );
        }
        assert!(s.iter().all(|x| (0.60..0.65).contains(&x.spacing_m)));
        assert_eq!(
            map.sleeper_spacing_at(5000.0),
            s.iter()
                .find(|x| x.end_chainage_m > 5000.0)
                .unwrap()
                .spacing_m
        );
    }
}
