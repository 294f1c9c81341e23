//! The pipeline configuration file (TOML) as written: its tables and keys, each with its
//! place in the file. One file declares any number of named pipelines; one replay runs them
//! all. This module only reads the file: [`crate::spec`] turns it into validated pipelines,
//! and its errors name the line of the table they are about.
//!
//! ```toml
//! [[pipeline]]
//! name = "kalman"
//! filter = "kalman"
//! motion = { model = "constant_acceleration", jerk_psd = 0.05 }
//!
//! [[pipeline.sensor]]
//! topic = "/loop/position"
//! variance = "message"      # the variance each message reports, or a number in SI units²
//! gate_nis = 25.0           # optional innovation gate
//! ```

use crate::checks::positive;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use toml::Spanned;

use crate::error::{Error, Result};
use crate::filter::federated::{Feedback, Fusion};
use crate::filter::particle::ParticleSettings;
use crate::filter::sharing::{Redistribution, SharingName};
use crate::filter::working_state::DetectorSettings;
use crate::measurement::Quantity;
use crate::model::{ConstantAcceleration, ConstantVelocity, MotionModel, ProcessNoise, Singer};
pub use crate::noise::{FromMessage, Variance, VarianceValue};
pub use railfuse_catalog::foreign::can::{CanBuses, CanSettings, SensorSource};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PipelinesFile {
    /// The track for pipelines that work in chainage, where the log carries none (a ROS 2
    /// bag): a GeoJSON file, or a CSV of latitude/longitude rows (`.csv`), relative to this
    /// configuration. A log's own `/track/map` wins.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track: Option<PathBuf>,
    /// How the log is read as one run; the command line's `--clock-offset` and `--align`
    /// win over these.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<RunSettings>,
    /// `[can]`: the vehicle's DBC, which the `[sensor."<topic>"]` tables read the bus with;
    /// or `[[can]]`, one table a bus (`bus = "CAN2"`, `dbc = "gnss.dbc"`), each bus decoded
    /// with its own DBC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can: Option<CanBuses>,
    /// `[sensor."/odometer/1"] from = "can:WheelSpeed.AxleSpeed1"`: a sensor made from the
    /// CAN bus's signals (with `[can]`), fed to the pipelines as if the log had its channel.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub sensor: BTreeMap<String, SensorSource>,
    /// `[vehicle]`: the train's length and where each sensor sits on it (its lever arm and
    /// mounting in the body frame, origin at the front end). Wins over the log's `/vehicle`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<VehicleConfig>")]
    pub vehicle: Option<Spanned<VehicleConfig>>,
    /// The probability that each pipeline's safe front end interval (`/fused/<name>/train`:
    /// the min and max safe front end, as ETCS reports them) holds the true front end,
    /// two-sided; 0.9999 when absent. `refuse --confidence` wins over it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<f64>,
    /// The pipelines, each run over the same log in one pass.
    #[schemars(with = "Vec<PipelineConfig>")]
    pub pipeline: Vec<Spanned<PipelineConfig>>,
}

/// `[vehicle]`: the train as its installation drawing gives it (see the book's Vehicle page).
///
/// ```toml
/// [vehicle]
/// length_m = 104.0
/// [vehicle.sensor."/gnss/fix"]
/// lever_arm_m = [-12.5, 0.0, 4.1]    # x behind the front end is negative, y left, z up
/// [vehicle.sensor."/imu"]
/// lever_arm_m = [-13.0, 0.25, 1.2]
/// mounting_deg = [0.4, -1.1, 0.8]    # roll, pitch, yaw of its axes in the body
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VehicleConfig {
    /// What the train is called, for reports.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// From the front end to the rear end, m.
    pub length_m: f64,
    /// How far the body leans out of a curve per m/s² of unbalanced lateral acceleration,
    /// rad (about 0.015 for a coach); 0 or absent: not given.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub roll_per_lateral_mps2: f64,
    /// The drawing's installation tolerance, 1σ of each lever arm component, m (0 or absent:
    /// the sensors sit exactly where drawn). Every pipeline's front end carries it in its
    /// chainage variance.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub installation_std_m: f64,
    /// Each sensor's place by its topic; a sensor not named here is at the front end.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub sensor: BTreeMap<String, MountConfig>,
}

