//! Rerun entity paths, in one place so the layout is visible at a glance.
//!
//! - `map/…`: the plan view (east right, north up): the track and its furniture (static), GNSS
//!   fixes by fix type, the true path and train, each pipeline's position and 3σ extent.
//! - `speed/…`, `chainage_error/…`, `speed_error/…`: time series shared by every pipeline.
//! - `diagnostics/<pipeline>/…`: one pipeline's NIS, gate decisions, β, effective sample size
//!   and sensor states.
//! - `sensors/…`: raw sensors on their own (position sensors' errors, the IMU).
//! - `events`: a text log.
//! - `tune/<pipeline>/…`: a tuning run's convergence trace (objective, best, each value).

use railfuse_catalog::messages::{FixType, GateDecision};

pub const TRACK: &str = "map/track";
pub const KM_MARKS: &str = "map/km_marks";
pub const BALISES: &str = "map/balises";
pub const STATIONS: &str = "map/stations";
pub const TUNNELS: &str = "map/tunnels";
pub const LEGEND: &str = "map/legend";
/// The true path so far (a trail of points).
pub const TRUTH_PATH: &str = "map/truth/path";
/// Where the train truly is at the time cursor.
pub const TRUTH_TRAIN: &str = "map/truth/train";
pub const EVENTS: &str = "events";

pub const SPEED_TRUTH: &str = "speed/truth";
pub const SPEED_RADAR: &str = "speed/radar";
pub const SPEED_GNSS: &str = "speed/gnss";
pub const LOOP_CHAINAGE_ERROR: &str = "sensors/chainage_error/loop";
pub const BALISE_CHAINAGE_ERROR: &str = "sensors/chainage_error/balise";
/// Satellites in use and HDOP of every fix.
pub const GNSS_QUALITY: &str = "sensors/gnss/quality";
/// Satellites of fixes without an HDOP.
pub const GNSS_SATELLITES: &str = "sensors/gnss/quality/satellites";
pub const IMU_SPECIFIC_FORCE: &str = "sensors/imu/specific_force";
pub const IMU_ANGULAR_RATE: &str = "sensors/imu/angular_rate";

/// A tuning run's objective and best-so-far, by evaluation time.
pub fn tune_objective(pipeline: &str) -> String {
    format!("tune/{pipeline}/objective")
}

/// One tuned value of a tuning run (`k`: its place in the run's parameter list).
pub fn tune_value(pipeline: &str, k: usize) -> String {
    format!("tune/{pipeline}/values/{k}")
}

/// GNSS fixes of one fix type on the map: one entity per type, so each has its colour and name.
pub fn gnss_fixes(fix: FixType) -> String {
    format!("map/gnss/{}", fix.name())
}

/// `speed/<odometer topic tail>`, e.g. `speed/odometer_1`.
pub fn speed_of(topic: &str) -> String {
    format!("speed/{}", topic_tail(topic))
}

/// A topic as one entity path part: `/odometer/1` → `odometer_1`.
pub fn topic_tail(topic: &str) -> String {
    topic.trim_start_matches('/').replace('/', "_")
}

/// The fused position of a pipeline on the map.
pub fn fused_position(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/position")
}

/// A pipeline's along-track ±3σ extent on the map.
pub fn fused_extent(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/extent")
}

/// The train along the track after a pipeline's state, rear end to front end.
pub fn fused_train(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/train")
}

/// A pipeline's safe front end interval (min to max safe front end) on the map.
pub fn fused_safe_front(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/train/safe_front")
}

/// The train's sensors where they sit, after a pipeline's state.
pub fn fused_train_sensors(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/train/sensors")
}

/// A 2-D pipeline's 3σ covariance ellipse on the map.
pub fn fused_ellipse(pipeline: &str) -> String {
    format!("map/fused/{pipeline}/ellipse")
}

/// A fused pipeline's speed.
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

/// Everything one pipeline says about itself.
pub fn diagnostics(pipeline: &str) -> String {
    format!("diagnostics/{pipeline}")
}

/// NIS of one measurement topic in one pipeline.
pub fn nis(pipeline: &str, topic: &str) -> String {
    format!("diagnostics/{pipeline}/nis/{}", topic_tail(topic))
}

/// The χ² bounds drawn over a pipeline's NIS.
pub fn nis_bounds(pipeline: &str) -> String {
    format!("diagnostics/{pipeline}/nis/chi2_bounds")
}

/// Markers of one gate decision (all but plain acceptance) in a pipeline's NIS plot.
pub fn gate_decisions(pipeline: &str, decision: GateDecision) -> String {
    format!(
        "diagnostics/{pipeline}/nis/{}",
        gate_decision_name(decision)
    )
}

pub fn gate_decision_name(decision: GateDecision) -> &'static str {
    match decision {
        GateDecision::Accepted => "accepted",
        GateDecision::AcceptedAfterLockout => "accepted_after_lockout",
        GateDecision::RejectedGate => "rejected_gate",
        GateDecision::RejectedInvalid => "rejected_invalid",
        GateDecision::RejectedLate => "rejected_late",
        GateDecision::BeforeInitialisation => "before_initialisation",
        GateDecision::RejectedDeviceFault => "rejected_device_fault",
        GateDecision::ResetToFix => "reset_to_fix",
    }
}

/// A federated pipeline's information-sharing coefficients β, one series per device.
pub fn sharing(pipeline: &str) -> String {
    format!("diagnostics/{pipeline}/sharing")
}

/// A pipeline with safety checks: whether each epoch was usable (1) or not (0).
pub fn safety(pipeline: &str) -> String {
    format!("diagnostics/{pipeline}/safety")
}

/// A pipeline's safe interval U_safe relative to the reference, drawn in the chainage-error
/// plot beside the ±3σ band (the reference is 0 there: the eye sees whether 0 stays inside).
pub fn safe_interval(pipeline: &str) -> String {
    format!("{}/u_safe", chainage_error(pipeline))
}

/// A particle pipeline's effective sample size.
pub fn effective_sample_size(pipeline: &str) -> String {
    format!("diagnostics/{pipeline}/effective_sample_size")
}

/// A 2-D pipeline's east or north velocity minus the truth, with its ±3σ bounds.
pub fn velocity_error(pipeline: &str, axis: &str) -> String {
    format!("diagnostics/{pipeline}/velocity_error/{axis}")
}

/// One term of a GNSS/INS pipeline's learnt IMU error model (`speed_residual`,
/// `heading_residual`), with its spread.
pub fn imu_error_model(pipeline: &str, term: &str) -> String {
    format!("diagnostics/{pipeline}/imu_error_model/{term}")
}

/// An eddy-current pipeline's windows: `correlation` (ρ with and without warping),
/// `acceleration` (the warp's and the filter's), `sleepers` (sensor a's count minus b's).
pub fn eddy_current(pipeline: &str, what: &str) -> String {
    format!("diagnostics/{pipeline}/eddy_current/{what}")
}

/// One sensor state a pipeline estimates (a radar's scale factor, a receiver's bias), with
/// its ±3σ bounds.
pub fn sensor_state(pipeline: &str, topic: &str, kind: &str) -> String {
    format!(
        "diagnostics/{pipeline}/sensor_states/{}/{kind}",
        topic_tail(topic)
    )
}
