//! Sensor states: calibration errors of individual sensors estimated beside the motion.
//!
//! Some sensor errors are not noise but slowly varying offsets that white measurement noise
//! cannot describe, and a filter that ignores them is both wrong and overconfident:
//!
//! | state | sensor model | dynamics |
//! |---|---|---|
//! | [`SensorState::ChainageBias`] `b` | `z = s + b + v` (a GNSS receiver's wandering position error) | first-order Gauss–Markov: `b_k = e^{−dt/τ} b_{k−1} + w`, `Var w = σ² (1 − e^{−2dt/τ})` |
//! | [`SensorState::AccelerationBias`] `b` | `z = a + b + v` (an accelerometer's bias) | first-order Gauss–Markov, as above |
//! | [`SensorState::ScaleFactor`] `k` | `z = (1 + k) v_train + v` (Doppler radar, worn wheels), or `z = (1 + k) s + v` (a loop's surveyed chainages off by a scale, so that its error grows along the line) | random walk: `k_k = k_{k−1} + w`, `Var w = q dt` |
//!
//! They are appended after the motion states: `x = [s, v, (a), b…, k…]`, with a block-diagonal
//! transition and process noise ([`WithSensorStates`]).

use nalgebra::SMatrix;

use super::TransitionModel;
use crate::quantity::Quantity;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SensorState {
    /// Along-track position bias, m: stationary standard deviation and correlation time.
    ChainageBias { std_m: f64, time_constant_s: f64 },
    /// Accelerometer bias, m/s²: stationary standard deviation and correlation time.
    AccelerationBias { std_mps2: f64, time_constant_s: f64 },
    /// Scale factor of a speed or a chainage (dimensionless, 0.003 = reads 0.3 % high): the
    /// quantity it scales, prior standard deviation and random-walk intensity (1/s).
    ScaleFactor {
        quantity: Quantity,
        std: f64,
        walk_per_s: f64,
    },
}

impl SensorState {
    /// Its name in configs and fused states.
    pub fn kind(&self) -> &'static str {
        match self {
            SensorState::ChainageBias { .. } => "chainage_bias",
            SensorState::AccelerationBias { .. } => "acceleration_bias",
            SensorState::ScaleFactor { .. } => "scale_factor",
        }
    }

    /// The quantity of its sensor's measurement that it enters.
    pub fn quantity(&self) -> Quantity {
        match *self {
            SensorState::ChainageBias { .. } => Quantity::Chainage,
            SensorState::AccelerationBias { .. } => Quantity::Acceleration,
            SensorState::ScaleFactor { quantity, .. } => quantity,
        }
    }

    /// Its prior standard deviation.
    pub fn std(&self) -> f64 {
        match *self {
            SensorState::ChainageBias { std_m: std, .. }
            | SensorState::AccelerationBias { std_mps2: std, .. } => std,
            SensorState::ScaleFactor { std, .. } => std,
        }
    }

    fn transition(&self, dt: f64) -> f64 {
        match *self {
            SensorState::ChainageBias {
                time_constant_s, ..
            }
            | SensorState::AccelerationBias {
                time_constant_s, ..
            } => (-dt / time_constant_s).exp(),
            SensorState::ScaleFactor { .. } => 1.0,
        }
    }

    fn process_noise(&self, dt: f64) -> f64 {
        match *self {
            SensorState::ChainageBias {
                std_m: std,
                time_constant_s,
            }
            | SensorState::AccelerationBias {
                std_mps2: std,
                time_constant_s,
            } => std * std * -(-2.0 * dt / time_constant_s).exp_m1(),
            SensorState::ScaleFactor { walk_per_s, .. } => walk_per_s * dt,
        }
    }
}

/// A `B`-state motion model with `N − B` sensor states appended.
pub struct WithSensorStates<const B: usize, const N: usize> {
    pub motion: Box<dyn TransitionModel<B>>,
    pub states: Vec<SensorState>,
}

impl<const B: usize, const N: usize> TransitionModel<N> for WithSensorStates<B, N> {
    fn transition(&self, dt: f64) -> SMatrix<f64, N, N> {
        let mut f = SMatrix::<f64, N, N>::identity();
        f.fixed_view_mut::<B, B>(0, 0)
            .copy_from(&self.motion.transition(dt));
        for (i, s) in self.states.iter().enumerate() {
            f[(B + i, B + i)] = s.transition(dt);
        }
        f
    }

    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        let mut q = SMatrix::<f64, N, N>::zeros();
        q.fixed_view_mut::<B, B>(0, 0)
            .copy_from(&self.motion.process_noise(dt));
        for (i, s) in self.states.iter().enumerate() {
            q[(B + i, B + i)] = s.process_noise(dt);
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ConstantAcceleration, ProcessNoise};

    fn model() -> WithSensorStates<3, 5> {
        WithSensorStates {
            motion: Box::new(ConstantAcceleration {
                noise: ProcessNoise::WhiteJerkPsd(0.3),
            }),
            states: vec![
                SensorState::ChainageBias {
                    std_m: 2.0,
                    time_constant_s: 60.0,
                },
                SensorState::ScaleFactor {
                    quantity: Quantity::Speed,
                    std: 0.01,
                    walk_per_s: 1e-8,
                },
            ],
        }
    }

    #[test]
    fn sensor_states_keep_their_stationary_variance_and_compose_over_split_steps() {
        let m = model();
        let (a, b) = (0.25, 0.6);
        let f = m.transition(b);
        let composed = f * m.process_noise(a) * f.transpose() + m.process_noise(b);
        assert!((composed - m.process_noise(a + b)).abs().max() < 1e-12);
        assert!(
            (m.transition(a + b) - m.transition(b) * m.transition(a))
                .abs()
                .max()
                < 1e-15
        );
        // A Gauss–Markov bias at its stationary variance stays there.
        let (phi, q) = (m.transition(3.0)[(3, 3)], m.process_noise(3.0)[(3, 3)]);
        assert!((phi * 4.0 * phi + q - 4.0).abs() < 1e-12);
        // Motion and sensor states are independent in one step.
        assert_eq!(m.transition(1.0)[(0, 3)], 0.0);
        assert_eq!(m.process_noise(1.0)[(1, 4)], 0.0);
    }
}
