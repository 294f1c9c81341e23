//! One configured pipeline: measurements are released to its filter in sensor-time order
//! (within a bounded reorder window), gated, and turned into fused state and diagnostics.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use nalgebra::{Matrix3, Vector3};
use railfuse_catalog::messages::{FusedDiagnostics, FusedState, GateDecision};
use serde::Serialize;

use crate::config::{PipelineConfig, Variance};
use crate::filter::KalmanFilter;
use crate::measurement::{Measurement, Quantity};
use crate::model::ConstantAcceleration;

/// What a pipeline did with its measurements.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct PipelineCounts {
    pub accepted: u64,
    pub rejected_gate: u64,
    pub rejected_invalid: u64,
    pub rejected_late: u64,
    pub before_initialisation: u64,
}

/// Output of one processed measurement.
#[derive(Debug, Clone)]
pub struct Fused {
    /// Replay time at which the filter released it: the log time of the message that pushed
    /// the replay past the reorder window (non-decreasing, so fused channels stay in
    /// log-time order).
    pub log_time_ns: u64,
    /// The new state, when the measurement was used.
    pub state: Option<FusedState>,
    pub diagnostics: FusedDiagnostics,
}

struct Pending {
    sensor: usize,
    measurement: Measurement,
}

pub struct KalmanPipeline {
    pub config: PipelineConfig,
    model: ConstantAcceleration,
    filter: Option<KalmanFilter<3>>,
    filter_time_ns: u64,
    window_ns: u64,
    /// Min-heap on (sensor stamp, arrival order) of measurements not yet released.
    order: BinaryHeap<Reverse<(u64, u64)>>,
    pending: std::collections::HashMap<u64, Pending>,
    seq: u64,
    /// The latest valid speed measurement before the first position: the initial speed.
    speed_before_init: Option<(f64, f64)>,
    pub counts: PipelineCounts,
}

impl KalmanPipeline {
    pub fn new(config: PipelineConfig) -> Self {
        Self {
            model: config.motion_model(),
            window_ns: (config.reorder_window_s * 1e9) as u64,
            config,
            filter: None,
            filter_time_ns: 0,
            order: BinaryHeap::new(),
            pending: Default::default(),
            seq: 0,
            speed_before_init: None,
            counts: PipelineCounts::default(),
        }
    }

    pub fn name(&self) -> &str {
        &self.config.name
    }

    /// Index of the configured sensor reading `topic`.
    pub fn sensor_for(&self, topic: &str) -> Option<usize> {
        self.config.sensor.iter().position(|s| s.topic == topic)
    }

    /// Queues a measurement received at `log_time_ns` and releases every measurement the
    /// replay is now more than the reorder window past.
    pub fn push(&mut self, sensor: usize, measurement: Measurement, log_time_ns: u64, out: &mut Vec<Fused>) {
        self.seq += 1;
        self.order.push(Reverse((measurement.stamp_ns, self.seq)));
        self.pending.insert(self.seq, Pending { sensor, measurement });
        self.release(log_time_ns.saturating_sub(self.window_ns), log_time_ns, out);
    }

    /// Releases everything still queued (end of the log, at replay time `log_time_ns`).
    pub fn finish(&mut self, log_time_ns: u64, out: &mut Vec<Fused>) {
        self.release(u64::MAX, log_time_ns, out);
    }

    fn release(&mut self, up_to_ns: u64, log_time_ns: u64, out: &mut Vec<Fused>) {
        while let Some(&Reverse((stamp, seq))) = self.order.peek() {
            if stamp > up_to_ns {
                break;
            }
            self.order.pop();
            let p = self.pending.remove(&seq).expect("every queued key has its measurement");
            out.push(self.process(p, log_time_ns));
        }
    }

