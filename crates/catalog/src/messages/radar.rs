use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// Doppler radar speed over the track.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RadarSpeed {
    pub stamp_ns: u64,
    /// Speed along the track (the radar cannot tell direction: non-negative).
    pub speed_mps: f64,
    /// Signal quality, 0 (no echo) to 1.
    pub quality: f64,
    /// False when the radar reports no usable measurement (standstill, lost echo).
    pub valid: bool,
    /// The sensor's own variance estimate of `speed_mps`, (m/s)².
    #[serde(default)]
    pub speed_variance_m2ps2: Option<f64>,
}

protobuf_form!(RadarSpeed {
    stamp_ns,
    speed_mps,
    quality,
    valid,
    speed_variance_m2ps2
});
