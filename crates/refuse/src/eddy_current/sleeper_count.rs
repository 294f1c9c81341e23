//! Distance by counting sleepers (source 004 §5). The band-passed signal of one sensor is
//! nearly a sine at the sleeper frequency: one upward zero crossing (with hysteresis, so noise
//! at a standstill counts nothing) per sleeper. Each crossing is placed on the distance axis
//! by the speed estimate (the "space domain") and judged against the sleeper spacing the atlas
//! gives there:
//!
//! - about one spacing after the last one: a sleeper;
//! - much less: a spurious crossing (a defect, a cable), not counted;
//! - about n spacings: n − 1 sleepers missed (a weak clamp), counted all the same;
//! - anything else, or inside a switch the map knows: an irregular section, bridged by the
//!   dead-reckoned distance until regular sleepers come back.
//!
//! "About" is statistical: within 4 median absolute deviations of the recent spacing ratios
//! (at least ±20 %), so a well-laid track is held to a tight tolerance and a rough one gets
//! room. Distance = Σ counted sleepers × their section's spacing, plus bridged stretches.

use std::collections::VecDeque;

/// How one crossing was judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Crossing {
    /// `n` sleepers counted (more than one: missed ones filled in).
    Counted(u32),
    Spurious,
    Irregular,
}

#[derive(Debug, Clone)]
pub struct SleeperCounter {
    /// Below −h then above +h counts one crossing; h follows the signal's level.
    armed: bool,
    mean_square: f64,
    /// Dead-reckoned distance at the last counted crossing.
    last_m: Option<f64>,
    ratios: VecDeque<f64>,
    /// Bridging an irregular section since this dead-reckoned distance.
    bridging_from: Option<f64>,
    pub sleepers: u64,
    pub distance_m: f64,
    pub missed_filled: u64,
    pub spurious: u64,
    pub irregular: u64,
}

impl Default for SleeperCounter {
    fn default() -> Self {
        SleeperCounter {
            armed: false,
            mean_square: 0.0,
            last_m: None,
            ratios: VecDeque::new(),
            bridging_from: None,
            sleepers: 0,
            distance_m: 0.0,
            missed_filled: 0,
            spurious: 0,
            irregular: 0,
        }
    }
}

const RATIOS: usize = 64;

impl SleeperCounter {
    /// The distance at dead-reckoned `odometer_m`: the count's, and dead reckoning since the
    /// last sleeper counted (or through the stretch being bridged).
    pub fn distance_at(&self, odometer_m: f64) -> f64 {
        let from = self.bridging_from.or(self.last_m).unwrap_or(odometer_m);
        self.distance_m + (odometer_m - from).max(0.0)
    }

    /// The signal stopped (a gap, a refused block): what comes next is bridged from the last
    /// sleeper by dead reckoning.
    pub fn restart(&mut self) {
        self.armed = false;
        if self.bridging_from.is_none() {
            self.bridging_from = self.last_m;
        }
    }

    /// The tolerance on a spacing ratio: 4 MADs of the recent ones, at least 0.2.
    fn tolerance(&self) -> f64 {
        if self.ratios.len() < 8 {
            return 0.25;
        }
        let mut r: Vec<f64> = self.ratios.iter().copied().collect();
        let mid = r.len() / 2;
        let median = *r.select_nth_unstable_by(mid, f64::total_cmp).1;
        let mut dev: Vec<f64> = r.iter().map(|x| (x - median).abs()).collect();
        let mad = *dev.select_nth_unstable_by(mid, f64::total_cmp).1;
        (4.0 * 1.4826 * mad).clamp(0.2, 0.35)
    }

    /// One band-passed sample `y` at dead-reckoned distance `odometer_m`, where the atlas
    /// says sleepers lie `spacing_m` apart; `irregular` when the map puts the sensor in a
    /// switch. A crossing, when this sample made one.
    pub fn sample(
        &mut self,
        y: f64,
        odometer_m: f64,
        spacing_m: f64,
        irregular: bool,
    ) -> Option<Crossing> {
        self.mean_square += 1e-3 * (y * y - self.mean_square);
        if irregular {
            if self.bridging_from.is_none() {
                self.bridging_from = Some(self.last_m.unwrap_or(odometer_m));
            }
            return None;
        }
        let h = 0.3 * self.mean_square.sqrt();
        if y < -h {
            self.armed = true;
            return None;
        }
        if !(self.armed && y > h) {
            return None;
        }
        self.armed = false;
        Some(self.crossing(odometer_m, spacing_m))
    }

