//! Estimators. The state and its covariance always travel together ([`StateAndCovariance`]).
//!
//! Two layers:
//! - a [`LocalFilter`] is one Bayesian filter on one motion model: the Kalman filter
//!   ([`kalman`]) or the particle filter ([`particle`]);
//! - an [`Estimator`] is what a pipeline runs: one local filter fed by every sensor
//!   ([`Centralised`]), or one local filter per device with a master filter
//!   ([`federated`]). Estimators own their time and advance themselves to each measurement.
//!
//! [`rts`] smooths a Kalman pipeline's output backwards over the whole run.

mod centralised;
pub mod covariance_matching;
pub mod em;
pub mod federated;
pub mod kalman;
pub mod particle;
pub mod rts;
pub mod sharing;
pub mod working_state;

pub use centralised::Centralised;
pub use kalman::KalmanFilter;
pub use particle::ParticleFilter;

use nalgebra::{RowSVector, SMatrix, SVector};

use crate::model::TransitionModel;

/// One device's part in a federated fusion: its information-sharing coefficient β and, while
/// it is out of the fusion, why.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceShare {
    pub device: String,
    /// Information-sharing coefficient β (0 while failed).
    pub beta: f64,
    /// Why the device is out of the fusion (timeout, stuck, gate_failures, reported), if it is.
    pub fault: Option<String>,
}

/// A Gaussian estimate: the state and its covariance, kept together.
#[derive(Debug, Clone, PartialEq)]
pub struct StateAndCovariance<const N: usize> {
    pub state: SVector<f64, N>,
    pub covariance: SMatrix<f64, N, N>,
}

impl<const N: usize> StateAndCovariance<N> {
    pub fn is_finite(&self) -> bool {
        self.state
            .iter()
            .chain(self.covariance.iter())
            .all(|x| x.is_finite())
    }
}

/// A scalar innovation and its statistics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation {
    /// ν = z − H x⁻
    pub residual: f64,
    /// S = H P⁻ Hᵀ + R
    pub variance: f64,
    /// Normalised innovation squared ν² / S (χ² with one degree of freedom when consistent).
    pub nis: f64,
}

impl Innovation {
    pub fn new(residual: f64, variance: f64) -> Self {
        Self {
            residual,
            variance,
            nis: residual * residual / variance,
        }
    }

    /// True when the innovation passes the NIS gate (a NaN NIS never passes).
    pub fn passes(&self, gate_nis: Option<f64>) -> bool {
        match gate_nis {
            None => !self.nis.is_nan(),
            Some(g) => self.nis <= g,
        }
    }
}

/// One scalar measurement `z = H x + offset + v`, `v ~ N(0, r)`, of one device.
///
/// A non-linear sensor model `z = h(x) + v` (a speed sensor's unknown scale factor:
/// `z = (1 + k) v`) comes linearised at the current estimate `x̂`: `H = ∂h/∂x (x̂)` and
/// `offset = h(x̂) − H x̂`, so that the innovation `z − offset − H x̂ = z − h(x̂)` (an extended
/// Kalman filter step). Linear sensors have `offset = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarMeasurement<const N: usize> {
    /// Index of the device (sub-filter) it belongs to; [`MASTER`] for the master filter.
    pub device: usize,
    /// The state component it measures (0 chainage, 1 speed, 2 acceleration): gate-lockout and
    /// stuck-output bookkeeping.
    pub quantity: usize,
    pub h: RowSVector<f64, N>,
    pub offset: f64,
    pub r: f64,
    pub z: f64,
    pub gate_nis: Option<f64>,
}

/// The device index of measurements that update the master filter of a federated estimator
/// (a balise: an absolute fix that every sub-filter should learn from at once).
pub const MASTER: usize = usize::MAX;

/// What an estimator did with a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    Accepted(Innovation),
    /// Used after a run of gate rejections of its quantity, with that component's variance
    /// widened first; the innovation is the one before widening.
    AcceptedAfterLockout(Innovation),
    RejectedGate(Innovation),
    /// The update would have made the estimate non-finite: not used.
    RejectedNumerics(Innovation),
    /// An absolute fix taken as the truth of its component after the gate had rejected the
    /// sensor too often in a row ([`Estimator::reset_to_fix`]); the innovation is the one
    /// before the reset.
    Reset(Innovation),
    /// Its device is failed (out of the fusion); the innovation is against the fused estimate.
    RejectedDeviceFault(Option<Innovation>),
}

