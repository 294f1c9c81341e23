use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A wheel/axle odometer (pulse generator) sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Odometer {
    pub stamp_ns: u64,
    pub sensor_id: String,
    /// Cumulative pulse count since the sensor started.
    pub pulse_count: u64,
    /// Pulses per wheel revolution.
    pub pulses_per_revolution: u32,
    /// Wheel diameter the sensor was configured with, m.
    pub wheel_diameter_m: f64,
    /// Distance since the previous sample from the configured diameter, m.
    pub distance_increment_m: f64,
    /// Speed over the last sample interval, m/s.
    pub speed_mps: f64,
}
