//! A smooth curve through noisy points of one line: for east and north each, a penalised
//! cubic B-spline of chainage (a P-spline, Eilers & Marx 1996).
//!
//! Knots lie every `h` metres from `start`; at chainage `s` four basis functions are non-zero
//! and the curve is `z(s) = Σ_k c_k B_k(s)`. The coefficients minimise
//!
//! ```text
//! Σ_i w_i (z_i − z(s_i))²  +  λ Σ_k (Δ²c_k)²
//! ```
//!
//! The penalty's pull on the curve goes as its fourth derivative, which a circular arc (to
//! within κ³h⁴) and a straight do not have: only where the curvature changes does it smooth,
//! over about `L`. Where there are no points (a tunnel, a stretch without RTK) it bridges the
//! gap with the curve of least bending that joins both sides (a cubic, as a draughtsman's
//! spline), well conditioned over kilometres, where a third-difference penalty's quadratic
//! bridge over hundreds of knots is not. The normal equations `(BᵀWB + λ D₂ᵀD₂) c = BᵀW z`
//! have seven diagonals and are solved in O(n) ([`crate::banded`]).
//!
//! λ comes from a smoothing length `L` as `λ = w̄ (L / h)⁴`, w̄ the points' weight per
//! coefficient, so the balance does not change with the number of runs. Its bias grows
//! steeply with `L`: on a 400 m radius, 0.03 mm at 5 m, 2 mm at 10 m, 0.3 m at 25 m
//! (noise-free, knots every 5 m); 10 m, the default, still averages a few fixes a side.

use crate::banded::{BandMatrix, NotPositiveDefinite};

/// Uniform knots over a chainage span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knots {
    pub start_m: f64,
    pub spacing_m: f64,
    /// Number of coefficients (intervals + 3).
    pub count: usize,
}

impl Knots {
    /// Knots every `spacing_m` covering `[from_m, to_m]`.
    pub fn covering(from_m: f64, to_m: f64, spacing_m: f64) -> Self {
        let intervals = ((to_m - from_m) / spacing_m).ceil().max(1.0) as usize;
        Self {
            start_m: from_m,
            spacing_m,
            count: intervals + 3,
        }
    }

    pub fn end_m(&self) -> f64 {
        self.start_m + (self.count - 3) as f64 * self.spacing_m
    }

    /// The first of the four coefficients that act at `s` and the position in its interval
    /// (0–1); `s` is clamped to the span.
    fn locate(&self, s: f64) -> (usize, f64) {
        let x = ((s - self.start_m) / self.spacing_m).clamp(0.0, (self.count - 3) as f64);
        let k = (x.floor() as usize).min(self.count - 4);
        (k, x - k as f64)
    }
}

/// The uniform cubic B-spline's four basis values at `u` in its interval.
fn basis(u: f64) -> [f64; 4] {
    let v = 1.0 - u;
    [
        v * v * v / 6.0,
        (3.0 * u * u * u - 6.0 * u * u + 4.0) / 6.0,
        (-3.0 * u * u * u + 3.0 * u * u + 3.0 * u + 1.0) / 6.0,
        u * u * u / 6.0,
    ]
}

/// Their derivatives with respect to `u`.
fn basis_derivative(u: f64) -> [f64; 4] {
    let v = 1.0 - u;
    [
        -v * v / 2.0,
        (9.0 * u * u - 12.0 * u) / 6.0,
        (-9.0 * u * u + 6.0 * u + 3.0) / 6.0,
        u * u / 2.0,
    ]
}

/// A fitted plane curve: east and north as splines of chainage.
#[derive(Debug, Clone)]
pub struct PlaneSpline {
    pub knots: Knots,
    east: Vec<f64>,
    north: Vec<f64>,
}

/// A fitted height profile: the top of rail's height as a spline of chainage.
#[derive(Debug, Clone)]
pub struct ProfileSpline {
    pub knots: Knots,
    up: Vec<f64>,
}

impl ProfileSpline {
    /// The penalised least-squares fit of `(chainage, weight, height)` points on `knots`,
    /// smoothing over about `smoothing_m`: the plane's fit, on one coordinate.
    pub fn fit(
        knots: Knots,
        points: &[(f64, f64, f64)],
        smoothing_m: f64,
    ) -> Result<Self, NotPositiveDefinite> {
        let [up] = fit_columns(
            &knots,
            points.iter().map(|&(s, w, h)| (s, w, [h])),
            smoothing_m,
        )?;
        Ok(Self { knots, up })
    }

    /// The height at chainage `s` (clamped to the knots' span).
    pub fn at(&self, s: f64) -> f64 {
        let (k, u) = self.knots.locate(s);
        let b = basis(u);
        (0..4).map(|i| b[i] * self.up[k + i]).sum()
    }
}

/// One point to fit: its chainage, position and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub chainage_m: f64,
    pub east_m: f64,
    pub north_m: f64,
    pub weight: f64,
}