/// `[vehicle.sensor."<topic>"]`: one sensor's place.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MountConfig {
    /// x (along the train from the front end, negative behind it), y (left), z (up from the
    /// top of rail), m.
    pub lever_arm_m: [f64; 3],
    /// Roll, pitch and yaw of its axes in the body, degrees (about the fixed x, y, z axes).
    #[serde(default, skip_serializing_if = "is_zero_angles")]
    pub mounting_deg: [f64; 3],
    /// Its frame in the recording's transforms (a ROS `frame_id`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_id: Option<String>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_zero_angles(v: &[f64; 3]) -> bool {
    v.iter().all(|a| *a == 0.0)
}

impl VehicleConfig {
    /// The catalogue's vehicle (unchecked: [`railfuse_catalog::messages::Vehicle::check`]).
    pub fn vehicle(&self) -> railfuse_catalog::messages::Vehicle {
        railfuse_catalog::messages::Vehicle {
            stamp_ns: 0,
            name: self.name.clone(),
            length_m: self.length_m,
            roll_per_lateral_mps2: self.roll_per_lateral_mps2,
            installation_std_m: self.installation_std_m,
            sensors: self
                .sensor
                .iter()
                .map(|(topic, m)| railfuse_catalog::messages::SensorMount {
                    topic: topic.clone(),
                    frame_id: m.frame_id.clone(),
                    lever_arm_m: m.lever_arm_m,
                    mounting_deg: m.mounting_deg,
                })
                .collect(),
        }
    }

    /// The table of a vehicle (what `--save-config` writes of a log's `/vehicle`).
    pub fn of(v: &railfuse_catalog::messages::Vehicle) -> VehicleConfig {
        VehicleConfig {
            name: v.name.clone(),
            length_m: v.length_m,
            roll_per_lateral_mps2: v.roll_per_lateral_mps2,
            installation_std_m: v.installation_std_m,
            sensor: v
                .sensors
                .iter()
                .map(|s| {
                    let m = MountConfig {
                        lever_arm_m: s.lever_arm_m,
                        mounting_deg: s.mounting_deg,
                        frame_id: s.frame_id.clone(),
                    };
                    (s.topic.clone(), m)
                })
                .collect(),
        }
    }
}

/// `[run]`: the recorders' clocks of a run of several files (see the book's Runs page).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RunSettings {
    /// Each recorder's clock against the run's, `"FILE=SECONDS[,DRIFTppm]"` as
    /// `--clock-offset` takes it (`"rack.mcap=+0.350,+20ppm"`; a bare file name matches the
    /// run's file of that name): positive for a clock ahead.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clock_offsets: Vec<String>,
    /// `"gnss"`: each input's clock estimated from the GNSS time it logged and put on the
    /// first input's (`--align gnss`); `"none"`: each file on its own clock.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub align: Option<String>,
}

/// The estimators along the track, built into the spec. `filter` may also name a registered
/// kind that reads whole messages ([`crate::kinds`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterKind {
    Kalman,
    Particle,
    FederatedKalman,
    FederatedParticle,
}

impl FilterKind {
    pub const ALL: [FilterKind; 4] = [
        FilterKind::Kalman,
        FilterKind::Particle,
        FilterKind::FederatedKalman,
        FilterKind::FederatedParticle,
    ];

    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
    pub fn is_federated(self) -> bool {
        matches!(
            self,
            FilterKind::FederatedKalman | FilterKind::FederatedParticle
        )
    }
    pub fn is_particle(self) -> bool {
        matches!(self, FilterKind::Particle | FilterKind::FederatedParticle)
    }
    pub fn name(self) -> &'static str {
        match self {
            FilterKind::Kalman => "kalman",
            FilterKind::Particle => "particle",
            FilterKind::FederatedKalman => "federated_kalman",
            FilterKind::FederatedParticle => "federated_particle",
        }
    }
}