    fn process(&mut self, p: Pending, log_time_ns: u64) -> Fused {
        let sensor = &self.config.sensor[p.sensor];
        let m = p.measurement;
        let variance = match sensor.variance {
            Variance::Fixed(v) => Some(v),
            Variance::FromMessage(_) => m.reported_variance,
        };
        let mut diagnostics = FusedDiagnostics {
            stamp_ns: m.stamp_ns,
            source: sensor.topic.clone(),
            measurement: m.value,
            measurement_variance: variance.unwrap_or(0.0),
            innovation: None,
            innovation_variance: None,
            nis: None,
            decision: GateDecision::Accepted,
        };
        let usable_variance = variance.filter(|r| r.is_finite() && *r > 0.0);
        let decision = match (usable_variance, &self.filter) {
            (None, _) => GateDecision::RejectedInvalid,
            _ if !m.valid || !m.value.is_finite() => GateDecision::RejectedInvalid,
            (Some(r), None) if m.quantity == Quantity::Chainage => {
                let init = &self.config.initial;
                let (speed, speed_var) = self.speed_before_init.unwrap_or((init.speed_mps, init.speed_std_mps.powi(2)));
                self.filter = Some(KalmanFilter::new(
                    Vector3::new(m.value, speed, 0.0),
                    Matrix3::from_diagonal(&Vector3::new(r, speed_var, init.acceleration_std_mps2.powi(2))),
                ));
                self.filter_time_ns = m.stamp_ns;
                GateDecision::Accepted
            }
            (Some(r), None) => {
                self.speed_before_init = Some((m.value, r));
                GateDecision::BeforeInitialisation
            }
            (Some(_), Some(_)) if m.stamp_ns < self.filter_time_ns => GateDecision::RejectedLate,
            (Some(r), Some(filter)) => {
                // Predict on a copy: a rejected measurement leaves the filter untouched.
                let mut predicted = filter.clone();
                let dt = (m.stamp_ns - self.filter_time_ns) as f64 / 1e9;
                if dt > 0.0 {
                    predicted.predict(&self.model, dt);
                }
                let h = m.quantity.h();
                let innovation = predicted.innovation(&h, r, m.value);
                diagnostics.innovation = Some(innovation.residual);
                diagnostics.innovation_variance = Some(innovation.variance);
                diagnostics.nis = Some(innovation.nis);
                // A NaN NIS fails the gate too.
                if sensor.gate_nis.is_some_and(|g| innovation.nis.is_nan() || innovation.nis > g) {
                    GateDecision::RejectedGate
                } else {
                    predicted.update(&h, r, m.value);
                    if predicted.estimate.state.iter().all(|x| x.is_finite()) {
                        self.filter = Some(predicted);
                        self.filter_time_ns = m.stamp_ns;
                        GateDecision::Accepted
                    } else {
                        GateDecision::RejectedInvalid
                    }
                }
            }
        };
        diagnostics.decision = decision;
        let counter = match decision {
            GateDecision::Accepted => &mut self.counts.accepted,
            GateDecision::RejectedGate => &mut self.counts.rejected_gate,
            GateDecision::RejectedInvalid => &mut self.counts.rejected_invalid,
            GateDecision::RejectedLate => &mut self.counts.rejected_late,
            GateDecision::BeforeInitialisation => &mut self.counts.before_initialisation,
        };
        *counter += 1;
        let state = (decision == GateDecision::Accepted).then(|| {
            let e = &self.filter.as_ref().expect("accepted means initialised").estimate;
            let mut covariance = [0.0; 9];
            for (i, c) in covariance.iter_mut().enumerate() {
                *c = e.covariance[(i / 3, i % 3)];
            }
            FusedState {
                stamp_ns: m.stamp_ns,
                chainage_m: e.state[0],
                speed_mps: e.state[1],
                acceleration_mps2: e.state[2],
                covariance,
                source: sensor.topic.clone(),
            }
        });
        Fused { log_time_ns, state, diagnostics }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PipelinesConfig;

    fn pipeline(gate: &str) -> KalmanPipeline {
        let text = format!(
            "[[pipeline]]\nname = \"p\"\nfilter = \"kalman\"\nmotion = {{ model = \"constant_acceleration\", jerk_psd = 0.1 }}\nreorder_window_s = 0.2\n\
             [[pipeline.sensor]]\ntopic = \"/pos\"\nvariance = 0.01\n{gate}\n[[pipeline.sensor]]\ntopic = \"/spd\"\nvariance = \"message\"\n"
        );
        let c = PipelinesConfig::parse(&text, std::path::Path::new("t.toml")).unwrap();
        KalmanPipeline::new(c.pipeline[0].clone())
    }

    fn m(stamp_ns: u64, quantity: Quantity, value: f64, var: Option<f64>) -> Measurement {
        Measurement { stamp_ns, quantity, value, reported_variance: var, valid: true }
    }

    #[test]
    fn measurements_are_fused_in_sensor_time_order_within_the_window() {
        let mut p = pipeline("");
        let mut out = Vec::new();
        let s = 1_000_000_000u64;
        p.push(0, m(s, Quantity::Chainage, 0.0, None), s, &mut out);
        // A speed measured at 1.10 s arrives after a position measured at 1.15 s.
        p.push(0, m(s + 150_000_000, Quantity::Chainage, 1.5, None), s + 160_000_000, &mut out);
        p.push(1, m(s + 100_000_000, Quantity::Speed, 10.0, Some(0.01)), s + 170_000_000, &mut out);
        p.finish(s + 200_000_000, &mut out);
        let stamps: Vec<u64> = out.iter().map(|f| f.diagnostics.stamp_ns).collect();
        assert_eq!(stamps, vec![s, s + 100_000_000, s + 150_000_000]);
        assert!(out.iter().all(|f| f.diagnostics.decision == GateDecision::Accepted));
        assert_eq!(p.counts.rejected_late, 0);
    }

    #[test]
    fn nan_and_missing_variances_are_rejected_and_never_reach_the_state() {
        let mut p = pipeline("gate_nis = 9.0");
        let mut out = Vec::new();
        p.push(0, m(0, Quantity::Chainage, 0.0, None), 0, &mut out);
        p.push(0, m(10, Quantity::Chainage, f64::NAN, None), 10, &mut out);
        p.push(0, m(20, Quantity::Chainage, f64::INFINITY, None), 20, &mut out);
        p.push(1, m(30, Quantity::Speed, 3.0, None), 30, &mut out); // "message" variance, none given
        p.push(1, m(40, Quantity::Speed, 0.0, Some(f64::NAN)), 40, &mut out);
        p.push(0, m(50, Quantity::Chainage, 1e6, None), 50, &mut out); // far outside the gate
        p.finish(60, &mut out);
        assert_eq!(p.counts.accepted, 1);
        assert_eq!(p.counts.rejected_invalid, 4);
        assert_eq!(p.counts.rejected_gate, 1);
        for f in &out {
            if let Some(s) = &f.state {
                assert!(s.chainage_m.is_finite() && s.covariance.iter().all(|c| c.is_finite()));
            }
        }
    }
}
