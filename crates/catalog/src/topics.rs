//! Topic names of the standard channels. Fused channels live under `/fused/<pipeline>/…` so
//! that several pipelines sit side by side in one file.

pub const GNSS_FIX: &str = "/gnss/fix";
pub const IMU: &str = "/imu";
pub const RADAR_SPEED: &str = "/radar/speed";
pub const ODOMETER_1: &str = "/odometer/1";
pub const ODOMETER_2: &str = "/odometer/2";
pub const LOOP_POSITION: &str = "/loop/position";
pub const BALISE: &str = "/balise";
pub const EDDY_CURRENT: &str = "/eddy_current/block";
pub const TRACK_MAP: &str = "/track/map";
pub const GROUND_TRUTH: &str = "/truth";
pub const EVENTS: &str = "/events";
pub const RECORDER_DIAGNOSTICS: &str = "/recorder/diagnostics";

/// Prefix of every fused channel.
pub const FUSED_PREFIX: &str = "/fused/";

/// `/fused/<pipeline>/state`: the fused along-track state of one pipeline.
pub fn fused_state(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/state")
}

/// `/fused/<pipeline>/diagnostics`: innovations, NIS and gate decisions of one pipeline.
pub fn fused_diagnostics(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/diagnostics")
}

/// `/fused/<pipeline>/smoothed`: the RTS-smoothed states of a Kalman pipeline.
pub fn fused_smoothed(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/smoothed")
}

/// The pipeline name of a fused topic, if it is one.
pub fn fused_pipeline_of(topic: &str) -> Option<&str> {
    topic
        .strip_prefix(FUSED_PREFIX)?
        .split('/')
        .next()
        .filter(|s| !s.is_empty())
}

/// Metadata record names railfuse writes.
pub mod metadata {
    /// Run description: run id, train, route, scenario parameters, tool version.
    pub const RUN: &str = "railfuse.run";
    /// One record per pipeline: the exact configuration that made its fused channels.
    pub const PIPELINE: &str = "railfuse.pipeline";
}
