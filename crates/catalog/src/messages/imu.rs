use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// One inertial sample in the sensor's body frame (x forward, y left, z up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Imu {
    pub stamp_ns: u64,
    pub sensor_id: String,
    /// Specific force (acceleration minus gravity, as an accelerometer measures it), m/s².
    pub specific_force_mps2: [f64; 3],
    /// Angular rate, rad/s.
    pub angular_rate_radps: [f64; 3],
}

protobuf_form!(Imu {
    stamp_ns,
    sensor_id,
    specific_force_mps2,
    angular_rate_radps
});