    fn crossing(&mut self, at_m: f64, spacing_m: f64) -> Crossing {
        if let Some(from) = self.bridging_from.take() {
            // Back on regular sleepers: the irregular stretch by dead reckoning.
            self.distance_m += (at_m - from).max(0.0);
            self.last_m = Some(at_m);
            self.irregular += 1;
            return Crossing::Irregular;
        }
        let Some(last) = self.last_m else {
            self.last_m = Some(at_m);
            return Crossing::Counted(0);
        };
        let ratio = (at_m - last) / spacing_m;
        let tol = self.tolerance();
        let n = ratio.round();
        if n < 1.0 || (ratio - n).abs() > tol * n.sqrt() {
            if ratio < 1.0 - tol {
                self.spurious += 1;
                return Crossing::Spurious;
            }
            // Neither a sleeper nor a whole number of them: bridge to the next crossing.
            self.bridging_from = Some(last);
            self.irregular += 1;
            return self.crossing(at_m, spacing_m);
        }
        if self.ratios.len() == RATIOS {
            self.ratios.pop_front();
        }
        self.ratios.push_back(ratio / n);
        let n = n as u32;
        self.sleepers += n as u64;
        self.missed_filled += (n - 1) as u64;
        self.distance_m += n as f64 * spacing_m;
        self.last_m = Some(at_m);
        Crossing::Counted(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sleeper pulses as a band-passed signal: a sine per sleeper, positions given.
    fn run(c: &mut SleeperCounter, sleepers: &[f64], end_m: f64, switch: Option<(f64, f64)>) {
        let dx = 0.005;
        let mut x = 0.0;
        while x < end_m {
            // The nearest sleeper's phase: a crossing at each sleeper.
            let i = sleepers.partition_point(|&s| s < x);
            let (a, b) = match i {
                0 => (sleepers[0] - 0.625, sleepers[0]),
                i if i >= sleepers.len() => (sleepers[i - 1], sleepers[i - 1] + 0.625),
                i => (sleepers[i - 1], sleepers[i]),
            };
            let phase = (x - a) / (b - a);
            let y = (std::f64::consts::TAU * phase).sin();
            let inside = switch.is_some_and(|(p, q)| (p..q).contains(&x));
            c.sample(y, x, 0.625, inside);
            x += dx;
        }
    }

    #[test]
    fn counting_returns_the_known_number_through_missed_sleepers_defects_and_a_switch() {
        // 400 sleepers 0.625 m apart with 8 mm laying error; sleepers 100 and 101 missed
        // (weak clamps: 1.875 m between crossings), and a switch from 150 m to 180 m where
        // the map says counting stops.
        let mut rng = 1u64;
        let mut jitter = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((rng >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 0.016
        };
        let all: Vec<f64> = (0..400)
            .map(|k| 0.3 + k as f64 * 0.625 + jitter())
            .collect();
        let switch = (150.0, 180.0);
        let visible: Vec<f64> = all
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != 100 && *k != 101)
            .map(|(_, &s)| s)
            .collect();
        let mut c = SleeperCounter::default();
        run(&mut c, &visible, 250.0, Some(switch));
        // Distance from the first crossing to the last, against the truth.
        let first = visible[0];
        let last = *visible.iter().rev().find(|&&s| s < 249.9).unwrap();
        assert!((c.distance_m - (last - first)).abs() < 0.1, "{c:?}");
        assert_eq!(c.missed_filled, 2, "{c:?}");
        assert_eq!(c.irregular, 1, "{c:?}");
        let in_switch = all.iter().filter(|&&s| (150.0..180.0).contains(&s)).count() as u64;
        let counted = all.iter().filter(|&&s| s >= first && s <= last).count() as u64 - 1;
        // Every sleeper outside the switch is counted, those in it are bridged by distance.
        assert!(
            c.sleepers.abs_diff(counted - in_switch) <= 1,
            "{} {}",
            c.sleepers,
            counted - in_switch
        );
    }
}
