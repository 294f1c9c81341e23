//! The centralised estimator: one local filter that every sensor updates directly.
//!
//! Gate lockout: an innovation gate protects the filter from bad measurements only while the
//! filter is right. When the train does what the motion model does not expect (a hard stop
//! takes the deceleration to zero within a sample), every measurement of that quantity fails
//! the gate and the estimate runs away unchecked. After `lockout_after` rejections in a row of
//! one quantity, the next is used with that component's variance first widened by `ν² − S`,
//! so that it fits with NIS = 1: the evidence of many sensor samples outweighs the model.

use super::rts::EpochRecorder;
use super::{
    fix_reset, Estimator, EstimatorDiagnostics, Innovation, LocalFilter, Outcome,
    ScalarMeasurement, StateAndCovariance,
};
use crate::model::TransitionModel;

pub struct Centralised<const N: usize, F: LocalFilter<N>> {
    filter: F,
    model: Box<dyn TransitionModel<N>>,
    time_ns: u64,
    /// The forward pass, kept for the RTS smoother when the pipeline asks for one.
    recorder: Option<EpochRecorder<N>>,
    /// Gate rejections in a row after which the filter takes itself to be locked out (0: never).
    lockout_after: u32,
    /// Gate rejections in a row, per state component.
    rejections: [u32; N],
}

impl<const N: usize, F: LocalFilter<N>> Centralised<N, F> {
    pub fn new(
        filter: F,
        model: Box<dyn TransitionModel<N>>,
        time_ns: u64,
        recorder: Option<EpochRecorder<N>>,
    ) -> Self {
        let mut c = Self {
            filter,
            model,
            time_ns,
            recorder,
            lockout_after: 0,
            rejections: [0; N],
        };
        if let Some(r) = &mut c.recorder {
            r.begin_epoch(time_ns, c.filter.estimate(), None);
        }
        c
    }

    /// Recover from gate lockout after `n` rejections in a row of one quantity (0: never).
    pub fn with_gate_lockout(mut self, n: u32) -> Self {
        self.lockout_after = n;
        self
    }
}

impl<const N: usize, F: LocalFilter<N>> Estimator<N> for Centralised<N, F> {
    fn advance_to(&mut self, t_ns: u64) {
        if t_ns <= self.time_ns {
            return;
        }
        let dt = (t_ns - self.time_ns) as f64 / 1e9;
        if let Some(r) = &mut self.recorder {
            r.end_epoch(self.filter.estimate());
        }
        self.filter.predict(self.model.as_ref(), dt, 1.0);
        self.time_ns = t_ns;
        if let Some(r) = &mut self.recorder {
            r.begin_epoch(
                t_ns,
                self.filter.estimate(),
                Some(self.model.transition(dt)),
            );
        }
    }

    fn process(&mut self, m: &ScalarMeasurement<N>) -> Outcome {
        let z = m.z - m.offset;
        let innovation = self.filter.innovation(&m.h, m.r, z);
        let k = m.quantity;
        if !innovation.passes(m.gate_nis) {
            if self.lockout_after == 0
                || !innovation.nis.is_finite()
                || self.rejections[k] + 1 < self.lockout_after
            {
                self.rejections[k] += 1;
                return Outcome::RejectedGate(innovation);
            }
            let extra = (innovation.residual * innovation.residual - innovation.variance)
                / (m.h[k] * m.h[k]);
            let mut widened = self.filter.estimate();
            widened.covariance[(k, k)] += extra;
            self.filter.reset(&widened);
            if let Some(r) = &mut self.recorder {
                // Widening is extra process noise of this step: the smoother must see it in
                // the prediction.
                r.widen_prediction(k, extra);
            }
            self.rejections[k] = 0;
            return if self.filter.update(&m.h, m.r, z) {
                Outcome::AcceptedAfterLockout(innovation)
            } else {
                Outcome::RejectedNumerics(innovation)
            };
        }
        self.rejections[k] = 0;
        if self.filter.update(&m.h, m.r, z) {
            Outcome::Accepted(innovation)
        } else {
            Outcome::RejectedNumerics(innovation)
        }
    }

    fn estimate(&self) -> StateAndCovariance<N> {
        self.filter.estimate()
    }

    fn innovation(&self, m: &ScalarMeasurement<N>) -> Innovation {
        self.filter.innovation(&m.h, m.r, m.z - m.offset)
    }

