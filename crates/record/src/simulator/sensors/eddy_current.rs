//! The eddy-current sensor pair of source 004: two identical sensors `spacing_m` apart along
//! the bogie, about 10 cm above the rail head, each an exciter coil and two pick-up coils
//! wired against each other. What passes under them comes out as pulses, in order along the
//! track:
//!
//! - sleepers (rail clamps) on the atlas's grid with a small laying error, each a bipolar
//!   pulse of its own strength;
//! - switches: long timbers at irregular spacing and the blades and frog, strong and
//!   irregular (the non-stationary part of the signal);
//! - cable crossings and rail defects: single pulses.
//!
//! The bogie's vibration moves the sensors up and down, and the sensitivity falls with the
//! cube of the height; the electronics add white noise; the converter clips at its range and
//! rounds to its step. Both sensors see the same track (the trailing one `spacing_m` later);
//! their gains differ a little. Samples go out in blocks of `block_s`, one
//! [`EddyCurrentBlock`] each, stamped with the first sample's time.

use std::collections::VecDeque;

use railfuse_catalog::messages::{EddyCurrentBlock, SleeperSection, TrackMap, TrackSwitch};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gauss;
use crate::simulator::world::{seconds, Emit, Outbox, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EddyCurrentParams {
    pub rate_hz: f64,
    /// Samples per message, in seconds.
    pub block_s: f64,
    pub latency_s: f64,
    /// Distance D between the two sensors along the track, m.
    pub spacing_m: f64,
    /// Laying error of each sleeper about its grid position, 1σ, m.
    pub sleeper_jitter_m: f64,
    /// Half-width of a sleeper's or a clamp's pulse along the track, m.
    pub pulse_width_m: f64,
    /// Peak of a sleeper's pulse at the nominal height, V, and its spread (relative, 1σ).
    pub sleeper_amplitude_v: f64,
    pub amplitude_spread: f64,
    /// Peak of a switch's blade and frog features, V.
    pub switch_amplitude_v: f64,
    /// Mean distance between cable crossings, m, and their pulse's peak, V.
    pub cable_spacing_m: f64,
    pub cable_amplitude_v: f64,
    /// Rail defects per km and their pulse's peak, V.
    pub defects_per_km: f64,
    pub defect_amplitude_v: f64,
    /// Nominal height above the rail head, m; the vibration's 1σ at speed (it grows with the
    /// speed up to 10 m/s; a standing bogie does not vibrate) and its correlation time.
    pub height_m: f64,
    pub vibration_m: f64,
    pub vibration_s: f64,
    /// White noise of each sensor's electronics, 1σ, V.
    pub noise_v: f64,
    /// The converter: ± range and step, V.
    pub range_v: f64,
    pub lsb_v: f64,
    /// The trailing sensor's gain relative to the leading one's.
    pub gain_b: f64,
}

/// Something in the track an eddy-current sensor responds to.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Feature {
    at_m: f64,
    amplitude_v: f64,
    width_m: f64,
}

impl Feature {
    /// The differential pick-up's response at `x`: a bipolar pulse, ±amplitude at ±width.
    fn response(&self, x: f64) -> f64 {
        let u = (x - self.at_m) / self.width_m;
        if u.abs() > 5.0 {
            return 0.0;
        }
        self.amplitude_v * u * (0.5 * (1.0 - u * u)).exp()
    }

    fn reach_m(&self) -> f64 {
        5.0 * self.width_m
    }
}

/// The track's features in increasing chainage, laid out 10 m at a time as the train reaches
/// them: memory stays flat however long the line.
struct TrackFeatures {
    sections: Vec<SleeperSection>,
    switches: Vec<TrackSwitch>,
    rng: ChaCha8Rng,
    /// Laid up to here, m.
    laid_to_m: f64,
    next_timber_m: Option<f64>,
    next_cable_m: f64,
    p: EddyCurrentParams,
}

const CHUNK_M: f64 = 10.0;

impl TrackFeatures {
    fn new(map: &TrackMap, p: &EddyCurrentParams, mut rng: ChaCha8Rng) -> Self {
        let sections = match map.sleeper_sections.is_empty() {
            true => vec![SleeperSection {
                start_chainage_m: f64::NEG_INFINITY,
                end_chainage_m: f64::INFINITY,
                spacing_m: map.sleeper_spacing_m,
            }],
            false => map.sleeper_sections.clone(),
        };
        let next_cable_m = exponential(&mut rng, p.cable_spacing_m);
        TrackFeatures {
            sections,
            switches: map.switches.clone(),
            rng,
            laid_to_m: -CHUNK_M,
            next_timber_m: None,
            next_cable_m,
            p: p.clone(),
        }
    }

