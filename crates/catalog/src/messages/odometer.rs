use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// A wheel/axle odometer (pulse generator) sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Odometer {
    pub stamp_ns: u64,
    pub sensor_id: String,
    /// Cumulative pulse count since the sensor started (absent from an odometer that reports
    /// only its speed, as a ROS `Twist` does).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulse_count: Option<u64>,
    /// Pulses per wheel revolution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulses_per_revolution: Option<u32>,
    /// Wheel diameter the sensor was configured with, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_diameter_m: Option<f64>,
    /// Distance since the previous sample from the configured diameter, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_increment_m: Option<f64>,
    /// Speed over the last sample interval, m/s.
    pub speed_mps: f64,
}

protobuf_form!(Odometer {
    stamp_ns,
    sensor_id,
    pulse_count,
    pulses_per_revolution,
    wheel_diameter_m,
    distance_increment_m,
    speed_mps,
});
