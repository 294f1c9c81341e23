//! Doppler radar: speed over ground with a scale-factor error, speed-dependent noise, no echo
//! at standstill and occasional echo losses.

use railfuse_catalog::messages::RadarSpeed;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gauss;
use crate::simulator::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RadarParams {
    pub rate_hz: f64,
    pub latency_s: f64,
    /// Multiplicative error (mounting angle, calibration): measured = true · (1 + scale_error).
    pub scale_error: f64,
    /// Noise σ = sigma_base + sigma_per_mps · v.
    pub sigma_base_mps: f64,
    pub sigma_per_mps: f64,
    /// Below this speed the radar sees no Doppler shift it can use.
    pub min_speed_mps: f64,
    /// Chance per sample that an echo loss begins, and its length range (s).
    pub dropout_probability: f64,
    pub dropout_s: (f64, f64),
}

pub struct Radar {
    p: RadarParams,
    /// Its lever arm's x (behind the front end), m.
    along_m: f64,
    schedule: Schedule,
    rng: ChaCha8Rng,
    dropout_until_ns: u64,
}

impl Radar {
    pub fn new(p: RadarParams, along_m: f64, start_ns: u64, rng: ChaCha8Rng) -> Self {
        Self {
            schedule: Schedule::new(start_ns, p.rate_hz),
            p,
            along_m,
            rng,
            dropout_until_ns: 0,
        }
    }
}

impl SimSensor for Radar {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        if !self.schedule.due(w.t_ns) {
            return;
        }
        let p = &self.p;
        if w.t_ns >= self.dropout_until_ns && self.rng.random_bool(p.dropout_probability) {
            self.dropout_until_ns =
                w.t_ns + seconds(self.rng.random_range(p.dropout_s.0..p.dropout_s.1));
        }
        // Over the ground under it, along the rail.
        let ground = w.rail_speed_at(self.along_m);
        let sigma = p.sigma_base_mps + p.sigma_per_mps * w.speed_mps;
        let valid = w.speed_mps >= p.min_speed_mps && w.t_ns >= self.dropout_until_ns;
        let msg = if valid {
            let speed = (ground * (1.0 + p.scale_error) + gauss(&mut self.rng, sigma)).max(0.0);
            RadarSpeed {
                stamp_ns: w.t_ns,
                speed_mps: speed,
                quality: (0.9 + gauss(&mut self.rng, 0.03)).clamp(0.5, 1.0),
                valid: true,
                speed_variance_m2ps2: Some(sigma * sigma),
            }
        } else {
            RadarSpeed {
                stamp_ns: w.t_ns,
                speed_mps: 0.0,
                quality: 0.0,
                valid: false,
                speed_variance_m2ps2: None,
            }
        };
        out.push(w.t_ns + seconds(p.latency_s), Emit::Radar(msg));
    }
}