/// One pipeline: a named estimator, its motion model and its sensors. A kind that reads whole
/// messages has its settings in a table of its own (`[pipeline.safety]`,
/// `[pipeline.gnss_ins]`, `[pipeline.eddy_current]`).
//
// A key that is none of these fields names a registered kind's table: kept as written in
// `sections` and read by the kind the spec finds in its registry (crate::kinds).
#[derive(Debug, Clone, PartialEq, schemars::JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct PipelineConfig {
    /// Names the output channels `/fused/<name>/…`: letters, digits, `_` and `-`.
    pub name: String,
    /// `kalman`, `particle`, `federated_kalman`, `federated_particle`, or a registered kind
    /// (`ekf_safety`, `gnss_ins`, `eddy_current`).
    #[schemars(with = "String")]
    pub filter: Spanned<String>,
    pub motion: MotionConfig,
    #[schemars(default)]
    pub initial: InitialConfig,
    /// Measurements are released to the filter in sensor-time order once the replay is this
    /// far past them, so sensors with different latencies are fused in the right order.
    #[schemars(default = "default_reorder_window_s")]
    pub reorder_window_s: f64,
    /// Fused states on a regular grid at this rate (predicted to each tick) instead of one
    /// state per accepted measurement.
    pub output_rate_hz: Option<f64>,
    /// Kalman and particle pipelines: after this many gate rejections in a row of one
    /// quantity (chainage, speed or acceleration), the filter has locked itself out (its
    /// estimate, not the sensors, is wrong: a hard stop its motion model did not expect). The
    /// next one widens that component's variance until the measurement fits (NIS = 1) and is
    /// used. 0 turns this off. Federated pipelines have their detector's `gate_failures`.
    pub gate_lockout: Option<u32>,
    /// Kalman pipelines: also write the fixed-interval RTS smoothed states.
    #[schemars(default)]
    pub smoother: bool,
    pub particle: Option<ParticleSettings>,
    /// Federated pipelines: the master filter's fusion, feedback, β tables and fault detector.
    pub federated: Option<FederatedConfig>,
    /// Registered kinds' settings tables by key (`safety`, `gnss_ins`, `eddy_current`), as
    /// written.
    #[schemars(skip)]
    pub sections: BTreeMap<String, Spanned<toml::Value>>,
    /// The channels it fuses, one table each.
    #[schemars(with = "Vec<SensorConfig>")]
    pub sensor: Vec<Spanned<SensorConfig>>,
    /// What `railfuse tune` may change in this pipeline and what it minimises; refuse
    /// ignores it.
    pub tune: Option<TuneConfig>,
    /// How it is scored on a log without truth: a sensor withheld from it in outages.
    pub eval: Option<EvalConfig>,
}

impl PipelineConfig {
    /// The keys of a `[[pipeline]]` table other than kinds' settings tables.
    pub const FIELDS: &'static [&'static str] = &[
        "name",
        "filter",
        "motion",
        "initial",
        "reorder_window_s",
        "output_rate_hz",
        "gate_lockout",
        "smoother",
        "particle",
        "federated",
        "sensor",
        "tune",
        "eval",
    ];

    /// The estimator along the track `filter` names, if it names one.
    pub fn filter_kind(&self) -> Option<FilterKind> {
        FilterKind::parse(self.filter.get_ref())
    }
}

