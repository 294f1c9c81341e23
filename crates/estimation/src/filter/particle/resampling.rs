//! Resampling schemes: which particles survive, and how many copies of each, given the
//! normalised weights. Every scheme keeps the particle count and gives particle `i` on average
//! `N·wᵢ` copies; they differ in the variance of that count (multinomial the most, systematic
//! usually the least) and in cost.

use rand::RngExt;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Resampling {
    /// N independent draws from the weights.
    Multinomial,
    /// One uniform offset, N evenly spaced pointers.
    Systematic,
    /// One uniform draw inside each of N equal strata.
    Stratified,
    /// ⌊N·wᵢ⌋ copies kept deterministically, the rest drawn multinomially from the residuals.
    Residual,
}

impl Resampling {
    /// Fills `out` with the indices of the surviving particles (`weights.len()` of them, in
    /// increasing order of index).
    pub fn resample(self, weights: &[f64], rng: &mut impl RngExt, out: &mut Vec<usize>) {
        let n = weights.len();
        out.clear();
        match self {
            Resampling::Multinomial => {
                let mut u: Vec<f64> = (0..n).map(|_| rng.random::<f64>()).collect();
                u.sort_by(f64::total_cmp);
                walk(weights, u.into_iter(), out);
            }
            Resampling::Systematic => {
                let u0: f64 = rng.random();
                walk(weights, (0..n).map(|k| (k as f64 + u0) / n as f64), out);
            }
            Resampling::Stratified => {
                let u: Vec<f64> = (0..n)
                    .map(|k| (k as f64 + rng.random::<f64>()) / n as f64)
                    .collect();
                walk(weights, u.into_iter(), out);
            }
            Resampling::Residual => {
                let mut residual = Vec::with_capacity(n);
                for (i, w) in weights.iter().enumerate() {
                    let copies = (n as f64 * w).floor() as usize;
                    out.extend(std::iter::repeat_n(i, copies));
                    residual.push(n as f64 * w - copies as f64);
                }
                let rest = n - out.len();
                let total: f64 = residual.iter().sum();
                if rest > 0 && total > 0.0 {
                    residual.iter_mut().for_each(|r| *r /= total);
                    let mut u: Vec<f64> = (0..rest).map(|_| rng.random::<f64>()).collect();
                    u.sort_by(f64::total_cmp);
                    walk(&residual, u.into_iter(), out);
                    out.sort_unstable();
                }
                // Rounding may leave the deterministic part one short with no residual mass.
                while out.len() < n {
                    out.push(heaviest(weights));
                }
            }
        }
    }
}

/// Walks the cumulative weights with sorted pointers in [0, 1).
fn walk(weights: &[f64], pointers: impl Iterator<Item = f64>, out: &mut Vec<usize>) {
    let last = weights.len() - 1;
    let (mut i, mut cumulative) = (0, weights[0]);
    for u in pointers {
        while u >= cumulative && i < last {
            i += 1;
            cumulative += weights[i];
        }
        out.push(i);
    }
}

fn heaviest(weights: &[f64]) -> usize {
    weights
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const SCHEMES: [Resampling; 4] = [
        Resampling::Multinomial,
        Resampling::Systematic,
        Resampling::Stratified,
        Resampling::Residual,
    ];

    /// Each scheme keeps N particles, and over many rounds the mean number of copies of
    /// particle i is N·wᵢ within 4 standard errors (multinomial variance bounds them all).
    #[test]
    fn every_scheme_keeps_the_count_and_the_expected_copies() {
        let raw = [0.31, 0.002, 0.11, 0.0, 0.05, 0.2, 0.077, 0.151, 0.05, 0.05];
        let total: f64 = raw.iter().sum();
        let w: Vec<f64> = raw.iter().map(|x| x / total).collect();
        let n = w.len();
        let rounds = 20_000;
        for scheme in SCHEMES {
            let mut rng = ChaCha8Rng::seed_from_u64(42);
            let mut copies = vec![0u64; n];
            let mut out = Vec::new();
            for _ in 0..rounds {
                scheme.resample(&w, &mut rng, &mut out);
                assert_eq!(out.len(), n, "{scheme:?}");
                assert!(
                    out.windows(2).all(|p| p[0] <= p[1]),
                    "{scheme:?} not sorted"
                );
                out.iter().for_each(|&i| copies[i] += 1);
            }
            for i in 0..n {
                let mean = copies[i] as f64 / rounds as f64;
                let expected = n as f64 * w[i];
                let se = (n as f64 * w[i] * (1.0 - w[i]) / rounds as f64).sqrt();
                assert!(
                    (mean - expected).abs() <= 4.0 * se + 1e-12,
                    "{scheme:?}: particle {i}: mean {mean}, expected {expected}"
                );
            }
            assert_eq!(copies[3], 0, "{scheme:?} copied a zero-weight particle");
        }
    }

    #[test]
    fn low_variance_schemes_keep_at_least_the_integer_part_of_n_w() {
        let w = [0.55, 0.25, 0.15, 0.05];
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut out = Vec::new();
        for scheme in [Resampling::Systematic, Resampling::Residual] {
            for _ in 0..1000 {
                scheme.resample(&w, &mut rng, &mut out);
                let c0 = out.iter().filter(|&&i| i == 0).count();
                assert!(
                    (2..=3).contains(&c0),
                    "{scheme:?}: {c0} copies of w = 0.55 of 4"
                );
            }
        }
    }
}
