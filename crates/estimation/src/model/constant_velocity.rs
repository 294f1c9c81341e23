use nalgebra::Matrix2;

use super::TransitionModel;

/// The constant-velocity model on `x = [s, v]`, driven by continuous white acceleration of
/// power spectral density `q` (m²/s³):
///
/// ```text
/// F(dt) = [[1, dt], [0, 1]],      Q(dt) = q · [[dt³/3, dt²/2], [dt²/2, dt]]
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantVelocity {
    pub acceleration_psd: f64,
}

impl TransitionModel<2> for ConstantVelocity {
    fn transition(&self, dt: f64) -> Matrix2<f64> {
        Matrix2::new(1.0, dt, 0.0, 1.0)
    }

    fn process_noise(&self, dt: f64) -> Matrix2<f64> {
        let (d2, d3) = (dt * dt, dt * dt * dt);
        self.acceleration_psd * Matrix2::new(d3 / 3.0, d2 / 2.0, d2 / 2.0, dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_adds_up_over_split_steps() {
        let m = ConstantVelocity {
            acceleration_psd: 0.4,
        };
        let (a, b) = (0.3, 0.45);
        let f = m.transition(b);
        let composed = f * m.process_noise(a) * f.transpose() + m.process_noise(b);
        assert!((composed - m.process_noise(a + b)).abs().max() < 1e-12);
    }
}
