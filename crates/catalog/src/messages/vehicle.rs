use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// The train as its installation drawing gives it: its length and where each sensor sits and
/// how it is turned, in the body frame. Written once at the start of a log, as the track map
/// is; [`crate::vehicle`] has the geometry.
///
/// The body frame has its origin at the train's front end on the centre line at the top of
/// rail (the reference ETCS reports), x forward, y to the left, z up. The train follows the
/// track: a sensor `x` metres behind the front end sits on the track `x` metres back along
/// it, `y` and `z` from the centre line in the body of its car there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Vehicle {
    pub stamp_ns: u64,
    pub name: String,
    /// From the front end to the rear end, m.
    pub length_m: f64,
    /// How far the body leans out of a curve per m/s² of unbalanced lateral acceleration, rad
    /// (its suspension's flexibility, about 0.015 for 1 m/s² on a coach); 0: not given.
    #[serde(default)]
    pub roll_per_lateral_mps2: f64,
    /// Each sensor's place, by the topic its messages travel on.
    pub sensors: Vec<SensorMount>,
    /// The drawing's installation tolerance, 1σ of each lever arm component, m: how far a
    /// sensor may sit from where the drawing puts it (0: exactly there).
    #[serde(default)]
    pub installation_std_m: f64,
}

/// Where one sensor sits on the train and how it is turned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SensorMount {
    /// The channel of its messages.
    pub topic: String,
    /// Its frame in the recording's transforms (a ROS `frame_id`), where it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_id: Option<String>,
    /// Lever arm in the body frame, m: x along the train from the front end (negative behind
    /// it), y to the left of the centre line, z up from the top of rail.
    pub lever_arm_m: [f64; 3],
    /// Mounting: roll, pitch and yaw of the sensor's axes in the body frame, degrees (ROS's
    /// convention: about the fixed x, then y, then z axes; a sensor's x forward, y left, z up
    /// is all zeros).
    #[serde(default)]
    pub mounting_deg: [f64; 3],
}

protobuf_form!(Vehicle {
    stamp_ns,
    name,
    length_m,
    roll_per_lateral_mps2,
    sensors,
    installation_std_m,
});
protobuf_form!(SensorMount {
    topic,
    frame_id,
    lever_arm_m,
    mounting_deg
});