/// Field by field (serde's derive cannot keep the unknown keys, the kinds' tables, without
/// buffering the table, which would lose the sensors' places in the file).
impl<'de> Deserialize<'de> for PipelineConfig {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Table;
        impl<'de> serde::de::Visitor<'de> for Table {
            type Value = PipelineConfig;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a [[pipeline]] table")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<PipelineConfig, A::Error> {
                use serde::de::Error as _;
                let (mut name, mut filter, mut motion, mut sensor) = (None, None, None, None);
                let mut c = PipelineConfig {
                    name: String::new(),
                    filter: Spanned::new(0..0, String::new()),
                    motion: MotionConfig::ConstantVelocity {
                        acceleration_psd: 0.0,
                    },
                    initial: InitialConfig::default(),
                    reorder_window_s: default_reorder_window_s(),
                    output_rate_hz: None,
                    gate_lockout: None,
                    smoother: false,
                    particle: None,
                    federated: None,
                    sections: BTreeMap::new(),
                    sensor: Vec::new(),
                    tune: None,
                    eval: None,
                };
                while let Some(key) = map.next_key::<String>()? {
                    match key.as_str() {
                        "name" => name = Some(map.next_value()?),
                        "filter" => filter = Some(map.next_value()?),
                        "motion" => motion = Some(map.next_value()?),
                        "initial" => c.initial = map.next_value()?,
                        "reorder_window_s" => c.reorder_window_s = map.next_value()?,
                        "output_rate_hz" => c.output_rate_hz = Some(map.next_value()?),
                        "gate_lockout" => c.gate_lockout = Some(map.next_value()?),
                        "smoother" => c.smoother = map.next_value()?,
                        "particle" => c.particle = Some(map.next_value()?),
                        "federated" => c.federated = Some(map.next_value()?),
                        "sensor" => sensor = Some(map.next_value()?),
                        "tune" => c.tune = Some(map.next_value()?),
                        "eval" => c.eval = Some(map.next_value()?),
                        _ => {
                            let table = map.next_value()?;
                            c.sections.insert(key, table);
                        }
                    }
                }
                c.name = name.ok_or_else(|| A::Error::missing_field("name"))?;
                c.filter = filter.ok_or_else(|| A::Error::missing_field("filter"))?;
                c.motion = motion.ok_or_else(|| A::Error::missing_field("motion"))?;
                c.sensor = sensor.ok_or_else(|| A::Error::missing_field("sensor"))?;
                Ok(c)
            }
        }
        d.deserialize_map(Table)
    }
}

/// The table as it is written back: the kinds' tables after the estimators' settings.
impl Serialize for PipelineConfig {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        #[derive(Serialize)]
        struct View<'a> {
            name: &'a str,
            filter: &'a Spanned<String>,
            motion: &'a MotionConfig,
            initial: &'a InitialConfig,
            reorder_window_s: f64,
            #[serde(skip_serializing_if = "Option::is_none")]
            output_rate_hz: Option<f64>,
            #[serde(skip_serializing_if = "Option::is_none")]
            gate_lockout: Option<u32>,
            #[serde(skip_serializing_if = "std::ops::Not::not")]
            smoother: bool,
            #[serde(skip_serializing_if = "Option::is_none")]
            particle: Option<&'a ParticleSettings>,
            #[serde(skip_serializing_if = "Option::is_none")]
            federated: Option<&'a FederatedConfig>,
            #[serde(flatten)]
            sections: &'a BTreeMap<String, Spanned<toml::Value>>,
            sensor: &'a [Spanned<SensorConfig>],
            #[serde(skip_serializing_if = "Option::is_none")]
            tune: Option<&'a TuneConfig>,
            #[serde(skip_serializing_if = "Option::is_none")]
            eval: Option<&'a EvalConfig>,
        }
        View {
            name: &self.name,
            filter: &self.filter,
            motion: &self.motion,
            initial: &self.initial,
            reorder_window_s: self.reorder_window_s,
            output_rate_hz: self.output_rate_hz,
            gate_lockout: self.gate_lockout,
            smoother: self.smoother,
            particle: self.particle.as_ref(),
            federated: self.federated.as_ref(),
            sections: &self.sections,
            sensor: &self.sensor,
            tune: self.tune.as_ref(),
            eval: self.eval.as_ref(),
        }
        .serialize(s)
    }
}

fn default_reorder_window_s() -> f64 {
    0.5
}

