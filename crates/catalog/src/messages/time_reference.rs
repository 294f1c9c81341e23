use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// A time reference (ROS's `sensor_msgs/TimeReference`): the recorder's own clock read at an
/// instant whose GNSS time is known, typically a receiver's pulse per second (PPS) edge with
/// the ZDA or RMC sentence that names it. Each recorder that logs these carries its clock
/// against GNSS time: `local_ns − stamp_ns` over a run gives its offset and drift.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TimeReference {
    /// The instant in GNSS time (UTC), ns since the Unix epoch.
    pub stamp_ns: u64,
    /// The recorder's clock at that instant, ns (ROS's `header.stamp`).
    pub local_ns: u64,
    /// What gave the time: `pps`, `nmea`, `ptp`, …
    pub source: String,
}

protobuf_form!(TimeReference {
    stamp_ns,
    local_ns,
    source
});