impl Outcome {
    pub fn innovation(&self) -> Option<Innovation> {
        match *self {
            Outcome::Accepted(i)
            | Outcome::AcceptedAfterLockout(i)
            | Outcome::RejectedGate(i)
            | Outcome::RejectedNumerics(i)
            | Outcome::Reset(i) => Some(i),
            Outcome::RejectedDeviceFault(i) => i,
        }
    }
}

/// Estimator-specific diagnostics attached to each processed measurement.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EstimatorDiagnostics {
    /// Effective sample size after the update (particle filters).
    pub effective_sample_size: Option<f64>,
    /// Whether the update triggered resampling (particle filters).
    pub resampled: Option<bool>,
    /// β and health per device (federated filters).
    pub sharing: Option<Vec<DeviceShare>>,
}

/// One Bayesian filter on one motion model.
pub trait LocalFilter<const N: usize> {
    /// Time update over `dt` seconds, with the process noise scaled by `q_scale` (federated
    /// information sharing divides `Q` by β).
    fn predict(&mut self, model: &dyn TransitionModel<N>, dt: f64, q_scale: f64);
    /// The innovation `z` would produce, without using it.
    fn innovation(&self, h: &RowSVector<f64, N>, r: f64, z: f64) -> Innovation;
    /// Measurement update; false (and the filter unchanged) when the result is not finite.
    fn update(&mut self, h: &RowSVector<f64, N>, r: f64, z: f64) -> bool;
    /// The filter's Gaussian estimate (mean and covariance of the particles for a particle
    /// filter).
    fn estimate(&self) -> StateAndCovariance<N>;
    /// Replace the estimate (federated feedback).
    fn reset(&mut self, to: &StateAndCovariance<N>);
    fn diagnostics(&self, _out: &mut EstimatorDiagnostics) {}
}

/// What a pipeline runs: consumes measurements in time order and gives the fused estimate.
pub trait Estimator<const N: usize> {
    /// Advances to `t_ns` (never backwards).
    fn advance_to(&mut self, t_ns: u64);
    /// Gates and uses one measurement taken at the current time.
    fn process(&mut self, m: &ScalarMeasurement<N>) -> Outcome;
    fn estimate(&self) -> StateAndCovariance<N>;
    /// Takes an absolute fix as the truth of the component it measures, as PX4's ekf2 resets
    /// its position once the innovation checks have failed for too long: the filter, not the
    /// fix, is wrong (a drifting loop it trusted, a slip it did not model), and a gate that
    /// keeps rejecting the fix would keep it wrong for ever. See [`fix_reset`]. Returns
    /// [`Outcome::Reset`], or [`Outcome::RejectedNumerics`] when the fix cannot be taken.
    fn reset_to_fix(&mut self, m: &ScalarMeasurement<N>) -> Outcome;
    /// The innovation `m` would produce against the estimate it would update, without using
    /// it (what its gate would judge).
    fn innovation(&self, m: &ScalarMeasurement<N>) -> Innovation;
    /// The state a non-linear measurement of `device` is linearised at: the estimate that
    /// measurement will update (a federated filter's device sub-filter; else the estimate).
    fn linearisation_point(&self, _device: usize) -> SVector<f64, N> {
        self.estimate().state
    }
    fn diagnostics(&self) -> EstimatorDiagnostics;
    /// A message of `device` arrived at `t_ns`, usable or not: the device is alive (a radar
    /// flags its samples invalid at standstill but keeps talking).
    fn heard_from(&mut self, _device: usize, _t_ns: u64) {}
    /// A fault or recovery a device reported itself (an event in the log).
    fn device_event(&mut self, _device: &str, _failed: bool) {}
    /// The recorded forward pass, for the RTS smoother (Kalman pipelines that asked for it).
    fn take_smoother(&mut self) -> Option<rts::EpochRecorder<N>> {
        None
    }
}