    /// Lays the next 10 m and appends its features in chainage order.
    fn lay(&mut self, out: &mut VecDeque<Feature>) {
        let (a, b) = (self.laid_to_m, self.laid_to_m + CHUNK_M);
        self.laid_to_m = b;
        let p = self.p.clone();
        let mut chunk = Vec::new();
        for s in &self.sections {
            let (lo, hi) = (a.max(s.start_chainage_m), b.min(s.end_chainage_m));
            if lo >= hi {
                continue;
            }
            // Grid positions start + (k + ½)·spacing inside [lo, hi).
            let origin = if s.start_chainage_m.is_finite() {
                s.start_chainage_m
            } else {
                0.0
            };
            let first = ((lo - origin) / s.spacing_m - 0.5).ceil() as i64;
            let mut k = first;
            loop {
                let grid = origin + (k as f64 + 0.5) * s.spacing_m;
                if grid >= hi {
                    break;
                }
                let spread = 1.0 + gauss(&mut self.rng, p.amplitude_spread);
                chunk.push(Feature {
                    at_m: grid + gauss(&mut self.rng, p.sleeper_jitter_m),
                    amplitude_v: p.sleeper_amplitude_v * spread,
                    width_m: p.pulse_width_m,
                });
                k += 1;
            }
        }
        for w in &self.switches {
            let (lo, hi) = (a.max(w.start_chainage_m), b.min(w.end_chainage_m));
            if lo >= hi {
                continue;
            }
            // Long timbers at irregular spacing, stronger than sleepers.
            let mut t = self.next_timber_m.filter(|&t| t >= lo).unwrap_or(lo + 0.3);
            while t < hi {
                chunk.push(Feature {
                    at_m: t,
                    amplitude_v: p.sleeper_amplitude_v * self.rng.random_range(1.2..2.0),
                    width_m: p.pulse_width_m * 1.5,
                });
                t += self.rng.random_range(0.5..0.8);
            }
            self.next_timber_m = Some(t);
            // Blades, check rails and the frog: broad, strong, of either sign, about one a
            // metre.
            let n = (hi - lo).ceil() as usize;
            for _ in 0..n {
                let sign = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
                chunk.push(Feature {
                    at_m: self.rng.random_range(lo..hi),
                    amplitude_v: sign * p.switch_amplitude_v * self.rng.random_range(0.3..1.0),
                    width_m: self.rng.random_range(0.05..0.4),
                });
            }
        }
        while self.next_cable_m < b {
            let sign = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
            chunk.push(Feature {
                at_m: self.next_cable_m,
                amplitude_v: sign * p.cable_amplitude_v,
                width_m: p.pulse_width_m,
            });
            self.next_cable_m += exponential(&mut self.rng, p.cable_spacing_m);
        }
        let defects = poisson(&mut self.rng, p.defects_per_km * CHUNK_M / 1000.0);
        for _ in 0..defects {
            chunk.push(Feature {
                at_m: self.rng.random_range(a..b),
                amplitude_v: p.defect_amplitude_v * self.rng.random_range(0.3..1.0),
                width_m: p.pulse_width_m * 0.5,
            });
        }
        chunk.sort_by(|x, y| x.at_m.total_cmp(&y.at_m));
        out.extend(chunk);
    }
}

fn exponential(rng: &mut impl rand::Rng, mean: f64) -> f64 {
    -mean * (1.0 - rng.random::<f64>()).ln()
}

fn poisson(rng: &mut impl rand::Rng, mean: f64) -> u32 {
    // Knuth: small means only (a chunk's few defects).
    let (l, mut k, mut p) = ((-mean).exp(), 0u32, 1.0);
    loop {
        p *= rng.random::<f64>();
        if p <= l {
            return k;
        }
        k += 1;
    }
}

pub struct EddyCurrentSensor {
    p: EddyCurrentParams,
    /// The leading sensor's lever arm x (behind the front end), m.
    along_m: f64,
    track: TrackFeatures,
    /// Features from behind the trailing sensor's reach to ahead of the leading one's.
    window: VecDeque<Feature>,
    rng: ChaCha8Rng,
    start_ns: u64,
    /// Index of the next sample since the start.
    next_sample: u64,
    /// Time and chainage at the last simulation step.
    last: Option<(u64, f64)>,
    /// The height's deviation from nominal, m.
    height_dev_m: f64,
    block_stamp_ns: u64,
    block_a: Vec<f32>,
    block_b: Vec<f32>,
}

