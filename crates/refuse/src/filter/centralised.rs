//! The centralised estimator: one local filter that every sensor updates directly.

use super::rts::EpochRecorder;
use super::{Estimator, EstimatorDiagnostics, LocalFilter, Outcome, ScalarMeasurement, StateAndCovariance};
use crate::model::TransitionModel;

pub struct Centralised<const N: usize, F: LocalFilter<N>> {
    filter: F,
    model: Box<dyn TransitionModel<N>>,
    time_ns: u64,
    /// The forward pass, kept for the RTS smoother when the pipeline asks for one.
    recorder: Option<EpochRecorder<N>>,
}

impl<const N: usize, F: LocalFilter<N>> Centralised<N, F> {
    pub fn new(filter: F, model: Box<dyn TransitionModel<N>>, time_ns: u64, recorder: Option<EpochRecorder<N>>) -> Self {
        let mut c = Self { filter, model, time_ns, recorder };
        if let Some(r) = &mut c.recorder {
            r.begin_epoch(time_ns, c.filter.estimate(), None);
        }
        c
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
            r.begin_epoch(t_ns, self.filter.estimate(), Some(self.model.transition(dt)));
        }
    }

    fn process(&mut self, m: &ScalarMeasurement<N>) -> Outcome {
        let innovation = self.filter.innovation(&m.h, m.r, m.z);
        if !innovation.passes(m.gate_nis) {
            Outcome::RejectedGate(innovation)
        } else if self.filter.update(&m.h, m.r, m.z) {
            Outcome::Accepted(innovation)
        } else {
            Outcome::RejectedNumerics(innovation)
        }
    }

    fn estimate(&self) -> StateAndCovariance<N> {
        self.filter.estimate()
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