    fn reset_to_fix(&mut self, m: &ScalarMeasurement<N>) -> Outcome {
        let before = self.filter.estimate();
        let innovation = Estimator::innovation(self, m);
        let Some(after) = fix_reset(&before, m) else {
            return Outcome::RejectedNumerics(innovation);
        };
        self.filter.reset(&after);
        let k = m.quantity;
        if let Some(r) = &mut self.recorder {
            // A reset is a jump the model did not predict: the smoother must not carry the
            // estimate before it across (a prior that knows nothing of k on the jump's scale).
            let scale = innovation.residual * innovation.residual + before.covariance[(k, k)] + m.r;
            r.widen_prediction(k, 1e6 * scale);
        }
        self.rejections[k] = 0;
        Outcome::Reset(innovation)
    }

    fn take_smoother(&mut self) -> Option<EpochRecorder<N>> {
        if let Some(r) = &mut self.recorder {
            r.end_epoch(self.filter.estimate());
        }
        self.recorder.take()
    }

    fn diagnostics(&self) -> EstimatorDiagnostics {
        let mut d = EstimatorDiagnostics::default();
        self.filter.diagnostics(&mut d);
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::KalmanFilter;
    use crate::model::{ConstantAcceleration, ProcessNoise};
    use nalgebra::{Matrix3, RowVector3, Vector3};

    /// A train braking at 0.9 m/s² stops dead at t = 2 s; an accelerometer (100 Hz) and a
    /// speed sensor (10 Hz) see it. Returns the worst speed error after the stop and the
    /// accelerometer's outcomes.
    fn hard_stop(lockout_after: u32) -> (f64, Vec<Outcome>) {
        let model = Box::new(ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(0.02),
        });
        let init = KalmanFilter::new(
            Vector3::new(0.0, 1.8, -0.9),
            Matrix3::from_diagonal(&Vector3::new(1.0, 1e-4, 1e-4)),
        );
        let mut c = Centralised::new(init, model, 0, None).with_gate_lockout(lockout_after);
        let (mut worst, mut outcomes) = (0.0f64, Vec::new());
        for k in 1..=600u64 {
            let t = k as f64 * 0.01;
            let (v, a) = if t < 2.0 {
                (1.8 - 0.9 * t, -0.9)
            } else {
                (0.0, 0.0)
            };
            c.advance_to(k * 10_000_000);
            outcomes.push(c.process(&ScalarMeasurement {
                device: 0,
                quantity: 2,
                h: RowVector3::new(0.0, 0.0, 1.0),
                offset: 0.0,
                r: 0.0009,
                z: a,
                gate_nis: Some(25.0),
            }));
            if k % 10 == 0 {
                // The speed sensor's outcomes are not kept: the lockout run below is the accelerometer's.
                c.process(&ScalarMeasurement {
                    device: 0,
                    quantity: 1,
                    h: RowVector3::new(0.0, 1.0, 0.0),
                    offset: 0.0,
                    r: 0.01,
                    z: v,
                    gate_nis: Some(16.0),
                });
            }
            if t >= 2.0 {
                worst = worst.max((c.estimate().state[1] - v).abs());
            }
            assert!(c.estimate().is_finite());
        }
        (worst, outcomes)
    }

    #[test]
    fn a_hard_stop_locks_the_gate_and_lockout_recovery_reopens_it() {
        let (locked, outcomes) = hard_stop(0);
        let gated = outcomes
            .iter()
            .filter(|o| matches!(o, Outcome::RejectedGate(_)))
            .count();
        assert!(
            locked > 0.3 && gated > 20,
            "without recovery the filter runs away: {locked} m/s, {gated} gated"
        );
        let (recovered, outcomes) = hard_stop(5);
        let lockouts = outcomes
            .iter()
            .filter(|o| matches!(o, Outcome::AcceptedAfterLockout(_)))
            .count();
        assert!(
            lockouts >= 1 && recovered < 0.1,
            "with recovery: {recovered} m/s after {lockouts} lockouts"
        );
        // The run that set it off: exactly `lockout_after` - 1 gate rejections before it.
        let first = outcomes
            .iter()
            .position(|o| matches!(o, Outcome::AcceptedAfterLockout(_)))
            .unwrap();
        assert!(outcomes[first - 4..first]
            .iter()
            .all(|o| matches!(o, Outcome::RejectedGate(_))));
    }
}
