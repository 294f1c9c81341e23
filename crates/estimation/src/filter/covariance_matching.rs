//! Covariance matching (Mehra 1972): a sensor's measurement variance estimated from its own
//! innovations. For a consistent filter `E[ν²] = H P Hᵀ + R`, so over the last `window`
//! innovations
//!
//! ```text
//! R̂ = max(R_stated, mean(ν_i² − H P_i Hᵀ))
//! ```
//!
//! Never below the stated variance: a sensor that turns out worse than it claims (a loop
//! whose error accumulates with distance, a wheel on a wet rail) is weighted by what it does,
//! while one as good as it says keeps about its stated weight. The current innovation counts
//! before it is used, so that the first of a run of surprising measurements is already
//! down-weighted: after a balise moves the estimate metres off a drifting loop, the loop's
//! next reading pulls it back by centimetres, not by half the gap.

use std::collections::VecDeque;

use super::Innovation;

/// The innovations of one sensor quantity over a window, and the variance they show.
#[derive(Debug, Clone, PartialEq)]
pub struct CovarianceMatching {
    window: usize,
    /// `ν² − H P Hᵀ` of the last `window` innovations.
    excess: VecDeque<f64>,
}

impl CovarianceMatching {
    /// Over the last `window` innovations (at least 1).
    pub fn new(window: usize) -> Self {
        let window = window.max(1);
        Self {
            window,
            excess: VecDeque::with_capacity(window),
        }
    }

    /// Takes the innovation `i` that a measurement of stated variance `stated` makes (its
    /// `variance` is `H P Hᵀ + stated`) and returns the variance to fuse it with.
    pub fn variance(&mut self, stated: f64, i: &Innovation) -> f64 {
        let excess = i.residual * i.residual - (i.variance - stated);
        if excess.is_finite() {
            if self.excess.len() == self.window {
                self.excess.pop_front();
            }
            self.excess.push_back(excess);
        }
        // Summed afresh: a window is tens of samples, and a running sum would drift.
        let n = self.excess.len().max(1) as f64;
        stated.max(self.excess.iter().sum::<f64>() / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The mean variance over `steps` innovations of a sensor whose errors have variance
    /// `actual`, stated `stated`, with `H P Hᵀ = hph`.
    fn mean_variance(actual: f64, stated: f64, hph: f64, steps: usize) -> f64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, (hph + actual).sqrt()).unwrap();
        let mut m = CovarianceMatching::new(20);
        let total: f64 = (0..steps)
            .map(|_| {
                m.variance(
                    stated,
                    &Innovation::new(noise.sample(&mut rng), hph + stated),
                )
            })
            .sum();
        total / steps as f64
    }

    #[test]
    fn a_sensor_as_good_as_it_says_keeps_about_its_stated_variance() {
        let r = mean_variance(0.01, 0.01, 0.02, 5000);
        // Never below, and above only by the spread of a 20-sample mean.
        assert!((0.01..0.015).contains(&r), "{r}");
    }

    #[test]
    fn a_sensor_ten_times_worse_than_it_says_is_weighted_by_what_it_does() {
        let r = mean_variance(0.1, 0.01, 0.02, 5000);
        assert!((0.08..0.12).contains(&r), "{r}");
    }

    #[test]
    fn the_first_surprise_is_already_down_weighted_and_the_weight_comes_back() {
        let mut m = CovarianceMatching::new(20);
        let (stated, hph) = (0.01, 0.02);
        for _ in 0..20 {
            m.variance(stated, &Innovation::new(0.1, hph + stated));
        }
        // A 3 m jump: the first reading already fused with a twentieth of its square.
        let r = m.variance(stated, &Innovation::new(3.0, hph + stated));
        assert!(r > 0.4, "{r}");
        // Twenty good readings later the stated variance is back.
        for _ in 0..20 {
            m.variance(stated, &Innovation::new(0.05, hph + stated));
        }
        assert_eq!(
            m.variance(stated, &Innovation::new(0.05, hph + stated)),
            stated
        );
    }

    #[test]
    fn a_non_finite_innovation_changes_nothing() {
        let mut m = CovarianceMatching::new(5);
        let stated = 0.01;
        let r = m.variance(stated, &Innovation::new(f64::NAN, 0.03));
        assert_eq!(r, stated);
    }
}
