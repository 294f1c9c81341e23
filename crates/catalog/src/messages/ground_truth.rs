use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// The true state of the train (simulation only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct GroundTruth {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
    pub acceleration_mps2: f64,
    pub east_m: f64,
    pub north_m: f64,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    /// Track heading, clockwise from north.
    pub heading_rad: f64,
}

protobuf_form!(GroundTruth {
    stamp_ns,
    chainage_m,
    speed_mps,
    acceleration_mps2,
    east_m,
    north_m,
    latitude_deg,
    longitude_deg,
    heading_rad,
});
