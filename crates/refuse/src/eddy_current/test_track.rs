//! A random track for the signal-processing tests: features every centimetre, smoothed over
//! five, and two sensors `D` apart driven along it.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

pub struct Track {
    profile: Vec<f64>,
}

/// The profile's step, m, and length, m.
const STEP_M: f64 = 0.01;
const LENGTH_M: f64 = 20.0;

impl Track {
    pub fn new(seed: u64) -> Self {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = (LENGTH_M / STEP_M) as usize;
        let raw: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
        let profile = (0..n)
            .map(|i| raw[i.saturating_sub(2)..(i + 3).min(n)].iter().sum::<f64>() / 5.0)
            .collect();
        Track { profile }
    }

    /// The profile at `x`, m (linear between its points).
    pub fn at(&self, x: f64) -> f64 {
        let t = x / STEP_M;
        let i = t.floor() as usize;
        let f = t - i as f64;
        self.profile[i] * (1.0 - f) + self.profile[i + 1] * f
    }

    /// `n` samples at `fs` of the leading sensor at `pos(t)` and the trailing one `d` behind.
    pub fn sensor_pair(
        &self,
        pos: impl Fn(f64) -> f64,
        d: f64,
        fs: f64,
        n: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let x = |k: usize| pos(k as f64 / fs);
        let a = (0..n).map(|k| self.at(x(k))).collect();
        let b = (0..n).map(|k| self.at(x(k) - d)).collect();
        (a, b)
    }
}
