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
//!
//! The innovations of a consistent filter are white (Mehra's test). A sensor whose error
//! drifts makes them correlated, and then its readings carry less information than their
//! count: with `ρ` the lag-one correlation over the window, where it stands out of chance
//! (`ρ > 2/√n`), `R̂` is multiplied by `(1 + ρ)/(1 − ρ)` (`ρ` at most 0.9), the variance of
//! the mean of an AR(1) sequence over that of a white one. A filter that follows a drifting
//! loop sees innovations no larger than its stated noise, but correlated.

use std::collections::VecDeque;

use super::Innovation;

/// The innovations of one sensor quantity over a window, and the variance they show.
#[derive(Debug, Clone, PartialEq)]
pub struct CovarianceMatching {
    window: usize,
    /// `ν² − H P Hᵀ` of the last `window` innovations.
    excess: VecDeque<f64>,
    /// The last `window` innovations, for their correlation.
    residuals: VecDeque<f64>,
}

impl CovarianceMatching {
    /// Over the last `window` innovations (at least 1).
    pub fn new(window: usize) -> Self {
        let window = window.max(1);
        Self {
            window,
            excess: VecDeque::with_capacity(window),
            residuals: VecDeque::with_capacity(window),
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
        if i.residual.is_finite() {
            if self.residuals.len() == self.window {
                self.residuals.pop_front();
            }
            self.residuals.push_back(i.residual);
        }
        // Summed afresh: a window is tens of samples, and a running sum would drift.
        let n = self.excess.len().max(1) as f64;
        let matched = stated.max(self.excess.iter().sum::<f64>() / n);
        matched * self.correlation_inflation()
    }

    /// `(1 + ρ)/(1 − ρ)` for a lag-one correlation `ρ` of the innovations that chance does
    /// not explain; 1 otherwise.
    fn correlation_inflation(&self) -> f64 {
        let r = &self.residuals;
        let n = r.len();
        if n < 3 {
            return 1.0;
        }
        let power: f64 = r.iter().map(|x| x * x).sum();
        let lag: f64 = r.iter().zip(r.iter().skip(1)).map(|(a, b)| a * b).sum();
        let rho = (lag / power.max(f64::MIN_POSITIVE)).clamp(0.0, 0.9);
        // Only a correlation the window can tell from chance.
        if rho < 2.0 / (n as f64).sqrt() {
            return 1.0;
        }
        (1.0 + rho) / (1.0 - rho)
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
        // Small readings of either sign: white.
        let sign = |k: usize| if k % 2 == 0 { 1.0 } else { -1.0 };
        for k in 0..20 {
            m.variance(stated, &Innovation::new(0.1 * sign(k), hph + stated));
        }
        // A 3 m jump: the first reading already fused with a twentieth of its square.
        let r = m.variance(stated, &Innovation::new(3.0, hph + stated));
        assert!(r > 0.4, "{r}");
        // Twenty good readings later the stated variance is back.
        for k in 0..20 {
            m.variance(stated, &Innovation::new(0.05 * sign(k), hph + stated));
        }
        assert_eq!(
            m.variance(stated, &Innovation::new(0.05, hph + stated)),
            stated
        );
    }

    #[test]
    fn correlated_innovations_weigh_less_than_their_size_says() {
        // Innovations no larger than the stated noise, but following each other (a drift):
        // an AR(1) sequence with ρ = 0.8.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let white = Normal::new(0.0, 0.1).unwrap();
        let (stated, hph) = (0.01, 0.0);
        let mut m = CovarianceMatching::new(10);
        let mut x = 0.0;
        let mut total = 0.0;
        for _ in 0..2000 {
            x = 0.8 * x + 0.6 * white.sample(&mut rng);
            total += m.variance(stated, &Innovation::new(x, hph + stated));
        }
        let mean = total / 2000.0;
        assert!(mean > 3.0 * stated, "{mean}");
    }

    #[test]
    fn a_non_finite_innovation_changes_nothing() {
        let mut m = CovarianceMatching::new(5);
        let stated = 0.01;
        let r = m.variance(stated, &Innovation::new(f64::NAN, 0.03));
        assert_eq!(r, stated);
    }
}
