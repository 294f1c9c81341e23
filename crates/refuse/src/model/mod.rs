//! Motion models: how the along-track state moves between two measurements `dt` apart.
//! Every model computes its matrices from the actual `dt` of the log, never from a nominal rate.
//!
//! | model | state | driving noise |
//! |---|---|---|
//! | [`ConstantVelocity`] | `[s, v]` | white acceleration |
//! | [`ConstantAcceleration`] | `[s, v, a]` | white jerk, or a jerk held over each step |
//! | [`Singer`] | `[s, v, a]` | acceleration as a first-order Gauss–Markov process |
//!
//! [`WithSensorStates`] appends sensor calibration states (a GNSS position bias, a speed
//! sensor's scale factor) to any of them.

mod constant_acceleration;
mod constant_velocity;
mod sensor_states;
mod singer;

pub use constant_acceleration::{ConstantAcceleration, ProcessNoise};
pub use constant_velocity::ConstantVelocity;
pub use sensor_states::{SensorState, WithSensorStates};
pub use singer::Singer;

use nalgebra::SMatrix;

/// A linear transition model `x_k = F(dt) x_{k-1} + w`, `w ~ N(0, Q(dt))`.
pub trait TransitionModel<const N: usize> {
    fn transition(&self, dt: f64) -> SMatrix<f64, N, N>;
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N>;
}

impl<const N: usize, M: TransitionModel<N> + ?Sized> TransitionModel<N> for Box<M> {
    fn transition(&self, dt: f64) -> SMatrix<f64, N, N> {
        (**self).transition(dt)
    }
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        (**self).process_noise(dt)
    }
}
