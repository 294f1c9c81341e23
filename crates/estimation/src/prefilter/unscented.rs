//! The unscented transform (Julier and Uhlmann): the mean and covariance of `y = f(x)` for a
//! Gaussian `x`, from `2n + 1` sigma points, without linearising `f`. Source 003 puts it on the
//! observation of its RLS pre-filter; here it carries a GNSS receiver's speed and course, with
//! their variances, into east and north velocity (`v sin c`, `v cos c`), which is not linear
//! and at low speed not even close: the course's error is large there and a linearisation
//! understates the spread and biases the mean.
//!
//! ```text
//! χ₀ = x̄,  χᵢ = x̄ ± (√((n + κ) P))ᵢ,     W₀ = κ / (n + κ),  Wᵢ = 1 / (2 (n + κ))
//! ȳ = Σ Wᵢ f(χᵢ),                         P_yy = Σ Wᵢ (f(χᵢ) − ȳ)(f(χᵢ) − ȳ)ᵀ
//! ```
//!
//! `κ = 3 − n` (Julier's choice for a Gaussian: the sigma points then match its fourth
//! moments too); for the two inputs used here `κ = 1` and every weight is positive, so `P_yy`
//! stays positive semi-definite.

use nalgebra::{SMatrix, SVector};

use crate::filter::{sqrt_psd, symmetric};

pub fn unscented<const N: usize, const M: usize>(
    mean: &SVector<f64, N>,
    covariance: &SMatrix<f64, N, N>,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, M>,
) -> (SVector<f64, M>, SMatrix<f64, M, M>) {
    let n = N as f64;
    let kappa = 3.0 - n;
    let spread = n + kappa;
    let l = sqrt_psd(&(covariance * spread));
    let w0 = kappa / spread;
    let wi = 1.0 / (2.0 * spread);
    let centre = f(mean);
    let sides: Vec<SVector<f64, M>> = (0..N)
        .flat_map(|i| {
            let column = l.column(i).into_owned();
            [f(&(mean + column)), f(&(mean - column))]
        })
        .collect();
    let y = centre * w0 + sides.iter().fold(SVector::zeros(), |acc, s| acc + s * wi);
    let outer = |s: &SVector<f64, M>| (s - y) * (s - y).transpose();
    let pyy = outer(&centre) * w0
        + sides
            .iter()
            .fold(SMatrix::zeros(), |acc, s| acc + outer(s) * wi);
    (y, symmetric(pyy))
}

/// East and north velocity from speed `v` and course `c` (clockwise from north), with the
/// variances of both.
pub fn velocity_from_speed_and_course(
    speed_mps: f64,
    speed_variance: f64,
    course_rad: f64,
    course_variance: f64,
) -> (SVector<f64, 2>, SMatrix<f64, 2, 2>) {
    unscented(
        &SVector::<f64, 2>::new(speed_mps, course_rad),
        &SMatrix::<f64, 2, 2>::new(speed_variance, 0.0, 0.0, course_variance),
        |x| SVector::<f64, 2>::new(x[0] * x[1].sin(), x[0] * x[1].cos()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_for_a_linear_function() {
        let mean = SVector::<f64, 2>::new(1.0, -2.0);
        let p = SMatrix::<f64, 2, 2>::new(2.0, 0.3, 0.3, 0.5);
        let a = SMatrix::<f64, 2, 2>::new(1.0, 2.0, -1.0, 0.5);
        let (y, pyy) = unscented(&mean, &p, |x| a * x);
        assert!((y - a * mean).norm() < 1e-12);
        assert!((pyy - a * p * a.transpose()).norm() < 1e-12);
    }

    #[test]
    fn velocity_matches_monte_carlo_where_linearising_does_not() {
        // 1 m/s with a 0.6 rad course error: the mean speed vector shrinks by exp(−σ²/2).
        let (v, sv, c, sc) = (1.0, 0.01, 0.3, 0.36);
        let (y, pyy) = velocity_from_speed_and_course(v, sv, c, sc);
        let shrink = (-sc / 2.0f64).exp();
        assert!((y[0] - v * c.sin() * shrink).abs() < 0.02, "{y}");
        assert!((y[1] - v * c.cos() * shrink).abs() < 0.02, "{y}");
        // Total variance: E|v|² − |E v|² = (v² + sv) − v² shrink².
        let total = pyy[(0, 0)] + pyy[(1, 1)];
        let exact = v * v + sv - v * v * shrink * shrink;
        assert!((total - exact).abs() / exact < 0.15, "{total} vs {exact}");
    }
}
