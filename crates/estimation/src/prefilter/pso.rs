//! A particle swarm that lives as long as the signal it tunes (source 003, section 1.2.2):
//! acceleration coefficients 2.6, random factors uniform on [0, 1], particle speed at most 10,
//! and "the generation count at time n is n": the swarm takes one generation per sample, so
//! by sample n it has searched for n generations while following a fitness that moves with
//! the signal.
//!
//! With both coefficients at 2.6 (φ = 5.2 > 4) the plain update diverges; the swarm uses
//! Clerc and Kennedy's constriction `χ = 2 / |2 − φ − √(φ² − 4φ)| ≈ 0.351`:
//!
//! ```text
//! v ← χ (v + c₁ r₁ (p − x) + c₂ r₂ (g − x)),   |vⱼ| ≤ v_max,   x ← clamp(x + v)
//! ```
//!
//! Because the fitness moves, every personal best is scored again on the current fitness each
//! generation before the particles are compared (a best found on an old stretch of signal
//! would otherwise hold the swarm for ever), and the particle with the worst best starts
//! again at a random place (a "random immigrant"): a constricted swarm collapses onto one
//! point within tens of generations and could not otherwise follow an optimum that moves.
//!
//! Written here rather than taken from `argmin`: its swarm starts afresh on every run and has
//! no speed limit, and this one must persist across millions of samples and keep the source's
//! speed cap.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The source's acceleration coefficients (cognitive and social).
pub const ACCELERATION: f64 = 2.6;
/// The source's maximum particle speed, per coordinate.
pub const MAX_SPEED: f64 = 10.0;

/// Clerc–Kennedy constriction for `φ = c₁ + c₂`.
pub fn constriction(phi: f64) -> f64 {
    2.0 / (2.0 - phi - (phi * phi - 4.0 * phi).sqrt()).abs()
}

#[derive(Debug, Clone)]
struct Particle<const D: usize> {
    position: [f64; D],
    speed: [f64; D],
    best: [f64; D],
    best_cost: f64,
}

/// A swarm over a box `[low, high]` in `D` dimensions.
#[derive(Debug, Clone)]
pub struct Swarm<const D: usize> {
    particles: Vec<Particle<D>>,
    low: [f64; D],
    high: [f64; D],
    chi: f64,
    rng: ChaCha8Rng,
    best: [f64; D],
    best_cost: f64,
    generations: u64,
}

impl<const D: usize> Swarm<D> {
    /// `size` particles spread uniformly over the box, one of them at `start` (the model's
    /// default, so the swarm is never worse than it from the first generation).
    pub fn new(size: usize, low: [f64; D], high: [f64; D], start: [f64; D], seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let particles = (0..size.max(1))
            .map(|i| {
                let position = match i {
                    0 => start,
                    _ => std::array::from_fn(|j| low[j] + rng.random::<f64>() * (high[j] - low[j])),
                };
                Particle {
                    position,
                    speed: [0.0; D],
                    best: position,
                    best_cost: f64::INFINITY,
                }
            })
            .collect();
        Self {
            particles,
            low,
            high,
            chi: constriction(2.0 * ACCELERATION),
            rng,
            best: start,
            best_cost: f64::INFINITY,
            generations: 0,
        }
    }

    /// The best position of the latest generation.
    pub fn best(&self) -> [f64; D] {
        self.best
    }

    pub fn generations(&self) -> u64 {
        self.generations
    }

    /// One generation against `cost` (lower is better; a NaN counts as worst). Returns the
    /// swarm's best position.
    pub fn generation(&mut self, mut cost: impl FnMut(&[f64; D]) -> f64) -> [f64; D] {
        let score = |c: f64| if c.is_nan() { f64::INFINITY } else { c };
        // The fitness has moved since the last generation: score the bests again, then move.
        self.best_cost = f64::INFINITY;
        for p in &mut self.particles {
            p.best_cost = score(cost(&p.best));
            if p.best_cost < self.best_cost {
                self.best_cost = p.best_cost;
                self.best = p.best;
            }
        }
        let g = self.best;
        let worst = (0..self.particles.len())
            .filter(|&i| self.particles[i].best != g)
            .max_by(|&a, &b| {
                let c = |i: usize| self.particles[i].best_cost;
                c(a).total_cmp(&c(b))
            });
        if let Some(w) = worst {
            let rng = &mut self.rng;
            let (low, high) = (self.low, self.high);
            let position =
                std::array::from_fn(|j| low[j] + rng.random::<f64>() * (high[j] - low[j]));
            self.particles[w] = Particle {
                position,
                speed: [0.0; D],
                best: position,
                best_cost: score(cost(&position)),
            };
        }
        for p in &mut self.particles {
            for j in 0..D {
                let (r1, r2) = (self.rng.random::<f64>(), self.rng.random::<f64>());
                let v = self.chi
                    * (p.speed[j]
                        + ACCELERATION * r1 * (p.best[j] - p.position[j])
                        + ACCELERATION * r2 * (g[j] - p.position[j]));
                p.speed[j] = v.clamp(-MAX_SPEED, MAX_SPEED);
                p.position[j] = (p.position[j] + p.speed[j]).clamp(self.low[j], self.high[j]);
            }
            let c = score(cost(&p.position));
            if c < p.best_cost {
                p.best_cost = c;
                p.best = p.position;
                if c < self.best_cost {
                    self.best_cost = c;
                    self.best = p.position;
                }
            }
        }
        self.generations += 1;
        self.best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constriction_of_the_sources_coefficients() {
        assert!((constriction(5.2) - 0.3510).abs() < 1e-4);
    }

    #[test]
    fn the_swarm_finds_a_minimum_and_follows_it_when_it_moves() {
        let mut swarm = Swarm::<2>::new(8, [0.0, 0.0], [20.0, 1.0], [10.0, 0.5], 1);
        let mut target = [3.0, 0.9];
        for n in 0..200 {
            if n == 100 {
                target = [15.0, 0.2];
            }
            swarm.generation(|x| (x[0] - target[0]).powi(2) + 100.0 * (x[1] - target[1]).powi(2));
            if n == 99 {
                let b = swarm.best();
                assert!(
                    (b[0] - 3.0).abs() < 0.05 && (b[1] - 0.9).abs() < 0.01,
                    "{b:?}"
                );
            }
        }
        let b = swarm.best();
        assert!(
            (b[0] - 15.0).abs() < 0.05 && (b[1] - 0.2).abs() < 0.01,
            "{b:?}"
        );
        assert_eq!(swarm.generations(), 200);
    }

    #[test]
    fn a_seed_gives_the_same_swarm() {
        let run = |seed| {
            let mut s = Swarm::<2>::new(6, [0.0, 0.0], [1.0, 1.0], [0.5, 0.5], seed);
            for _ in 0..20 {
                s.generation(|x| (x[0] - 0.3).abs() + (x[1] - 0.7).abs());
            }
            s.best()
        };
        assert_eq!(run(9), run(9));
        assert_ne!(run(9), run(10));
    }
}
