use nalgebra::{Matrix3, Vector3};

use super::TransitionModel;

/// A constant-acceleration state `[d, v, a]` on one axis driven by a measured acceleration
/// `U` (source 002's `X_k = A X_{k−1} + B U + W`): over a step the train accelerates at `U`,
/// so
///
/// ```text
/// A(dt) = [[1, dt, 0],      B(dt) = [dt²/2, dt, 1]ᵀ
///          [0, 1,  0],
///          [0, 0,  0]]
/// ```
///
/// and the acceleration state is `U` itself. `U`'s error is coloured (it is a smoothed
/// slope) with standard deviation σ and correlation time τ: it enters as `σ² B Bᵀ` for the
/// step, plus white acceleration of PSD `q = 2 σ² τ` on d and v for what it does between
/// steps (the low-frequency power of a first-order process of that σ and τ):
///
/// ```text
/// Q(dt) = σ² B Bᵀ + q [[dt³/3, dt²/2, 0], [dt²/2, dt, 0], [0, 0, 0]]
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelerationInput {
    pub input_std_mps2: f64,
    pub correlation_time_s: f64,
}

impl AccelerationInput {
    /// `B(dt) U`, what the input adds to the state over a step.
    pub fn input_term(&self, dt: f64, u: f64) -> Vector3<f64> {
        Vector3::new(dt * dt / 2.0, dt, 1.0) * u
    }
}

impl TransitionModel<3> for AccelerationInput {
    fn transition(&self, dt: f64) -> Matrix3<f64> {
        Matrix3::new(1.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    }

    fn process_noise(&self, dt: f64) -> Matrix3<f64> {
        let var = self.input_std_mps2 * self.input_std_mps2;
        let b = Vector3::new(dt * dt / 2.0, dt, 1.0);
        let q = 2.0 * var * self.correlation_time_s;
        let white = Matrix3::new(
            dt * dt * dt / 3.0,
            dt * dt / 2.0,
            0.0,
            dt * dt / 2.0,
            dt,
            0.0,
            0.0,
            0.0,
            0.0,
        );
        var * b * b.transpose() + q * white
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_integrates_the_input_exactly() {
        let m = AccelerationInput {
            input_std_mps2: 0.1,
            correlation_time_s: 0.5,
        };
        let x = Vector3::new(100.0, 10.0, 7.0); // the old acceleration is forgotten
        let (dt, u) = (2.0, 0.5);
        let next = m.transition(dt) * x + m.input_term(dt, u);
        assert_eq!(next, Vector3::new(100.0 + 20.0 + 1.0, 11.0, 0.5));
        let q = m.process_noise(dt);
        assert_eq!(q, q.transpose());
        assert!(q.symmetric_eigenvalues().min() > -1e-15);
        assert!((q[(2, 2)] - 0.01).abs() < 1e-15);
    }
}
