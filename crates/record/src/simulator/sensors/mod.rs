//! Simulated sensors, one module each. Every sensor owns its RNG stream (seed and stream
//! index), so adding or changing one sensor never changes what another one measures.

pub mod balise;
pub mod eddy_current;
pub mod gnss;
pub mod imu;
pub mod induction_loop;
pub mod odometer;
pub mod radar;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The RNG stream of one sensor for one seed.
pub fn rng_stream(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// A zero-mean normal draw (σ may be 0).
pub fn gauss(rng: &mut impl rand::Rng, sigma: f64) -> f64 {
    use rand_distr::{Distribution, StandardNormal};
    let z: f64 = StandardNormal.sample(rng);
    z * sigma
}

/// Rounds to the sensor's least significant bit.
pub fn quantise(x: f64, lsb: f64) -> f64 {
    if lsb > 0.0 {
        (x / lsb).round() * lsb
    } else {
        x
    }
}
