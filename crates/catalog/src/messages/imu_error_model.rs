use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// What a GNSS/INS pipeline has learnt of its IMU's errors (source 003's `ε = Aδ + Bσ + Cψ`),
/// written at every fused GNSS fix and whenever GNSS is lost or comes back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ImuErrorModel {
    pub stamp_ns: u64,
    /// `δ`: the filter's estimates of the forward accelerometer's and the yaw gyro's bias;
    /// before the filter starts, the offsets measured while the train stood (the forward
    /// one includes the gradient's pull).
    pub accel_bias_mps2: f64,
    pub gyro_bias_radps: f64,
    /// IMU samples taken while the train stood, and the time they span (s): the static
    /// offsets' footing.
    pub standstill_samples: u64,
    pub standstill_s: f64,
    /// `ψ`: the mean rate at which GNSS corrected the speed and the heading beyond the
    /// biases over the learning period, applied to the inertial solution while GNSS is lost;
    /// `σ`: the spread of those rates.
    pub speed_residual_mps2: f64,
    pub speed_residual_std_mps2: f64,
    pub heading_residual_radps: f64,
    pub heading_residual_std_radps: f64,
    /// Seconds of good GNSS learnt from.
    pub learnt_s: f64,
    /// True while GNSS is lost and the learnt model corrects the inertial solution.
    pub applied: bool,
}

protobuf_form!(ImuErrorModel {
    stamp_ns,
    accel_bias_mps2,
    gyro_bias_radps,
    standstill_samples,
    standstill_s,
    speed_residual_mps2,
    speed_residual_std_mps2,
    heading_residual_radps,
    heading_residual_std_radps,
    learnt_s,
    applied,
});
