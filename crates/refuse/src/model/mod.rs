//! Motion models: how the along-track state moves between two measurements `dt` apart.
//! Every model computes its matrices from the actual `dt` of the log, never from a nominal rate.

mod constant_acceleration;

pub use constant_acceleration::{ConstantAcceleration, ProcessNoise};

use nalgebra::SMatrix;

/// A linear transition model `x_k = F(dt) x_{k-1} + w`, `w ~ N(0, Q(dt))`.
pub trait TransitionModel<const N: usize> {
    fn transition(&self, dt: f64) -> SMatrix<f64, N, N>;
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N>;
}