/// The penalised least-squares coefficients of `C` coordinates at once on `knots`, each point
/// `(chainage, weight, values)`, smoothing over about `smoothing_m`: one system, `C` solves.
fn fit_columns<const C: usize>(
    knots: &Knots,
    points: impl Iterator<Item = (f64, f64, [f64; C])>,
    smoothing_m: f64,
) -> Result<[Vec<f64>; C], NotPositiveDefinite> {
    let n = knots.count;
    let mut a = BandMatrix::zeros(n, 3);
    let mut rhs: [Vec<f64>; C] = std::array::from_fn(|_| vec![0.0; n]);
    let mut total_weight = 0.0;
    for (s, w, values) in points {
        let (k, u) = knots.locate(s);
        let b = basis(u);
        for i in 0..4 {
            for j in 0..=i {
                a.add(k + i, k + j, w * b[i] * b[j]);
            }
            for (c, v) in values.iter().enumerate() {
                rhs[c][k + i] += w * b[i] * v;
            }
        }
        total_weight += w;
    }
    let per_coefficient = (total_weight / n as f64).max(f64::MIN_POSITIVE);
    let lambda = per_coefficient * (smoothing_m / knots.spacing_m).powi(4);
    // D₂ᵀD₂: each row of D₂ is (1, −2, 1) on three neighbouring coefficients.
    const D2: [f64; 3] = [1.0, -2.0, 1.0];
    for r in 0..n.saturating_sub(2) {
        for (i, di) in D2.iter().enumerate() {
            for (j, dj) in D2[..=i].iter().enumerate() {
                a.add(r + i, r + j, lambda * di * dj);
            }
        }
    }
    // A whisper of ridge keeps the system definite where a gap leaves only the penalty.
    let ridge = 1e-9 * per_coefficient;
    for i in 0..n {
        a.add(i, i, ridge);
    }
    let l = a.cholesky()?;
    Ok(std::array::from_fn(|c| l.solve(&rhs[c])))
}

impl PlaneSpline {
    /// The penalised least-squares fit of `samples` on `knots`, smoothing over about
    /// `smoothing_m`.
    pub fn fit(
        knots: Knots,
        samples: &[Sample],
        smoothing_m: f64,
    ) -> Result<Self, NotPositiveDefinite> {
        let points = samples
            .iter()
            .map(|s| (s.chainage_m, s.weight, [s.east_m, s.north_m]));
        let [east, north] = fit_columns(&knots, points, smoothing_m)?;
        Ok(Self { knots, east, north })
    }

    /// East and north at chainage `s` (clamped to the knots' span).
    pub fn at(&self, s: f64) -> (f64, f64) {
        let (k, u) = self.knots.locate(s);
        let b = basis(u);
        let dot = |c: &[f64]| (0..4).map(|i| b[i] * c[k + i]).sum::<f64>();
        (dot(&self.east), dot(&self.north))
    }

    /// The tangent (d east/ds, d north/ds) at `s`.
    pub fn tangent(&self, s: f64) -> (f64, f64) {
        let (k, u) = self.knots.locate(s);
        let b = basis_derivative(u);
        let dot = |c: &[f64]| (0..4).map(|i| b[i] * c[k + i]).sum::<f64>() / self.knots.spacing_m;
        (dot(&self.east), dot(&self.north))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_basis_sums_to_one_and_its_derivative_to_zero() {
        for u in [0.0, 0.25, 0.5, 0.9, 1.0] {
            assert!((basis(u).iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(basis_derivative(u).iter().sum::<f64>().abs() < 1e-12);
        }
    }

    /// Points on a circle of radius `r`, `chainage` its arc length.
    fn arc(r: f64, len: f64, step: f64, noise: impl Fn(usize) -> f64) -> Vec<Sample> {
        (0..=(len / step) as usize)
            .map(|i| {
                let s = i as f64 * step;
                let a = s / r;
                let e = noise(i);
                Sample {
                    chainage_m: s,
                    east_m: (r + e) * a.sin(),
                    north_m: r - (r + e) * a.cos(),
                    weight: 1.0,
                }
            })
            .collect()
    }

    #[test]
    fn a_noisy_arc_is_fitted_to_millimetres_and_not_pulled_to_its_chord() {
        // 2 cm of noise (a deterministic pseudo-random sequence) on a 400 m radius arc.
        let noise = |i: usize| 0.02 * (((i * 7919) % 1000) as f64 / 500.0 - 1.0) * 1.7;
        let samples = arc(400.0, 600.0, 3.0, noise);
        let fit = PlaneSpline::fit(Knots::covering(0.0, 600.0, 5.0), &samples, 10.0).unwrap();
        let mut worst: f64 = 0.0;
        for i in 20..180 {
            let s = i as f64 * 3.0;
            let (e, n) = fit.at(s);
            let radial = e.hypot(n - 400.0) - 400.0;
            worst = worst.max(radial.abs());
        }
        assert!(worst < 0.015, "worst radial error {worst} m");
        // The tangent is a unit vector along the arc.
        let (te, tn) = fit.tangent(300.0);
        assert!((te.hypot(tn) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn a_gap_is_bridged_smoothly() {
        let mut samples = arc(1000.0, 1000.0, 3.0, |_| 0.0);
        samples.retain(|s| !(400.0..600.0).contains(&s.chainage_m));
        let fit = PlaneSpline::fit(Knots::covering(0.0, 1000.0, 5.0), &samples, 10.0).unwrap();
        let (e, n) = fit.at(500.0);
        let radial = e.hypot(n - 1000.0) - 1000.0;
        assert!(radial.abs() < 0.05, "{radial} m off the arc in the gap");
    }
}