impl EddyCurrentSensor {
    /// `layout_rng` lays the track's features, `rng` draws the vibration and the noise.
    pub fn new(
        p: EddyCurrentParams,
        along_m: f64,
        map: &TrackMap,
        start_ns: u64,
        layout_rng: ChaCha8Rng,
        rng: ChaCha8Rng,
    ) -> Self {
        let n = (p.rate_hz * p.block_s).round() as usize;
        EddyCurrentSensor {
            track: TrackFeatures::new(map, &p, layout_rng),
            p,
            along_m,
            window: VecDeque::new(),
            rng,
            start_ns,
            next_sample: 0,
            last: None,
            height_dev_m: 0.0,
            block_stamp_ns: start_ns,
            block_a: Vec::with_capacity(n),
            block_b: Vec::with_capacity(n),
        }
    }

    fn sample_ns(&self, k: u64) -> u64 {
        self.start_ns + (k as f64 * 1e9 / self.p.rate_hz).round() as u64
    }

    /// Both sensors' outputs with the leading one at chainage `x`.
    fn sample(&mut self, x: f64, speed_mps: f64, dt: f64) -> (f32, f32) {
        let p = &self.p;
        let xb = x - p.spacing_m;
        while self.track.laid_to_m < x + 1.0 {
            self.track.lay(&mut self.window);
        }
        while self
            .window
            .front()
            .is_some_and(|f| f.at_m + f.reach_m() < xb)
        {
            self.window.pop_front();
        }
        let (mut a, mut b) = (0.0, 0.0);
        for f in self.window.iter().take_while(|f| f.at_m - f.reach_m() < x) {
            a += f.response(x);
            b += f.response(xb);
        }
        // Height: a first-order Gauss–Markov process; sensitivity ∝ (h₀ / h)³.
        let phi = (-dt / p.vibration_s).exp();
        let sigma = p.vibration_m * (speed_mps.abs() / 10.0).min(1.0);
        self.height_dev_m =
            phi * self.height_dev_m + gauss(&mut self.rng, sigma * (1.0 - phi * phi).sqrt());
        let gain = (p.height_m / (p.height_m + self.height_dev_m)).powi(3);
        let a = gain * a + gauss(&mut self.rng, p.noise_v);
        let b = gain * p.gain_b * b + gauss(&mut self.rng, p.noise_v);
        (self.convert(a), self.convert(b))
    }

    fn convert(&self, v: f64) -> f32 {
        let v = v.clamp(-self.p.range_v, self.p.range_v);
        ((v / self.p.lsb_v).round() * self.p.lsb_v) as f32
    }
}

impl SimSensor for EddyCurrentSensor {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        // The leading sensor's place on the track.
        let here = w.chainage_at(self.along_m);
        let Some((t0, s0)) = self.last.replace((w.t_ns, here)) else {
            return;
        };
        let span = (w.t_ns - t0) as f64;
        let dt = 1.0 / self.p.rate_hz;
        let per_block = (self.p.rate_hz * self.p.block_s).round() as usize;
        loop {
            let t = self.sample_ns(self.next_sample);
            if t > w.t_ns {
                return;
            }
            // The chainage between the last two steps, linearly.
            let x = s0 + (here - s0) * (t.saturating_sub(t0) as f64 / span);
            if self.block_a.is_empty() {
                self.block_stamp_ns = t;
            }
            let (a, b) = self.sample(x, w.speed_mps, dt);
            self.block_a.push(a);
            self.block_b.push(b);
            self.next_sample += 1;
            if self.block_a.len() == per_block {
                let block = EddyCurrentBlock {
                    stamp_ns: self.block_stamp_ns,
                    sample_rate_hz: self.p.rate_hz,
                    spacing_m: self.p.spacing_m,
                    sensor_a: std::mem::replace(&mut self.block_a, Vec::with_capacity(per_block)),
                    sensor_b: std::mem::replace(&mut self.block_b, Vec::with_capacity(per_block)),
                    volts_per_count: (self.p.lsb_v > 0.0).then_some(self.p.lsb_v),
                };
                out.push(t + seconds(self.p.latency_s), Emit::EddyCurrent(block));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pulse_peaks_at_its_width_with_its_amplitude_and_sign() {
        let f = Feature {
            at_m: 10.0,
            amplitude_v: 0.8,
            width_m: 0.04,
        };
        assert!((f.response(10.04) - 0.8).abs() < 1e-12);
        assert!((f.response(9.96) + 0.8).abs() < 1e-12);
        assert_eq!(f.response(10.0), 0.0);
        assert_eq!(f.response(10.3), 0.0);
    }
}
