//! The fixed-interval Rauch–Tung–Striebel smoother, run backwards over a Kalman pipeline's
//! whole forward pass (offline data allows it):
//!
//! ```text
//! C_k   = P_k Fᵀ_{k+1} (P⁻_{k+1})⁻¹
//! x^s_k = x_k + C_k (x^s_{k+1} − x⁻_{k+1})
//! P^s_k = P_k + C_k (P^s_{k+1} − P⁻_{k+1}) C_kᵀ
//! ```
//!
//! where `x⁻_{k+1}, P⁻_{k+1}` is the prediction into epoch `k+1` and `x_k, P_k` the filtered
//! estimate at epoch `k`. An epoch is one filter time: every measurement stamp (accepted or
//! gated) and every output tick.
//!
//! Memory does not grow with the log: the forward pass is spilled to a temporary file of
//! fixed-size records, read back in blocks from the end, and the smoothed epochs are written to
//! a second file at their own offsets so they can be read forward again.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};

use nalgebra::{SMatrix, SVector};

use super::{symmetric, StateAndCovariance};

/// Spills the forward pass of a filter, one record per epoch.
pub struct EpochRecorder<const N: usize> {
    file: BufWriter<File>,
    records: u64,
    open: Option<(u64, StateAndCovariance<N>, SMatrix<f64, N, N>)>,
    error: Option<std::io::Error>,
}

/// One smoothed epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct SmoothedEpoch<const N: usize> {
    pub stamp_ns: u64,
    pub estimate: StateAndCovariance<N>,
}

const fn record_len(n: usize) -> usize {
    // stamp, prior x and P, F, posterior x and P
    1 + 2 * n + 3 * n * n
}

const fn smoothed_len(n: usize) -> usize {
    1 + n + n * n
}

impl<const N: usize> EpochRecorder<N> {
    pub fn new() -> std::io::Result<Self> {
        Ok(Self {
            file: BufWriter::with_capacity(1 << 16, tempfile::tempfile()?),
            records: 0,
            open: None,
            error: None,
        })
    }

    /// Starts the epoch at `stamp_ns` with the prediction into it (`transition` None for the
    /// first epoch).
    pub fn begin_epoch(
        &mut self,
        stamp_ns: u64,
        prior: StateAndCovariance<N>,
        transition: Option<SMatrix<f64, N, N>>,
    ) {
        self.open = Some((
            stamp_ns,
            prior,
            transition.unwrap_or_else(SMatrix::identity),
        ));
    }

    /// Adds `variance` to component `k` of the open epoch's prediction (process noise the
    /// estimator added inside the step: gate-lockout recovery).
    pub fn widen_prediction(&mut self, k: usize, variance: f64) {
        if let Some((_, prior, _)) = &mut self.open {
            prior.covariance[(k, k)] += variance;
        }
    }

    /// Closes the open epoch with its filtered estimate.
    pub fn end_epoch(&mut self, posterior: StateAndCovariance<N>) {
        let Some((stamp, prior, f)) = self.open.take() else {
            return;
        };
        let mut buf = Vec::with_capacity(record_len(N) * 8);
        buf.extend_from_slice(&stamp.to_le_bytes());
        for x in prior
            .state
            .iter()
            .chain(prior.covariance.iter())
            .chain(f.iter())
            .chain(posterior.state.iter())
            .chain(posterior.covariance.iter())
        {
            buf.extend_from_slice(&x.to_le_bytes());
        }
        if self.error.is_none() {
            if let Err(e) = self.file.write_all(&buf) {
                self.error = Some(e);
            }
        }
        self.records += 1;
    }

    pub fn epochs(&self) -> u64 {
        self.records
    }

    /// Runs the backward pass; the smoothed epochs come back in forward time order.
    pub fn smooth(mut self) -> std::io::Result<SmoothedEpochs<N>> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        let mut input = self.file.into_inner().map_err(|e| e.into_error())?;
        let mut output = tempfile::tempfile()?;
        let n = self.records;
        const BLOCK: u64 = 4096;
        let (rl, sl) = (record_len(N) * 8, smoothed_len(N) * 8);
        // (x^s, P^s) of epoch k+1 and its prior and transition.
        let mut next: Option<(
            StateAndCovariance<N>,
            StateAndCovariance<N>,
            SMatrix<f64, N, N>,
        )> = None;
        let mut hi = n;
        let mut bytes = Vec::new();
        let mut out = Vec::new();
        while hi > 0 {
            let lo = hi.saturating_sub(BLOCK);
            bytes.resize((hi - lo) as usize * rl, 0);
            input.seek(SeekFrom::Start(lo * rl as u64))?;
            input.read_exact(&mut bytes)?;
            out.clear();
            out.resize((hi - lo) as usize * sl, 0);
            for k in (0..(hi - lo) as usize).rev() {
                let rec = Record::<N>::parse(&bytes[k * rl..(k + 1) * rl]);
                let smoothed = match &next {
                    None => rec.posterior.clone(),
                    Some((xs_next, prior_next, f_next)) => {
                        rts_step(&rec.posterior, prior_next, f_next, xs_next)
                    }
                };
                let o = &mut out[k * sl..(k + 1) * sl];
                o[..8].copy_from_slice(&rec.stamp_ns.to_le_bytes());
                for (i, x) in smoothed
                    .state
                    .iter()
                    .chain(smoothed.covariance.iter())
                    .enumerate()
                {
                    o[8 + i * 8..16 + i * 8].copy_from_slice(&x.to_le_bytes());
                }
                next = Some((smoothed, rec.prior, rec.transition));
            }
            output.seek(SeekFrom::Start(lo * sl as u64))?;
            output.write_all(&out)?;
            hi = lo;
        }
        output.seek(SeekFrom::Start(0))?;
        Ok(SmoothedEpochs {
            reader: BufReader::with_capacity(1 << 16, output),
            remaining: n,
        })
    }
}

