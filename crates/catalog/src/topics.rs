//! Topic names of the standard channels. Fused channels live under `/fused/<pipeline>/…` so
//! that several pipelines sit side by side in one file.

use crate::messages::MessageKind;

pub const GNSS_FIX: &str = "/gnss/fix";
pub const IMU: &str = "/imu";
pub const RADAR_SPEED: &str = "/radar/speed";
pub const ODOMETER_1: &str = "/odometer/1";
pub const ODOMETER_2: &str = "/odometer/2";
pub const LOOP_POSITION: &str = "/loop/position";
pub const BALISE: &str = "/balise";
pub const EDDY_CURRENT: &str = "/eddy_current/block";
pub const TRACK_MAP: &str = "/track/map";
/// The train's length and where each sensor sits on it (the installation drawing).
pub const VEHICLE: &str = "/vehicle";
pub const GROUND_TRUTH: &str = "/truth";
pub const EVENTS: &str = "/events";
pub const RECORDER_DIAGNOSTICS: &str = "/recorder/diagnostics";
/// A recorder's clock against GNSS time (its PPS); `/time_reference/<recorder>` where a run
/// has several recorders, one topic each.
pub const TIME_REFERENCE: &str = "/time_reference";

/// The message kind a standard topic carries.
pub fn standard_kind(topic: &str) -> Option<MessageKind> {
    Some(match topic {
        GNSS_FIX => MessageKind::GnssFix,
        IMU => MessageKind::Imu,
        RADAR_SPEED => MessageKind::RadarSpeed,
        ODOMETER_1 | ODOMETER_2 => MessageKind::Odometer,
        LOOP_POSITION => MessageKind::LoopPosition,
        BALISE => MessageKind::BalisePassage,
        EDDY_CURRENT => MessageKind::EddyCurrentBlock,
        TRACK_MAP => MessageKind::TrackMap,
        VEHICLE => MessageKind::Vehicle,
        GROUND_TRUTH => MessageKind::GroundTruth,
        EVENTS => MessageKind::Event,
        RECORDER_DIAGNOSTICS => MessageKind::RecorderDiagnostics,
        TIME_REFERENCE => MessageKind::TimeReference,
        _ => return None,
    })
}

/// `/time_reference/<recorder>`: one recorder's time reference in a run of several.
pub fn time_reference(recorder: &str) -> String {
    format!("{TIME_REFERENCE}/{recorder}")
}

/// `/tune/<pipeline>/trace`: the convergence trace of a tuning run of one pipeline.
pub fn tune_trace(pipeline: &str) -> String {
    format!("/tune/{pipeline}/trace")
}

/// The pipeline of a `/tune/<pipeline>/trace` topic.
pub fn tune_trace_pipeline(topic: &str) -> Option<&str> {
    topic.strip_prefix("/tune/")?.strip_suffix("/trace")
}

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

/// `/fused/<pipeline>/safety`: the safety checks and safe interval of each epoch of a
/// pipeline with safety checks.
pub fn fused_safety(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/safety")
}

/// `/fused/<pipeline>/train`: the whole train's position after the pipeline's states: front
/// end with its safe interval, rear end, speed.
pub fn fused_train(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/train")
}

/// `/fused/<pipeline>/imu_error_model`: what a GNSS/INS pipeline learnt of its IMU's errors.
pub fn fused_imu_error_model(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/imu_error_model")
}

/// `/fused/<pipeline>/navsatfix`: for a ROS 2 input, the fused position as
/// `sensor_msgs/msg/NavSatFix` (CDR), for ROS tools.
pub fn fused_nav_sat_fix(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/navsatfix")
}

/// `/fused/<pipeline>/odometry`: for a ROS 2 input, the fused state as `nav_msgs/msg/Odometry`
/// (CDR).
pub fn fused_odometry(pipeline: &str) -> String {
    format!("{FUSED_PREFIX}{pipeline}/odometry")
}

/// The channels each pipeline writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusedChannel {
    State,
    Diagnostics,
    Smoothed,
    Safety,
    ImuErrorModel,
    Train,
}

/// The pipeline and channel of a fused topic (`/fused/<pipeline>/<channel>`), if it is one.
pub fn parse_fused(topic: &str) -> Option<(&str, FusedChannel)> {
    let (pipeline, channel) = topic.strip_prefix(FUSED_PREFIX)?.split_once('/')?;
    let channel = match channel {
        "state" => FusedChannel::State,
        "diagnostics" => FusedChannel::Diagnostics,
        "smoothed" => FusedChannel::Smoothed,
        "safety" => FusedChannel::Safety,
        "imu_error_model" => FusedChannel::ImuErrorModel,
        "train" => FusedChannel::Train,
        _ => return None,
    };
    (!pipeline.is_empty()).then_some((pipeline, channel))
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
    /// One record per pipeline a sensor was withheld from: the topic and the outages (log
    /// time), written before the fused channels so that a reader scores as it goes.
    pub const WITHHELD: &str = "railfuse.withheld";
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fused_topics_are_built_and_parsed_by_one_module() {
        for (topic, channel) in [
            (fused_state("kf"), FusedChannel::State),
            (fused_diagnostics("kf"), FusedChannel::Diagnostics),
            (fused_smoothed("kf"), FusedChannel::Smoothed),
            (fused_safety("kf"), FusedChannel::Safety),
            (fused_imu_error_model("kf"), FusedChannel::ImuErrorModel),
            (fused_train("kf"), FusedChannel::Train),
        ] {
            assert_eq!(parse_fused(&topic), Some(("kf", channel)));
            assert_eq!(fused_pipeline_of(&topic), Some("kf"));
        }
        assert_eq!(parse_fused("/fused/kf/other"), None);
        assert_eq!(parse_fused("/fused//state"), None);
        assert_eq!(parse_fused(RADAR_SPEED), None);
        assert_eq!(standard_kind(RADAR_SPEED), Some(MessageKind::RadarSpeed));
    }
}
