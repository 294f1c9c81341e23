//! What a pipeline gives back, whatever its kind: fused records (state, diagnostics, safety
//! status, IMU error model) and the counts of what it did with its measurements. Below every
//! pipeline and the replay, which all write them.

use railfuse_catalog::messages::{FusedDiagnostics, FusedState, GateDecision, SafetyStatus};
use serde::Serialize;

use crate::filter::Innovation;

/// What a pipeline did with its measurements.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct PipelineCounts {
    pub accepted: u64,
    /// Used after a gate lockout (the filter's variance widened first).
    pub accepted_after_lockout: u64,
    pub rejected_gate: u64,
    pub rejected_invalid: u64,
    pub rejected_late: u64,
    pub rejected_device_fault: u64,
    pub before_initialisation: u64,
    /// Absolute fixes the estimate was reset to, after the gate had rejected their sensor
    /// `reset_after` times in a row.
    pub resets_to_fix: u64,
}

/// The diagnostics record of one measurement of a pipeline that reads whole messages
/// (`ekf_safety`, `gnss_ins`): its value and variance, its innovation, what was decided and
/// why, and the axis of the plane it is on.
pub fn measurement_record(
    stamp_ns: u64,
    topic: &str,
    axis: Option<&str>,
    (z, r): (Option<f64>, Option<f64>),
    i: Option<Innovation>,
    decision: GateDecision,
    reason: Option<&str>,
) -> FusedDiagnostics {
    FusedDiagnostics {
        stamp_ns,
        source: topic.to_owned(),
        measurement: z.filter(|z| z.is_finite()),
        measurement_variance: r.filter(|r| r.is_finite()),
        innovation: i.map(|i| i.residual).filter(|x| x.is_finite()),
        innovation_variance: i.map(|i| i.variance).filter(|x| x.is_finite()),
        nis: i.map(|i| i.nis).filter(|x| x.is_finite()),
        decision,
        device: None,
        axis: axis.map(str::to_owned),
        reason: reason.map(str::to_owned),
        effective_sample_size: None,
        resampled: None,
        sharing: None,
        eddy_current: None,
    }
}

/// Output of one processed measurement or output tick.
#[derive(Debug, Clone, Default)]
pub struct Fused {
    /// Replay time at which the filter released it: the log time of the message that pushed
    /// the replay past the reorder window (non-decreasing, so fused channels stay in
    /// log-time order).
    pub log_time_ns: u64,
    pub state: Option<FusedState>,
    pub diagnostics: Option<FusedDiagnostics>,
    /// Pipelines with safety checks: the epoch's checks and safe interval.
    pub safety: Option<SafetyStatus>,
    /// GNSS/INS pipelines: what they learnt of the IMU's errors.
    pub imu_error_model: Option<railfuse_catalog::messages::ImuErrorModel>,
}
