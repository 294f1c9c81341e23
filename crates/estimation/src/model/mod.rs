//! Motion models: how the along-track state moves between two measurements `dt` apart.
//! Every model computes its matrices from the actual `dt` of the log, never from a nominal rate.
//!
//! | model | state | driving noise |
//! |---|---|---|
//! | [`ConstantVelocity`] | `[s, v]` | white acceleration |
//! | [`ConstantAcceleration`] | `[s, v, a]` | white jerk, or a jerk held over each step |
//! | [`Singer`] | `[s, v, a]` | acceleration as a first-order Gauss–Markov process |
//! | [`AccelerationInput`] | `[d, v, a]` on one axis | a measured acceleration `U` and its error |
//!
//! [`WithSensorStates`] appends sensor calibration states (a GNSS position bias, a speed
//! sensor's scale factor) to any of them.

mod acceleration_input;
mod constant_acceleration;
mod constant_velocity;
mod sensor_states;
mod singer;

pub use acceleration_input::AccelerationInput;
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

/// The motion model of a pipeline, its process noise chosen: what a configuration's `motion`
/// table becomes once validated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionModel {
    ConstantVelocity(ConstantVelocity),
    ConstantAcceleration(ConstantAcceleration),
    Singer(Singer),
}

impl MotionModel {
    /// Its motion states: `[s, v]` or `[s, v, a]`.
    pub fn dimension(&self) -> usize {
        match self {
            MotionModel::ConstantVelocity(_) => 2,
            MotionModel::ConstantAcceleration(_) | MotionModel::Singer(_) => 3,
        }
    }

    /// The transition model of an `N`-state pipeline: these motion states followed by
    /// `states`. `N` is [`dimension`](Self::dimension) plus the number of sensor states.
    pub fn with_sensor_states<const N: usize>(
        &self,
        states: Vec<SensorState>,
    ) -> Box<dyn TransitionModel<N>> {
        debug_assert_eq!(self.dimension() + states.len(), N);
        match *self {
            MotionModel::ConstantVelocity(m) => Box::new(WithSensorStates::<2, N> {
                motion: Box::new(m),
                states,
            }),
            MotionModel::ConstantAcceleration(m) => Box::new(WithSensorStates::<3, N> {
                motion: Box::new(m),
                states,
            }),
            MotionModel::Singer(m) => Box::new(WithSensorStates::<3, N> {
                motion: Box::new(m),
                states,
            }),
        }
    }
}
