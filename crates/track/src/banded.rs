//! Symmetric positive definite systems whose matrix is banded, solved by a banded Cholesky
//! factorisation `A = L Lᵀ` in O(n·p²) time and O(n·p) memory (p the half-bandwidth): a
//! spline's normal equations over a hundred kilometres of line are tens of thousands of
//! unknowns but only seven diagonals wide. Written here because no well-kept crate offers a
//! banded SPD solve without a LAPACK build.

/// A symmetric matrix of half-bandwidth `p`, its lower band stored row by row:
/// `band[i * (p + 1) + d]` is `A[i][i − d]`.
#[derive(Debug, Clone)]
pub struct BandMatrix {
    n: usize,
    p: usize,
    band: Vec<f64>,
}

/// The factorisation met a pivot that is not positive: the system is singular (too few
/// points for the unknowns) or not positive definite.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("the banded system is not positive definite at row {row}")]
pub struct NotPositiveDefinite {
    pub row: usize,
}

impl BandMatrix {
    pub fn zeros(n: usize, p: usize) -> Self {
        Self {
            n,
            p,
            band: vec![0.0; n * (p + 1)],
        }
    }

    pub fn len(&self) -> usize {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Adds `v` to `A[i][j]` (and so to `A[j][i]`); `|i − j|` must be within the band.
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        debug_assert!(i - j <= self.p, "({i}, {j}) outside the band {}", self.p);
        self.band[i * (self.p + 1) + (i - j)] += v;
    }

    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        if i - j > self.p {
            0.0
        } else {
            self.band[i * (self.p + 1) + (i - j)]
        }
    }

    /// The Cholesky factor `L`, in the same banded storage (its lower triangle).
    pub fn cholesky(mut self) -> Result<BandCholesky, NotPositiveDefinite> {
        let (n, p) = (self.n, self.p);
        let w = p + 1;
        for i in 0..n {
            for j in i.saturating_sub(p)..=i {
                let mut sum = self.band[i * w + (i - j)];
                for k in i.saturating_sub(p).max(j.saturating_sub(p))..j {
                    sum -= self.band[i * w + (i - k)] * self.band[j * w + (j - k)];
                }
                if i == j {
                    // Not positive, or not a number.
                    if sum.is_nan() || sum <= 0.0 {
                        return Err(NotPositiveDefinite { row: i });
                    }
                    self.band[i * w] = sum.sqrt();
                } else {
                    self.band[i * w + (i - j)] = sum / self.band[j * w];
                }
            }
        }
        Ok(BandCholesky { l: self })
    }
}

/// `L` of `A = L Lᵀ`, ready to solve.
#[derive(Debug, Clone)]
pub struct BandCholesky {
    l: BandMatrix,
}

impl BandCholesky {
    /// `x` with `A x = b`.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let BandMatrix { n, p, ref band } = self.l;
        let w = p + 1;
        assert_eq!(b.len(), n);
        let mut y = b.to_vec();
        for i in 0..n {
            let mut sum = y[i];
            for k in i.saturating_sub(p)..i {
                sum -= band[i * w + (i - k)] * y[k];
            }
            y[i] = sum / band[i * w];
        }
        for i in (0..n).rev() {
            let mut sum = y[i];
            for k in i + 1..(i + p + 1).min(n) {
                sum -= band[k * w + (k - i)] * y[k];
            }
            y[i] = sum / band[i * w];
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn the_banded_solve_equals_a_dense_cholesky_solve() {
        let (n, p) = (40, 3);
        let mut a = BandMatrix::zeros(n, p);
        let mut dense = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in i.saturating_sub(p)..=i {
                // Diagonally dominant, so positive definite.
                let v = if i == j {
                    10.0 + (i % 7) as f64
                } else {
                    ((i * 31 + j * 17) % 11) as f64 / 11.0 - 0.5
                };
                a.add(i, j, v);
                dense[(i, j)] += v;
                if i != j {
                    dense[(j, i)] += v;
                }
            }
        }
        assert_eq!(a.get(5, 3), dense[(5, 3)]);
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x = a.cholesky().unwrap().solve(&b);
        let expected = dense.cholesky().unwrap().solve(&DVector::from_vec(b));
        for i in 0..n {
            assert!(
                (x[i] - expected[i]).abs() < 1e-12,
                "{i}: {} {}",
                x[i],
                expected[i]
            );
        }
    }

    #[test]
    fn a_singular_system_is_refused_with_its_row() {
        let mut a = BandMatrix::zeros(3, 1);
        a.add(0, 0, 1.0);
        a.add(1, 0, 1.0);
        a.add(1, 1, 1.0);
        a.add(2, 2, 1.0);
        assert_eq!(a.cholesky().unwrap_err(), NotPositiveDefinite { row: 1 });
    }
}
