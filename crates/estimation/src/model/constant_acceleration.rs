use nalgebra::{Matrix3, Vector3};

use super::TransitionModel;

/// How the jerk that drives the constant-acceleration model is modelled.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
pub enum ProcessNoise {
    /// Continuous white jerk of power spectral density `q` (m²/s⁵):
    ///
    /// ```text
    /// Q(dt) = q · [[dt⁵/20, dt⁴/8, dt³/6],
    ///              [dt⁴/8,  dt³/3, dt²/2],
    ///              [dt³/6,  dt²/2, dt   ]]
    /// ```
    WhiteJerkPsd(f64),
    /// A jerk `w ~ N(0, σ²)` held over each step, as sources 000 and 001 write it:
    /// `Q(dt) = σ² G Gᵀ`, `G = [dt³/6, dt²/2, dt]ᵀ`.
    PiecewiseJerkVariance(f64),
}

/// The constant-acceleration model on `x = [s, v, a]` (chainage, speed, acceleration):
///
/// ```text
/// F(dt) = [[1, dt, dt²/2],
///          [0, 1,  dt   ],
///          [0, 0,  1    ]]
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantAcceleration {
    pub noise: ProcessNoise,
}

impl TransitionModel<3> for ConstantAcceleration {
    fn transition(&self, dt: f64) -> Matrix3<f64> {
        Matrix3::new(1.0, dt, dt * dt / 2.0, 0.0, 1.0, dt, 0.0, 0.0, 1.0)
    }

    fn process_noise(&self, dt: f64) -> Matrix3<f64> {
        match self.noise {
            ProcessNoise::WhiteJerkPsd(q) => {
                let (d2, d3) = (dt * dt, dt * dt * dt);
                let (d4, d5) = (d3 * dt, d3 * d2);
                q * Matrix3::new(
                    d5 / 20.0,
                    d4 / 8.0,
                    d3 / 6.0,
                    d4 / 8.0,
                    d3 / 3.0,
                    d2 / 2.0,
                    d3 / 6.0,
                    d2 / 2.0,
                    dt,
                )
            }
            ProcessNoise::PiecewiseJerkVariance(var) => {
                let g = Vector3::new(dt * dt * dt / 6.0, dt * dt / 2.0, dt);
                var * g * g.transpose()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transition_composes_over_split_steps() {
        let m = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(1.0),
        };
        let whole = m.transition(0.7);
        let split = m.transition(0.3) * m.transition(0.4);
        assert!((whole - split).abs().max() < 1e-15);
    }

    #[test]
    fn continuous_noise_adds_up_over_split_steps() {
        // For white jerk, Q(a+b) = F(b) Q(a) F(b)ᵀ + Q(b): the model does not depend on how
        // the interval is cut, which is what makes irregular sample times safe.
        let m = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(0.3),
        };
        let (a, b) = (0.25, 0.6);
        let f = m.transition(b);
        let composed = f * m.process_noise(a) * f.transpose() + m.process_noise(b);
        assert!((composed - m.process_noise(a + b)).abs().max() < 1e-12);
    }

    #[test]
    fn piecewise_noise_is_rank_one_and_matches_the_source() {
        let m = ConstantAcceleration {
            noise: ProcessNoise::PiecewiseJerkVariance(0.001),
        };
        let q = m.process_noise(1.0);
        assert!((q[(2, 2)] - 0.001).abs() < 1e-15);
        assert!((q[(0, 0)] - 0.001 / 36.0).abs() < 1e-15);
        assert!(q.determinant().abs() < 1e-20);
    }
}
