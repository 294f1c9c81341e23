//! Balise reader: reports a balise's surveyed chainage when the antenna passes over it, with
//! a detection-position error and the occasional missed balise.

use railfuse_catalog::messages::{BalisePassage, TrackBalise};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gauss;
use crate::simulator::world::{seconds, Emit, Outbox, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaliseParams {
    pub latency_s: f64,
    /// Where along the balise the passage is detected, 1σ, m.
    pub detection_sigma_m: f64,
    pub miss_probability: f64,
    /// The variance reported with each passage, m².
    pub reported_variance_m2: f64,
}

pub struct BaliseReader {
    p: BaliseParams,
    /// The reader antenna's lever arm x (behind the front end), m.
    along_m: f64,
    rng: ChaCha8Rng,
    balises: Vec<TrackBalise>,
    next: usize,
    /// Detection offset of the next balise, drawn once per balise.
    offset: f64,
}

impl BaliseReader {
    pub fn new(
        p: BaliseParams,
        along_m: f64,
        balises: Vec<TrackBalise>,
        mut rng: ChaCha8Rng,
    ) -> Self {
        let offset = gauss(&mut rng, p.detection_sigma_m);
        Self {
            p,
            along_m,
            rng,
            balises,
            next: 0,
            offset,
        }
    }
}

impl SimSensor for BaliseReader {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        while let Some(b) = self.balises.get(self.next) {
            let at = b.chainage_m + self.offset;
            // Detected when the antenna, not the front end, passes over it.
            if w.chainage_at(self.along_m) < at {
                return;
            }
            if !self.rng.random_bool(self.p.miss_probability) {
                let stamp_ns = w.time_at(at - self.along_m);
                let msg = BalisePassage {
                    stamp_ns,
                    balise_id: b.balise_id.clone(),
                    chainage_m: b.chainage_m,
                    variance_m2: Some(self.p.reported_variance_m2),
                };
                out.push(stamp_ns + seconds(self.p.latency_s), Emit::Balise(msg));
            }
            self.next += 1;
            self.offset = gauss(&mut self.rng, self.p.detection_sigma_m);
        }
    }
}