/// The smoother gain `J = P_k|k Fᵀ_{k+1} (P_{k+1|k})⁻¹`; None when the prediction's
/// covariance is singular.
pub fn smoother_gain<const N: usize>(
    filtered_covariance: &SMatrix<f64, N, N>,
    transition_next: &SMatrix<f64, N, N>,
    predicted_covariance_next: &SMatrix<f64, N, N>,
) -> Option<SMatrix<f64, N, N>> {
    let p = predicted_covariance_next;
    let inv = p
        .cholesky()
        .map(|c| c.inverse())
        .or_else(|| p.try_inverse())?;
    Some(filtered_covariance * transition_next.transpose() * inv)
}

/// One RTS step: epoch k's smoothed estimate from its filtered one and epoch k+1's.
pub fn rts_step<const N: usize>(
    filtered: &StateAndCovariance<N>,
    prior_next: &StateAndCovariance<N>,
    transition_next: &SMatrix<f64, N, N>,
    smoothed_next: &StateAndCovariance<N>,
) -> StateAndCovariance<N> {
    let p_pred = prior_next.covariance;
    let Some(c) = smoother_gain(&filtered.covariance, transition_next, &p_pred) else {
        return filtered.clone();
    };
    StateAndCovariance {
        state: filtered.state + c * (smoothed_next.state - prior_next.state),
        covariance: symmetric(
            filtered.covariance + c * (smoothed_next.covariance - p_pred) * c.transpose(),
        ),
    }
}

struct Record<const N: usize> {
    stamp_ns: u64,
    prior: StateAndCovariance<N>,
    transition: SMatrix<f64, N, N>,
    posterior: StateAndCovariance<N>,
}

impl<const N: usize> Record<N> {
    fn parse(b: &[u8]) -> Self {
        let stamp_ns = u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
        let mut vals = b[8..]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")));
        let prior = read_gaussian(&mut vals);
        let transition = SMatrix::from_iterator(vals.by_ref().take(N * N));
        let posterior = read_gaussian(&mut vals);
        Self {
            stamp_ns,
            prior,
            transition,
            posterior,
        }
    }
}

fn read_gaussian<const N: usize>(vals: &mut impl Iterator<Item = f64>) -> StateAndCovariance<N> {
    let state = SVector::from_iterator(vals.by_ref().take(N));
    let covariance = SMatrix::from_iterator(vals.by_ref().take(N * N));
    StateAndCovariance { state, covariance }
}

/// The smoothed epochs in forward order, read from the spill file.
pub struct SmoothedEpochs<const N: usize> {
    reader: BufReader<File>,
    remaining: u64,
}

impl<const N: usize> Iterator for SmoothedEpochs<N> {
    type Item = std::io::Result<SmoothedEpoch<N>>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.remaining == 0 {
            return None;
        }
        self.remaining -= 1;
        let mut b = vec![0u8; smoothed_len(N) * 8];
        Some(self.reader.read_exact(&mut b).map(|()| {
            let stamp_ns = u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
            let mut vals = b[8..]
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")));
            SmoothedEpoch {
                stamp_ns,
                estimate: read_gaussian(&mut vals),
            }
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::KalmanFilter;
    use crate::model::{ConstantAcceleration, ProcessNoise, TransitionModel};
    use nalgebra::{Matrix3, RowVector3, Vector3};

    /// The spilled, blocked backward pass equals a plain in-memory RTS over the same epochs.
    #[test]
    fn spilled_smoother_equals_the_in_memory_recursion_across_blocks() {
        let model = ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(0.1),
        };
        let mut kf = KalmanFilter::new(Vector3::new(0.0, 10.0, 0.0), Matrix3::identity());
        let mut rec = EpochRecorder::<3>::new().unwrap();
        let mut mem: Vec<(StateAndCovariance<3>, StateAndCovariance<3>, Matrix3<f64>)> = Vec::new();
        let mut prior = kf.estimate.clone();
        let mut f = Matrix3::identity();
        rec.begin_epoch(0, prior.clone(), None);
        for k in 0..9000u64 {
            let z = 10.0 * k as f64 * 0.1 + ((k * 7919) % 13) as f64 * 0.05;
            kf.update(&RowVector3::new(1.0, 0.0, 0.0), 0.25, z);
            rec.end_epoch(kf.estimate.clone());
            mem.push((prior, kf.estimate.clone(), f));
            let dt = 0.1 + (k % 3) as f64 * 0.01;
            kf.predict(&model, dt);
            prior = kf.estimate.clone();
            f = model.transition(dt);
            rec.begin_epoch((k + 1) * 100, prior.clone(), Some(f));
        }
        rec.end_epoch(kf.estimate.clone());
        mem.push((prior, kf.estimate.clone(), f));
        let smoothed: Vec<_> = rec.smooth().unwrap().map(Result::unwrap).collect();
        assert_eq!(smoothed.len(), mem.len());
        let mut s_next = mem.last().unwrap().1.clone();
        for k in (0..mem.len() - 1).rev() {
            s_next = rts_step(&mem[k].1, &mem[k + 1].0, &mem[k + 1].2, &s_next);
            assert_eq!(smoothed[k].estimate, s_next, "epoch {k}");
        }
        // Smoothing can only shrink the variance.
        assert!(smoothed[100].estimate.covariance[(0, 0)] < mem[100].1.covariance[(0, 0)]);
    }
}
