use nalgebra::{Matrix3, SMatrix};

use super::TransitionModel;

/// Singer's manoeuvre model on `x = [s, v, a]`: the acceleration is a first-order
/// Gauss–Markov process with time constant `τ` and standard deviation `σ_a`,
///
/// ```text
/// ȧ = −a/τ + w,    w white with PSD 2σ_a²/τ
/// ```
///
/// so a train's traction and braking efforts, which last seconds to tens of seconds, decay
/// back to zero mean instead of persisting for ever as in the constant-acceleration model.
/// `F(dt) = exp(A dt)` in closed form; `Q(dt)` by Van Loan's method (exact, no series cut):
///
/// ```text
/// F(dt) = [[1, dt, (αdt − 1 + e^{−αdt})/α²],
///          [0, 1,  (1 − e^{−αdt})/α       ],
///          [0, 0,  e^{−αdt}               ]],   α = 1/τ
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Singer {
    pub time_constant_s: f64,
    pub acceleration_std_mps2: f64,
}

impl Singer {
    fn continuous(&self) -> (Matrix3<f64>, f64) {
        let alpha = 1.0 / self.time_constant_s;
        let a = Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -alpha);
        (a, 2.0 * self.acceleration_std_mps2.powi(2) * alpha)
    }
}

impl TransitionModel<3> for Singer {
    fn transition(&self, dt: f64) -> Matrix3<f64> {
        let alpha = 1.0 / self.time_constant_s;
        let e = (-alpha * dt).exp();
        Matrix3::new(
            1.0,
            dt,
            (alpha * dt - 1.0 + e) / (alpha * alpha),
            0.0,
            1.0,
            (1.0 - e) / alpha,
            0.0,
            0.0,
            e,
        )
    }

    fn process_noise(&self, dt: f64) -> Matrix3<f64> {
        // Van Loan: exp([[−A, L q Lᵀ], [0, Aᵀ]] dt) = [[·, F⁻¹Q], [0, Fᵀ]].
        let (a, q) = self.continuous();
        let mut m = SMatrix::<f64, 6, 6>::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-a * dt));
        m[(2, 5)] = q * dt;
        m.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(a.transpose() * dt));
        let e = m.exp();
        let f = e.fixed_view::<3, 3>(3, 3).transpose();
        let qd = f * e.fixed_view::<3, 3>(0, 3);
        (qd + qd.transpose()) * 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transition_is_the_matrix_exponential() {
        let m = Singer {
            time_constant_s: 8.0,
            acceleration_std_mps2: 0.3,
        };
        let (a, _) = m.continuous();
        let dt = 0.37;
        assert!(((a * dt).exp() - m.transition(dt)).abs().max() < 1e-12);
    }

    #[test]
    fn noise_adds_up_over_split_steps_and_the_acceleration_settles_at_its_variance() {
        let m = Singer {
            time_constant_s: 5.0,
            acceleration_std_mps2: 0.4,
        };
        let (a, b) = (0.2, 0.9);
        let f = m.transition(b);
        let composed = f * m.process_noise(a) * f.transpose() + m.process_noise(b);
        assert!((composed - m.process_noise(a + b)).abs().max() < 1e-12);
        // Over many time constants the acceleration's variance tends to σ_a².
        assert!((m.process_noise(200.0)[(2, 2)] - 0.16).abs() < 1e-9);
    }
}