/// The motion model and its noise: exactly one noise parameter, the one the model takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum MotionConfig {
    /// `[s, v]`, white acceleration of PSD `acceleration_psd` (m²/s³).
    ConstantVelocity { acceleration_psd: f64 },
    /// `[s, v, a]`: `jerk_psd` (continuous white jerk, m²/s⁵) or `jerk_variance` (a jerk held
    /// over each step, m²/s⁶, as sources 000 and 001 write it).
    ConstantAcceleration {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        jerk_psd: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        jerk_variance: Option<f64>,
    },
    /// `[s, v, a]`, acceleration a Gauss–Markov process.
    Singer {
        time_constant_s: f64,
        acceleration_std_mps2: f64,
    },
}

impl MotionConfig {
    /// The model, its noise checked.
    pub fn model(&self) -> Result<MotionModel, String> {
        Ok(match *self {
            MotionConfig::ConstantVelocity { acceleration_psd } => {
                MotionModel::ConstantVelocity(ConstantVelocity {
                    acceleration_psd: positive("motion.acceleration_psd", acceleration_psd)?,
                })
            }
            MotionConfig::ConstantAcceleration {
                jerk_psd,
                jerk_variance,
            } => {
                let noise = match (jerk_psd, jerk_variance) {
                    (Some(q), None) => ProcessNoise::WhiteJerkPsd(positive("motion.jerk_psd", q)?),
                    (None, Some(v)) => {
                        ProcessNoise::PiecewiseJerkVariance(positive("motion.jerk_variance", v)?)
                    }
                    _ => return Err("motion needs exactly one of jerk_psd or jerk_variance".into()),
                };
                MotionModel::ConstantAcceleration(ConstantAcceleration { noise })
            }
            MotionConfig::Singer {
                time_constant_s,
                acceleration_std_mps2,
            } => MotionModel::Singer(Singer {
                time_constant_s: positive("motion.time_constant_s", time_constant_s)?,
                acceleration_std_mps2: positive(
                    "motion.acceleration_std_mps2",
                    acceleration_std_mps2,
                )?,
            }),
        })
    }
}

/// Where the filter starts. By default at its first position measurement: chainage from it;
/// speed from the latest valid speed measurement before it (else `speed_mps`,
/// `speed_std_mps`); acceleration `acceleration_mps2` (default 0) with
/// `acceleration_std_mps2`. With `chainage_m` (and `chainage_std_m`, default 0.01 m) it
/// starts there at its first usable measurement of any kind; a pipeline none of whose sensors
/// gives chainage (radar and odometers only) starts so at chainage 0: distance travelled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct InitialConfig {
    /// Start here, m, at the first usable measurement of any kind.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chainage_m: Option<f64>,
    /// The spread of `chainage_m`, m (default 0.01).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chainage_std_m: Option<f64>,
    pub speed_mps: f64,
    pub speed_std_mps: f64,
    pub acceleration_mps2: f64,
    pub acceleration_std_mps2: f64,
}

