//! Cross-induction loop: a position fix at every cable crossing the train passes. Each
//! crossing's surveyed chainage carries an installation error, and the survey's scale error
//! makes the position error grow with distance, as source 000 describes.

use railfuse_catalog::messages::LoopPosition;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gauss;
use crate::simulator::world::{seconds, Emit, Outbox, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopParams {
    pub crossing_spacing_m: f64,
    pub latency_s: f64,
    /// Installation error of each crossing, 1σ, m.
    pub installation_sigma_m: f64,
    /// Relative scale error of the surveyed chainages (error grows with distance).
    pub scale_error: f64,
    /// Jitter of the crossing detection, s.
    pub timing_sigma_s: f64,
    /// The variance the loop reports with each fix, m².
    pub reported_variance_m2: f64,
}

pub struct InductionLoop {
    p: LoopParams,
    /// The loop antenna's lever arm x (behind the front end), m.
    along_m: f64,
    rng: ChaCha8Rng,
    next_crossing: u32,
}

impl InductionLoop {
    pub fn new(p: LoopParams, along_m: f64, rng: ChaCha8Rng) -> Self {
        Self {
            p,
            along_m,
            rng,
            next_crossing: 1,
        }
    }
}

impl SimSensor for InductionLoop {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        let p = &self.p;
        loop {
            let at = self.next_crossing as f64 * p.crossing_spacing_m;
            // The antenna's place, which the loop reports, crosses it.
            if w.chainage_at(self.along_m) < at {
                return;
            }
            let jitter = gauss(&mut self.rng, p.timing_sigma_s);
            let stamp_ns = (w.time_at(at - self.along_m) as i64 + (jitter * 1e9) as i64) as u64;
            let reported =
                at * (1.0 + p.scale_error) + gauss(&mut self.rng, p.installation_sigma_m);
            let msg = LoopPosition {
                stamp_ns,
                chainage_m: reported,
                crossing: Some(self.next_crossing),
                variance_m2: Some(p.reported_variance_m2),
            };
            out.push(stamp_ns + seconds(p.latency_s), Emit::Loop(msg));
            self.next_crossing += 1;
        }
    }
}
