//! The `[can]`/`[[can]]` and `[sensor."<topic>"]` tables of a configuration as written, and
//! what is wrong with a mapping.

use std::collections::BTreeMap;
use std::path::PathBuf;

use railfuse_can::dbc::DbcError;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::messages::FixType;

/// `[can]` of a configuration: the vehicle's DBC, and which bus to read.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CanSettings {
    /// The vehicle's DBC file, relative to the configuration.
    pub dbc: PathBuf,
    /// Read frames of this bus only (`can0`); every bus when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bus: Option<String>,
}

/// `[can]` (one DBC) or `[[can]]` (a DBC a bus: a vehicle bus and an OBD-2 bus side by side).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum CanBuses {
    One(CanSettings),
    Each(Vec<CanSettings>),
}

impl CanBuses {
    pub fn buses(&self) -> &[CanSettings] {
        match self {
            CanBuses::One(one) => std::slice::from_ref(one),
            CanBuses::Each(each) => each,
        }
    }
}

/// `[sensor."<topic>"]`: a railfuse sensor made from decoded CAN signals.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SensorSource {
    /// The speed signal, `"can:Message.Signal"`: in m/s, km/h or mph by its DBC unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from: Option<String>,
    /// Or, for an odometer, its axle pulse generator's count (an unsigned integer signal,
    /// wrapping at its bits): distance from the wheel below, speed over `speed_window_s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulses: Option<String>,
    /// With `pulses`: pulses a wheel revolution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulses_per_revolution: Option<u32>,
    /// With `pulses`: the wheel's diameter, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_diameter_m: Option<f64>,
    /// With `pulses`: the speed is the distance over the last this long, s (0.2 unless told).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_window_s: Option<f64>,
    /// A signal of the same message that is 0 when the sensor has no measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valid: Option<String>,
    /// A signal of the same message giving the measurement's quality: 0–1, or 0–100 in `%`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<String>,
    /// A GNSS fix (`/gnss/fix`): its latitude, in degrees (or radians by its DBC unit); the
    /// fix is made when this signal's message arrives.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latitude: Option<String>,
    /// A GNSS fix: its longitude, of the latitude's message.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub longitude: Option<String>,
    /// A GNSS fix: its height above mean sea level, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub altitude: Option<String>,
    /// A GNSS fix: the receiver's horizontal accuracy estimate, m, taken as the east and north
    /// σ (the vertical as twice it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<String>,
    /// A GNSS fix: its fix type, a number `fix_types` names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fix_type: Option<String>,
    /// A GNSS fix: what each `fix_type` value is (`none`, `single`, `dgps`, `rtk_float`,
    /// `rtk_fixed`); u-blox's NAV-PVT fix types without it (0 none, 1 dead reckoning: none, 2
    /// and 3 2-D/3-D: single, 4 GNSS with dead reckoning: single, 5 time only: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fix_types: Option<BTreeMap<String, FixType>>,
    /// A GNSS fix: satellites used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub satellites: Option<String>,
    /// A GNSS fix: speed over ground (m/s, km/h or mph by its unit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<String>,
    /// A GNSS fix: course over ground (or heading), clockwise from north, ° or rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub course: Option<String>,
    /// An IMU (`/imu`): specific force on its x, y, z axes (m/s², or g, mg by unit); the
    /// sample is made when the first one's message arrives.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceleration: Option<[String; 3]>,
    /// An IMU: angular rate about x, y, z (°/s or rad/s by unit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_rate: Option<[String; 3]>,
    /// A GNSS fix or IMU: the oldest a signal of another message may be to be used, s (1.5
    /// for a fix, 0.1 for an IMU).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_age_s: Option<f64>,
}

/// What is wrong with a CAN mapping (the caller names the configuration file).
#[derive(Debug, thiserror::Error)]
pub enum MappingError {
    #[error(transparent)]
    Dbc(#[from] DbcError),
    #[error("[sensor.\"{topic}\"] {key} = \"{given}\": {cause}")]
    Signal {
        topic: String,
        key: &'static str,
        given: String,
        cause: String,
    },
    #[error("[sensor.\"{topic}\"]: {cause}")]
    Sensor { topic: String, cause: String },
}
