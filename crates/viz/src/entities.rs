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

/// A fused pipeline's speed, with `…/plus_3sigma` and `…/minus_3sigma` beside it.
pub fn fused_speed(pipeline: &str) -> String {
    format!("speed/fused/{pipeline}")
}

/// Fused chainage minus truth, with its ±3σ band.
pub fn chainage_error(pipeline: &str) -> String {
    format!("chainage_error/{pipeline}")
}

/// Fused speed minus truth, with its ±3σ band.
pub fn speed_error(pipeline: &str) -> String {
    format!("speed_error/{pipeline}")
}

pub const PLUS_3SIGMA: &str = "plus_3sigma";
pub const MINUS_3SIGMA: &str = "minus_3sigma";
