use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A block of raw samples from the two eddy-current sensors, which sit `spacing_m` apart
/// along the track. `stamp_ns` is the time of the first sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EddyCurrentBlock {
    pub stamp_ns: u64,
    pub sample_rate_hz: f64,
    /// Distance D between the two sensors along the track, m.
    pub spacing_m: f64,
    /// The leading sensor's samples (volts).
    pub sensor_a: Vec<f32>,
    /// The trailing sensor's samples (volts), same length as `sensor_a`.
    pub sensor_b: Vec<f32>,
}