/// The estimate `e` reset to the fix `m` (measuring component `k = m.quantity`):
///
/// ```text
/// x_k ← x_k + (z − offset − H x) / H_k        (H x̂ now equals the fix)
/// P_kj = P_jk ← 0 for j ≠ k,   P_kk ← r / H_k²  (the fix's variance, uncorrelated)
/// ```
///
/// The other components keep their estimates and covariances (speed and a sensor's bias
/// are not what the fix measures). `None` when the row does not measure `k` or the result is
/// not finite.
pub fn fix_reset<const N: usize>(
    e: &StateAndCovariance<N>,
    m: &ScalarMeasurement<N>,
) -> Option<StateAndCovariance<N>> {
    let k = m.quantity;
    let hk = *m.h.get(k)?;
    if hk == 0.0 || !(m.r > 0.0) {
        return None;
    }
    let mut out = e.clone();
    out.state[k] += (m.z - m.offset - (m.h * e.state)[0]) / hk;
    for j in 0..N {
        out.covariance[(k, j)] = 0.0;
        out.covariance[(j, k)] = 0.0;
    }
    out.covariance[(k, k)] = m.r / (hk * hk);
    (out.state.iter().all(|x| x.is_finite())).then_some(out)
}

/// Symmetrises a covariance after arithmetic that may have broken its symmetry by rounding.
pub fn symmetric<const N: usize>(p: SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    (p + p.transpose()) * 0.5
}

/// A square root `L` of a positive semi-definite `Q` (`L Lᵀ = Q`): Cholesky that passes over
/// zero pivots, so that rank-deficient noise (a jerk held over the step is rank one) is
/// handled exactly instead of failing.
pub fn sqrt_psd<const N: usize>(q: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    let mut l = SMatrix::<f64, N, N>::zeros();
    let scale = q.diagonal().amax().max(f64::MIN_POSITIVE);
    for j in 0..N {
        let d = q[(j, j)] - (0..j).map(|k| l[(j, k)] * l[(j, k)]).sum::<f64>();
        if d <= 1e-13 * scale {
            continue;
        }
        let djj = d.sqrt();
        l[(j, j)] = djj;
        for i in j + 1..N {
            l[(i, j)] = (q[(i, j)] - (0..j).map(|k| l[(i, k)] * l[(j, k)]).sum::<f64>()) / djj;
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix4, RowVector4, Vector4};

    /// A fix `z = s + b` (a loop with a chainage bias state) taken as the truth of s: the
    /// row now predicts the fix exactly, s carries the fix's variance and no correlation, and
    /// speed, acceleration and the bias keep theirs.
    #[test]
    fn a_fix_reset_moves_its_component_onto_the_fix_and_leaves_the_others() {
        let a = Matrix4::new(
            2.0, 0.3, 0.1, 0.2, //
            0.0, 0.5, 0.1, 0.0, //
            0.0, 0.0, 0.2, 0.05, //
            0.0, 0.0, 0.0, 0.4,
        );
        let e = StateAndCovariance {
            state: Vector4::new(1000.0, 20.0, 0.5, 1.5),
            covariance: a * a.transpose(),
        };
        let m = ScalarMeasurement {
            device: 0,
            quantity: 0,
            h: RowVector4::new(1.0, 0.0, 0.0, 1.0),
            offset: 0.0,
            r: 0.04,
            z: 1010.0,
            gate_nis: Some(9.0),
        };
        let out = fix_reset(&e, &m).unwrap();
        assert!(((m.h * out.state)[0] - m.z).abs() < 1e-9);
        assert_eq!(out.state.fixed_rows::<3>(1), e.state.fixed_rows::<3>(1));
        assert_eq!(out.covariance[(0, 0)], 0.04);
        for j in 1..4 {
            assert_eq!((out.covariance[(0, j)], out.covariance[(j, 0)]), (0.0, 0.0));
            for i in 1..4 {
                assert_eq!(out.covariance[(i, j)], e.covariance[(i, j)]);
            }
        }
        assert!(out.covariance.symmetric_eigenvalues().min() > 0.0);
        // A row that does not measure the component, or a fix without a variance, is no fix.
        let blind = ScalarMeasurement {
            h: RowVector4::new(0.0, 1.0, 0.0, 0.0),
            ..m
        };
        assert!(fix_reset(&e, &blind).is_none());
        assert!(fix_reset(&e, &ScalarMeasurement { r: 0.0, ..m }).is_none());
    }
}