impl Default for InitialConfig {
    fn default() -> Self {
        Self {
            chainage_m: None,
            chainage_std_m: None,
            speed_mps: 0.0,
            speed_std_mps: 5.0,
            acceleration_mps2: 0.0,
            acceleration_std_mps2: 1.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FederatedConfig {
    #[serde(default = "default_feedback")]
    pub feedback: Feedback,
    /// How the master combines the local estimates: "information" (the default: β is each
    /// sub-filter's share of the information) or "shares" (β weights the estimates).
    #[serde(default, skip_serializing_if = "is_information")]
    pub fusion: Fusion,
    /// Master fusion period; 0 fuses after every accepted measurement.
    #[serde(default = "default_fusion_period_s")]
    pub fusion_period_s: f64,
    #[serde(default = "default_redistribution")]
    pub redistribution: Redistribution,
    #[serde(default)]
    pub detector: DetectorSettings,
    /// A named β table: "even" (the default), "source_000" (devices loop and radar) or
    /// "source_001" (devices ins, gnss and radar); a table for other devices is an error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharing: Option<SharingName>,
    /// β by speed band, in increasing speed; the last band has no `below_kmh`. Instead of
    /// `sharing`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub band: Vec<BandConfig>,
}

impl Default for FederatedConfig {
    fn default() -> Self {
        Self {
            feedback: default_feedback(),
            fusion: Fusion::Information,
            fusion_period_s: default_fusion_period_s(),
            redistribution: default_redistribution(),
            detector: DetectorSettings::default(),
            sharing: None,
            band: Vec::new(),
        }
    }
}

fn is_information(f: &Fusion) -> bool {
    *f == Fusion::Information
}
fn default_feedback() -> Feedback {
    Feedback::FusionReset
}
fn default_fusion_period_s() -> f64 {
    1.0
}
fn default_redistribution() -> Redistribution {
    Redistribution::Accuracy
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BandConfig {
    /// The band holds speeds below this, km/h (the last band has none: every speed above).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub below_kmh: Option<f64>,
    /// β per device name.
    pub beta: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    pub topic: String,
    /// What the sensor is, where its channel's schema cannot say: a ROS
    /// `geometry_msgs/msg/TwistWithCovarianceStamped` is a `"radar"`'s speed or an
    /// `"odometer"`'s (also `"gnss"`, `"imu"`). railfuse's own channels need none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<railfuse_catalog::foreign::Role>,
    /// Federated filters: the device (sub-filter) this channel feeds, or "master" for
    /// absolute fixes fused in the master filter. Default: the topic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// Which of the message's quantities to use (default: all its sensor model measures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fields: Option<Vec<Quantity>>,
    pub variance: Variance,
    /// Reject a measurement whose normalised innovation squared exceeds this (χ², 1 dof:
    /// 6.63 keeps 99 %, 10.83 keeps 99.9 %).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gate_nis: Option<f64>,
    /// An absolute fix (a balise, the loop, GNSS chainage): once the gate has rejected this
    /// many of its chainage measurements in a row, the last of them is taken as the truth of
    /// the position, as PX4's ekf2 resets after its innovation checks fail for a while: the
    /// filter's position is set to the fix, with the fix's variance (diagnostics decision
    /// `reset_to_fix`). Default: 1 for a balise (a surveyed position in a telegram), 3 for the
    /// loop, 10 for GNSS (a second at 10 Hz: multipath passes). 0: never, the gate alone (the
    /// sources' behaviour, which a filter too sure of itself never recovers from).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reset_after: Option<u32>,
    /// Weight this sensor by what its innovations show rather than by its variance alone
    /// (covariance matching over its last `window` innovations), never above its stated
    /// weight: a loop whose error accumulates with distance, once a balise has shown it off,
    /// stops pulling the estimate back to its own error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive_variance: Option<AdaptiveVarianceConfig>,
    /// Estimate this sensor's along-track position bias as a state (a GNSS receiver's slowly
    /// wandering error, which white measurement noise cannot describe).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chainage_bias: Option<ChainageBiasConfig>,
    /// Estimate this sensor's acceleration bias as a state (an accelerometer's bias).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceleration_bias: Option<AccelerationBiasConfig>,
    /// Estimate this sensor's speed scale factor as a state (Doppler radar, worn wheels), or
    /// its chainage scale (`quantity = "chainage"`: a loop's survey scale).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_factor: Option<ScaleFactorConfig>,
    /// The speed it reports is the mean over this window ending at its stamp (an odometer
    /// that counts pulses over 0.2 s), s: under the constant-acceleration model that is
    /// `v − a W / 2`, not `v`, a lag of `W/2` that otherwise shows as a position error after
    /// every brake and start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_window_s: Option<f64>,
    /// Its stamps are this late, s: the measurement time is the stamp less this (a driver
    /// that stamps a message when it arrives; PX4's default GNSS delay is 0.11 s). The
    /// measurement is fused at its own time, the reorder window holding the others back,
    /// as PX4's delayed fusion horizon does; so it must stay below `reorder_window_s`.
    /// Negative: stamped early. `tune` can estimate it (`sensor[TOPIC].time_offset_s`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_offset_s: Option<f64>,
    /// The log must have this channel: without it refuse and tune stop. By default a sensor
    /// whose channel is missing (a balise on a run that passed none) is left out with a
    /// warning, and the pipeline runs on the others.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub required: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AdaptiveVarianceConfig {
    /// The innovations its variance is estimated from (at least 2): 20 at 1 Hz forgets a
    /// surprise in 20 s.
    pub window: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChainageBiasConfig {
    /// Stationary standard deviation, m.
    pub std_m: f64,
    /// Correlation time, s.
    pub time_constant_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AccelerationBiasConfig {
    /// Stationary standard deviation, m/s².
    pub std_mps2: f64,
    /// Correlation time, s.
    pub time_constant_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScaleFactorConfig {
    /// Prior standard deviation (0.005 = 0.5 %).
    pub std: f64,
    /// Random-walk intensity, 1/s (0: a constant scale factor).
    #[serde(default)]
    pub walk_per_s: f64,
    /// The quantity it scales: `speed` (a radar, an odometer: the default) or `chainage` (a
    /// loop whose surveyed chainages are off by a scale, so its error grows along the line).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantity: Option<Quantity>,
}

/// `[pipeline.tune]`: the noise values `railfuse tune` chooses, within their bounds, and what
/// it minimises over the logs.
///
/// ```toml
/// [pipeline.tune]
/// reference = "/truth/state"   # or an RTK GNSS channel, or another pipeline's state
/// objective = "rmse"           # position_weight · RMSE(s) + speed_weight · RMSE(v); or "nll"
/// optimiser = "nelder_mead"    # grid, nelder_mead, pso, bayesian, em
/// [pipeline.tune.params]
/// "motion.jerk_psd" = { min = 0.001, max = 10.0 }
/// "sensor[/radar/speed].variance" = { min = 1e-4, max = 1.0 }
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TuneConfig {
    /// The reference topic (ground truth, an RTK GNSS channel, another pipeline's state or
    /// smoothed states); without one the objective is the innovations' likelihood.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objective: Option<ObjectiveKind>,
    /// Weights of the `rmse` objective: position (per m) and speed (per m/s) RMSE; 1 and 1
    /// when not given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_weight: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_weight: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optimiser: Option<OptimiserKind>,
    /// The most evaluations (replays of every log) the search may make.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_evaluations: Option<usize>,
    /// Seed of the randomised searches (particle swarm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Parameter path → bounds. Paths name a number of the pipeline's table:
    /// `motion.jerk_psd`, `sensor[/radar/speed].variance`, `sensor[/gnss].variance.chainage`,
    /// `sensor[/odometer/1].gate_nis`, `sensor[/gnss].chainage_bias.std_m`, ….
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, ParamBounds>,
}

/// `[pipeline.eval]`: scoring the pipeline on a log without truth by the withholding
/// protocol (`refuse --withhold TOPIC --outages SPEC` does the same for every pipeline that
/// fuses TOPIC, and wins):
///
/// ```toml
/// [pipeline.eval]
/// withhold = "/gnss/fix"
/// outages = "60:every=180"     # or "standard": 30, 60 and 120 s in turn, every 180 s
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EvalConfig {
    /// A sensor topic of the pipeline hidden from it inside the outages (for the whole run
    /// without `outages`); the accuracy table is then scored against it.
    #[schemars(with = "String")]
    pub withhold: Spanned<String>,
    /// `LEN[:every=PERIOD][:from=T]` (s; the first outage starts 60 s into the run unless
    /// `from` says otherwise), or `standard`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<String>")]
    pub outages: Option<Spanned<String>>,
}

/// What tuning minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ObjectiveKind {
    /// Weighted position and speed RMSE against the reference, pooled over the logs.
    Rmse,
    /// Negative log-likelihood of the innovations of every measurement that reached the gate.
    Nll,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum OptimiserKind {
    Grid,
    /// The default. `nelder-mead` is read as well, as the command line takes it.
    #[serde(alias = "nelder-mead")]
    NelderMead,
    /// Particle swarm.
    Pso,
    /// Bayesian optimisation: efficient global optimisation (egobox), a Gaussian-process model
    /// of the objective sampled where the expected improvement is largest.
    Bayesian,
    /// Expectation–maximisation: the maximum-likelihood motion noise and sensor variances of
    /// a linear-Gaussian Kalman pipeline.
    Em,
}

impl OptimiserKind {
    /// Every optimiser, for help texts.
    pub const ALL: &'static [Self] = &[
        OptimiserKind::Grid,
        OptimiserKind::NelderMead,
        OptimiserKind::Pso,
        OptimiserKind::Bayesian,
        OptimiserKind::Em,
    ];
}

impl ObjectiveKind {
    /// Every objective, for help texts.
    pub const ALL: &'static [Self] = &[ObjectiveKind::Rmse, ObjectiveKind::Nll];
}

/// The names of `values` as a configuration file spells them.
pub fn value_names<T: Serialize>(values: &[T]) -> Vec<String> {
    values
        .iter()
        .filter_map(|v| serde_json::to_value(v).ok()?.as_str().map(str::to_owned))
        .collect()
}

/// Bounds of one tuned value, in its own units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ParamBounds {
    pub min: f64,
    pub max: f64,
    /// `log` (the default when both bounds are positive: noise values span decades) or
    /// `linear`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<Scale>,
    /// Grid search: points along this parameter (default 5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Scale {
    Linear,
    Log,
}

impl SensorConfig {
    pub fn device_name(&self) -> &str {
        self.device.as_deref().unwrap_or(&self.topic)
    }
}

impl PipelinesFile {
    /// Reads a configuration file: its syntax and types, not yet its values.
    pub fn load(path: &Path) -> Result<(Self, String)> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::ConfigRead {
            path: path.to_owned(),
            source,
        })?;
        Ok((Self::parse(&text, path)?, text))
    }

    /// Parses configuration text; `path` names it in errors, which give line and column.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        toml::from_str(text).map_err(|e| Error::ConfigSyntax {
            path: path.to_owned(),
            message: match e.span() {
                Some(span) => {
                    let (line, column) = line_column(text, span.start);
                    format!("line {line}, column {column}: {}", e.message())
                }
                None => e.message().to_owned(),
            },
        })
    }
}

