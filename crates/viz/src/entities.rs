//! Rerun entity paths, in one place so the layout is visible at a glance.

pub const TRACK: &str = "map/track";
pub const BALISES: &str = "map/balises";
pub const STATIONS: &str = "map/stations";
pub const TRUTH_POSITION: &str = "map/truth";
pub const GNSS_POSITION: &str = "map/gnss";
pub const EVENTS: &str = "events";

pub const SPEED_TRUTH: &str = "speed/truth";
pub const SPEED_RADAR: &str = "speed/radar";
pub const SPEED_GNSS: &str = "speed/gnss";
pub const LOOP_CHAINAGE_ERROR: &str = "chainage_error/loop";
pub const BALISE_CHAINAGE_ERROR: &str = "chainage_error/balise";

/// `speed/<odometer topic tail>`, e.g. `speed/odometer_1`.
pub fn speed_of(topic: &str) -> String {
    format!("speed/{}", topic.trim_start_matches('/').replace('/', "_"))
}

/// The fused position of a pipeline on the map.
pub fn fused_position(pipeline: &str) -> String {
    format!("map/fused/{pipeline}")
}

/// A fused pipeline's speed: three series, the value and its +3σ and −3σ bounds.
pub fn fused_speed(pipeline: &str) -> String {
    format!("speed/fused/{pipeline}")
}

/// Fused chainage minus truth, with its ±3σ bounds as two more series.
pub fn chainage_error(pipeline: &str) -> String {
    format!("chainage_error/{pipeline}")
}

/// Fused speed minus truth, with its ±3σ bounds as two more series.
pub fn speed_error(pipeline: &str) -> String {
    format!("speed_error/{pipeline}")
}

/// One sensor state a pipeline estimates (a radar's scale factor, a receiver's bias), with
/// its ±3σ bounds: `sensor_states/<pipeline>/<topic tail>/<kind>`.
pub fn sensor_state(pipeline: &str, topic: &str, kind: &str) -> String {
    format!(
        "sensor_states/{pipeline}/{}/{kind}",
        topic.trim_start_matches('/').replace('/', "_")
    )
}

/// A federated pipeline's information-sharing coefficients β, one series per device.
pub fn sharing(pipeline: &str) -> String {
    format!("sharing/{pipeline}")
}
