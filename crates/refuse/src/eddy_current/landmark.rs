//! Absolute position from switches (source 004's "electromagnetic atlas"): a switch's blades,
//! frog and long timbers make the signal stronger and irregular for the switch's length. The
//! signal's level, averaged over the last 2 m of travel, is watched against its usual level
//! (a slow average over about 200 m of plain track); a stretch of at least 8 m above 1.6
//! times it is a switch passage. Its middle, matched to the nearest switch of the map's atlas
//! within `search_m` of where the pipeline thinks it is, fixes the chainage there.

use railfuse_catalog::messages::TrackMap;

/// Averaging distances, m.
const LEVEL_M: f64 = 2.0;
const USUAL_M: f64 = 200.0;
/// A passage: above `ENTER` times the usual level, until below `LEAVE` times it, at least
/// `MIN_LENGTH_M` long.
const ENTER: f64 = 1.6;
const LEAVE: f64 = 1.3;
const MIN_LENGTH_M: f64 = 8.0;

/// A switch seen in the signal and found in the map.
#[derive(Debug, Clone, PartialEq)]
pub struct Fix {
    pub name: String,
    /// The switch's middle in the map, and the correction to the chainage there.
    pub chainage_m: f64,
    pub correction_m: f64,
}

#[derive(Debug, Clone, Default)]
pub struct SwitchDetector {
    level: f64,
    usual: Option<f64>,
    /// Odometer where the passage began.
    inside_from: Option<f64>,
    travelled: f64,
}

impl SwitchDetector {
    /// One low-passed sample `x` after `ds` m of travel, at odometer `odometer_m`, where the
    /// pipeline's chainage is `chainage_m`: a fix when a passage just ended on a switch of the
    /// map within `search_m`.
    pub fn sample(
        &mut self,
        x: f64,
        ds: f64,
        odometer_m: f64,
        chainage_m: f64,
        map: Option<&TrackMap>,
        search_m: f64,
    ) -> Option<Fix> {
        if ds <= 0.0 {
            return None;
        }
        self.travelled += ds;
        self.level += (x.abs() - self.level) * (ds / LEVEL_M).min(1.0);
        if self.travelled < LEVEL_M {
            return None;
        }
        let usual = *self.usual.get_or_insert(self.level);
        match self.inside_from {
            None if self.level > ENTER * usual && self.travelled > USUAL_M => {
                self.inside_from = Some(odometer_m - LEVEL_M);
            }
            None => {
                self.usual = Some(usual + (self.level - usual) * (ds / USUAL_M).min(1.0));
            }
            Some(from) if self.level < LEAVE * usual => {
                self.inside_from = None;
                // The level lags by about its averaging distance.
                let to = odometer_m - LEVEL_M;
                if to - from < MIN_LENGTH_M {
                    return None;
                }
                let middle = chainage_m - (odometer_m - 0.5 * (from + to));
                return nearest_switch(map?, middle, search_m);
            }
            Some(_) => {}
        }
        None
    }
}

fn nearest_switch(map: &TrackMap, middle: f64, search_m: f64) -> Option<Fix> {
    map.switches
        .iter()
        .map(|w| (w, 0.5 * (w.start_chainage_m + w.end_chainage_m)))
        .filter(|(_, c)| (c - middle).abs() <= search_m)
        .min_by(|a, b| (a.1 - middle).abs().total_cmp(&(b.1 - middle).abs()))
        .map(|(w, c)| Fix {
            name: w.name.clone(),
            chainage_m: c,
            correction_m: c - middle,
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::messages::{AnyMessage, MessageKind, TrackSwitch};

    #[test]
    fn a_strong_stretch_is_found_in_the_map_and_fixes_the_chainage() {
        let AnyMessage::TrackMap(mut map) = MessageKind::TrackMap.example() else {
            panic!("a map example")
        };
        map.switches = vec![TrackSwitch {
            name: "W1".into(),
            start_chainage_m: 400.0,
            end_chainage_m: 430.0,
        }];
        let mut d = SwitchDetector::default();
        let ds = 0.01;
        // The pipeline thinks it is 12 m further than it is.
        let offset = 12.0;
        let mut fixes = Vec::new();
        let mut x: f64 = 0.0;
        while x < 600.0 {
            let strong = (400.0..430.0).contains(&x);
            let level = if strong { 2.5 } else { 1.0 };
            // A pulse-like signal: the level times a fast oscillation.
            let s = level * (x * 40.0).sin();
            if let Some(f) = d.sample(s, ds, x, x + offset, Some(&map), 50.0) {
                fixes.push(f);
            }
            x += ds;
        }
        assert_eq!(fixes.len(), 1, "{fixes:?}");
        assert_eq!(fixes[0].name, "W1");
        assert!((fixes[0].correction_m + offset).abs() < 1.5, "{fixes:?}");
    }
}