impl PipelineConfig {
    /// This pipeline alone, as TOML: what is stored beside its fused channels.
    pub fn to_toml(&self) -> String {
        toml::to_string(&PipelinesFile {
            track: None,
            run: None,
            can: None,
            sensor: BTreeMap::new(),
            vehicle: None,
            confidence: None,
            pipeline: vec![Spanned::new(0..0, self.clone())],
        })
        .expect("a config serialises")
    }
}

/// Line and column (from 1) of byte `offset` of `text`.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// A config file path for messages when the text did not come from a file.
pub fn embedded_path(name: &str) -> PathBuf {
    PathBuf::from(format!("<embedded {name}>"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The help lists every value the parser takes: a new variant fails to compile here until
    /// it is in `ALL`.
    #[test]
    fn help_lists_every_optimiser_and_objective_and_both_spellings_read() {
        for k in OptimiserKind::ALL {
            match k {
                OptimiserKind::Grid
                | OptimiserKind::NelderMead
                | OptimiserKind::Pso
                | OptimiserKind::Bayesian
                | OptimiserKind::Em => {}
            }
        }
        for k in ObjectiveKind::ALL {
            match k {
                ObjectiveKind::Rmse | ObjectiveKind::Nll => {}
            }
        }
        assert_eq!(OptimiserKind::ALL.len(), 5);
        assert_eq!(ObjectiveKind::ALL.len(), 2);
        for spelling in ["nelder_mead", "nelder-mead"] {
            let t: TuneConfig = toml::from_str(&format!("optimiser = \"{spelling}\"")).unwrap();
            assert_eq!(t.optimiser, Some(OptimiserKind::NelderMead));
        }
    }
}
