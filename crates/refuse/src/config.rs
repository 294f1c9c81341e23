//! The pipeline configuration file (TOML). One file declares any number of named pipelines;
//! one replay runs them all.
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

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::filter::federated::Feedback;
use crate::filter::particle::Resampling;
use crate::filter::sharing::{Redistribution, SharingTable, SpeedBand};
use crate::filter::working_state::DetectorSettings;
use crate::measurement::Quantity;
use crate::model::{ProcessNoise, SensorState};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelinesConfig {
    pub pipeline: Vec<PipelineConfig>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterKind {
    Kalman,
    Particle,
    FederatedKalman,
    FederatedParticle,
}

impl FilterKind {
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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineConfig {
    /// Names the output channels `/fused/<name>/…`: letters, digits, `_` and `-`.
    pub name: String,
    pub filter: FilterKind,
    pub motion: MotionConfig,
    #[serde(default)]
    pub initial: InitialConfig,
    /// Measurements are released to the filter in sensor-time order once the replay is this
    /// far past them, so sensors with different latencies are fused in the right order.
    #[serde(default = "default_reorder_window_s")]
    pub reorder_window_s: f64,
    /// Fused states on a regular grid at this rate (predicted to each tick) instead of one
    /// state per accepted measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub output_rate_hz: Option<f64>,
    /// Kalman and particle pipelines: after this many gate rejections in a row of one
    /// quantity (chainage, speed or acceleration), the filter has locked itself out (its
    /// estimate, not the sensors, is wrong: a hard stop its motion model did not expect). The
    /// next one widens that component's variance until the measurement fits (NIS = 1) and is
    /// used. 0 turns this off. Federated pipelines have their detector's `gate_failures`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gate_lockout: Option<u32>,
    /// Kalman pipelines: also write the fixed-interval RTS smoothed states.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub smoother: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particle: Option<ParticleConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub federated: Option<FederatedConfig>,
    pub sensor: Vec<SensorConfig>,
}

/// Gate rejections in a row of one quantity after which a centralised filter takes itself to
/// be locked out.
pub const DEFAULT_GATE_LOCKOUT: u32 = 5;

fn default_reorder_window_s() -> f64 {
    0.5
}

/// The motion model and its noise: exactly one noise parameter, the one the model takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// Dimension of the state.
    pub fn dimension(&self) -> usize {
        match self {
            MotionConfig::ConstantVelocity { .. } => 2,
            _ => 3,
        }
    }
}

/// Where the filter starts. By default at its first position measurement: chainage from it;
/// speed from the latest valid speed measurement before it (else `speed_mps`,
/// `speed_std_mps`); acceleration `acceleration_mps2` (default 0) with
/// `acceleration_std_mps2`. With `chainage_m` (and `chainage_std_m`, default 0.01 m) it
/// starts there at its first usable measurement of any kind; a pipeline none of whose sensors
/// gives chainage (radar and odometers only) starts so at chainage 0: distance travelled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialConfig {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chainage_m: Option<f64>,
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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParticleConfig {
    pub particles: usize,
    pub resampling: Resampling,
    /// Resample when the effective sample size falls below this share of the particles.
    pub ess_threshold: f64,
    /// Roughening constant K after resampling (0: off).
    pub roughening: f64,
    pub seed: u64,
}

impl Default for ParticleConfig {
    fn default() -> Self {
        Self {
            particles: 1000,
            resampling: Resampling::Systematic,
            ess_threshold: 0.5,
            roughening: 0.1,
            seed: 1,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FederatedConfig {
    #[serde(default = "default_feedback")]
    pub feedback: Feedback,
    /// Master fusion period; 0 fuses after every accepted measurement.
    #[serde(default = "default_fusion_period_s")]
    pub fusion_period_s: f64,
    #[serde(default = "default_redistribution")]
    pub redistribution: Redistribution,
    #[serde(default)]
    pub detector: DetectorSettings,
    /// β by speed band, in increasing speed; the last band has no `below_kmh`. Default: source
    /// 001's table for devices ins/gnss/radar, source 000's for loop/radar, else equal shares.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub band: Vec<BandConfig>,
}

impl Default for FederatedConfig {
    fn default() -> Self {
        Self {
            feedback: default_feedback(),
            fusion_period_s: default_fusion_period_s(),
            redistribution: default_redistribution(),
            detector: DetectorSettings::default(),
            band: Vec::new(),
        }
    }
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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BandConfig {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub below_kmh: Option<f64>,
    /// β per device name.
    pub beta: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "a variance (a number, SI units squared), \"message\", or a table of those per field"
)]
pub enum Variance {
    Fixed(f64),
    FromMessage(FromMessage),
    PerField(BTreeMap<Quantity, VarianceValue>),
}

/// One field's variance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "a variance (a number, SI units squared) or \"message\""
)]
pub enum VarianceValue {
    Fixed(f64),
    FromMessage(FromMessage),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FromMessage {
    Message,
}

impl Variance {
    /// The variance setting of one field, if the sensor gives one for it.
    pub fn of(&self, q: Quantity) -> Option<VarianceValue> {
        match self {
            Variance::Fixed(v) => Some(VarianceValue::Fixed(*v)),
            Variance::FromMessage(m) => Some(VarianceValue::FromMessage(*m)),
            Variance::PerField(map) => map.get(&q).copied(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    pub topic: String,
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
    /// Estimate this sensor's along-track position bias as a state (a GNSS receiver's slowly
    /// wandering error, which white measurement noise cannot describe).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chainage_bias: Option<ChainageBiasConfig>,
    /// Estimate this sensor's acceleration bias as a state (an accelerometer's bias).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceleration_bias: Option<AccelerationBiasConfig>,
    /// Estimate this sensor's speed scale factor as a state (Doppler radar, worn wheels).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_factor: Option<ScaleFactorConfig>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChainageBiasConfig {
    /// Stationary standard deviation, m.
    pub std_m: f64,
    /// Correlation time, s.
    pub time_constant_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerationBiasConfig {
    /// Stationary standard deviation, m/s².
    pub std_mps2: f64,
    /// Correlation time, s.
    pub time_constant_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleFactorConfig {
    /// Prior standard deviation (0.005 = 0.5 %).
    pub std: f64,
    /// Random-walk intensity, 1/s (0: a constant scale factor).
    #[serde(default)]
    pub walk_per_s: f64,
}

impl SensorConfig {
    pub fn device_name(&self) -> &str {
        self.device.as_deref().unwrap_or(&self.topic)
    }

    /// The calibration states this sensor adds to the pipeline's state, in state order.
    pub fn sensor_states(&self) -> impl Iterator<Item = SensorState> + '_ {
        let bias = self.chainage_bias.map(|b| SensorState::ChainageBias {
            std_m: b.std_m,
            time_constant_s: b.time_constant_s,
        });
        let accel = self
            .acceleration_bias
            .map(|b| SensorState::AccelerationBias {
                std_mps2: b.std_mps2,
                time_constant_s: b.time_constant_s,
            });
        let scale = self.scale_factor.map(|k| SensorState::ScaleFactor {
            std: k.std,
            walk_per_s: k.walk_per_s,
        });
        bias.into_iter().chain(accel).chain(scale)
    }
}

/// The most state components a pipeline may have (motion and sensor states together).
pub const MAX_STATES: usize = 6;

/// The device name reserved for the master filter of a federated pipeline.
pub const MASTER_DEVICE: &str = "master";

impl PipelinesConfig {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::ConfigRead {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates configuration text; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let config: PipelinesConfig = toml::from_str(text).map_err(|e| Error::ConfigSyntax {
            path: path.to_owned(),
            message: match e.span() {
                Some(span) => {
                    let (line, column) = line_column(text, span.start);
                    format!("line {line}, column {column}: {}", e.message())
                }
                None => e.message().to_owned(),
            },
        })?;
        config.validate(path)?;
        Ok(config)
    }

    fn validate(&self, path: &Path) -> Result<()> {
        if self.pipeline.is_empty() {
            return Err(Error::ConfigSyntax {
                path: path.to_owned(),
                message: "no [[pipeline]] declared".into(),
            });
        }
        for (i, p) in self.pipeline.iter().enumerate() {
            let invalid = |message: String| Error::ConfigInvalid {
                path: path.to_owned(),
                pipeline: p.name.clone(),
                message,
            };
            if self.pipeline[..i].iter().any(|q| q.name == p.name) {
                return Err(invalid("declared twice".into()));
            }
            p.check().map_err(invalid)?;
        }
        Ok(())
    }
}

fn positive(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be positive, not {v}"))
    }
}

impl PipelineConfig {
    /// Checks every value and combination; the message names the offending key.
    fn check(&self) -> Result<(), String> {
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err("the name may hold only letters, digits, '_' and '-'".into());
        }
        match &self.motion {
            MotionConfig::ConstantVelocity { acceleration_psd } => {
                positive("motion.acceleration_psd", *acceleration_psd)?;
            }
            MotionConfig::ConstantAcceleration { .. } => {
                self.process_noise()?;
            }
            MotionConfig::Singer {
                time_constant_s,
                acceleration_std_mps2,
            } => {
                positive("motion.time_constant_s", *time_constant_s)?;
                positive("motion.acceleration_std_mps2", *acceleration_std_mps2)?;
            }
        }
        if !(self.reorder_window_s.is_finite() && self.reorder_window_s >= 0.0) {
            return Err(format!(
                "reorder_window_s must be ≥ 0, not {}",
                self.reorder_window_s
            ));
        }
        if let Some(r) = self.output_rate_hz {
            positive("output_rate_hz", r)?;
        }
        let init = &self.initial;
        if !(init.speed_std_mps > 0.0
            && init.acceleration_std_mps2 > 0.0
            && init.speed_mps.is_finite()
            && init.acceleration_mps2.is_finite())
        {
            return Err("initial standard deviations must be positive".into());
        }
        if init.chainage_m.is_some_and(|c| !c.is_finite())
            || init
                .chainage_std_m
                .is_some_and(|s| !(s.is_finite() && s > 0.0))
        {
            return Err("initial chainage_m must be finite and chainage_std_m positive".into());
        }
        if self.gate_lockout.is_some() && self.filter.is_federated() {
            return Err("gate_lockout is for kalman and particle pipelines; a federated pipeline's devices have [federated] detector.gate_failures".into());
        }
        if self.dimension() > MAX_STATES {
            return Err(format!(
                "{} motion states and {} sensor states: at most {MAX_STATES} state components in all",
                self.motion.dimension(),
                self.sensor_states().len()
            ));
        }
        if self.smoother && self.filter != FilterKind::Kalman {
            return Err(format!("smoother = true needs filter = \"kalman\" (the RTS smoother is linear), not \"{}\"", self.filter.name()));
        }
        match (&self.particle, self.filter.is_particle()) {
            (Some(_), false) => {
                return Err(format!(
                    "a [particle] section, but filter = \"{}\"",
                    self.filter.name()
                ))
            }
            (Some(pc), true) => {
                if pc.particles == 0 {
                    return Err("particle.particles must be at least 1".into());
                }
                if !(pc.ess_threshold > 0.0 && pc.ess_threshold <= 1.0) {
                    return Err(format!(
                        "particle.ess_threshold must be in (0, 1], not {}",
                        pc.ess_threshold
                    ));
                }
                if !(pc.roughening.is_finite() && pc.roughening >= 0.0) {
                    return Err(format!(
                        "particle.roughening must be ≥ 0, not {}",
                        pc.roughening
                    ));
                }
            }
            _ => {}
        }
        if self.sensor.is_empty() {
            return Err("no [[pipeline.sensor]]: nothing to fuse".into());
        }
        for s in &self.sensor {
            let values: Vec<VarianceValue> = match &s.variance {
                Variance::PerField(m) => m.values().copied().collect(),
                v => v.of(Quantity::Chainage).into_iter().collect(),
            };
            for v in values {
                if let VarianceValue::Fixed(v) = v {
                    if !(v.is_finite() && v > 0.0) {
                        return Err(format!(
                            "sensor {}: variance must be positive, not {v}",
                            s.topic
                        ));
                    }
                }
            }
            if let Some(g) = s.gate_nis {
                positive(&format!("sensor {}: gate_nis", s.topic), g)?;
            }
            if let Some(fields) = &s.fields {
                if fields.is_empty() {
                    return Err(format!("sensor {}: fields is empty", s.topic));
                }
                if self.motion.dimension() < 3 && fields.contains(&Quantity::Acceleration) {
                    return Err(format!(
                        "sensor {}: the constant-velocity model has no acceleration to measure",
                        s.topic
                    ));
                }
            }
            if let Variance::PerField(m) = &s.variance {
                for q in s.fields.iter().flatten() {
                    if !m.contains_key(q) {
                        return Err(format!(
                            "sensor {}: no variance for field {}",
                            s.topic,
                            q.name()
                        ));
                    }
                }
            }
            if s.device.is_some() && !self.filter.is_federated() {
                return Err(format!(
                    "sensor {}: device is for federated filters only",
                    s.topic
                ));
            }
            if let Some(b) = s.chainage_bias {
                positive(&format!("sensor {}: chainage_bias.std_m", s.topic), b.std_m)?;
                positive(
                    &format!("sensor {}: chainage_bias.time_constant_s", s.topic),
                    b.time_constant_s,
                )?;
                if s.fields
                    .as_ref()
                    .is_some_and(|f| !f.contains(&Quantity::Chainage))
                {
                    return Err(format!(
                        "sensor {}: chainage_bias, but chainage is not among its fields",
                        s.topic
                    ));
                }
            }
            if let Some(b) = s.acceleration_bias {
                positive(
                    &format!("sensor {}: acceleration_bias.std_mps2", s.topic),
                    b.std_mps2,
                )?;
                positive(
                    &format!("sensor {}: acceleration_bias.time_constant_s", s.topic),
                    b.time_constant_s,
                )?;
                if self.motion.dimension() < 3
                    || s.fields
                        .as_ref()
                        .is_some_and(|f| !f.contains(&Quantity::Acceleration))
                {
                    return Err(format!(
                        "sensor {}: acceleration_bias, but no acceleration is measured",
                        s.topic
                    ));
                }
            }
            if let Some(k) = s.scale_factor {
                positive(&format!("sensor {}: scale_factor.std", s.topic), k.std)?;
                if !(k.walk_per_s.is_finite() && k.walk_per_s >= 0.0) {
                    return Err(format!(
                        "sensor {}: scale_factor.walk_per_s must be ≥ 0, not {}",
                        s.topic, k.walk_per_s
                    ));
                }
                if s.fields
                    .as_ref()
                    .is_some_and(|f| !f.contains(&Quantity::Speed))
                {
                    return Err(format!(
                        "sensor {}: scale_factor, but speed is not among its fields",
                        s.topic
                    ));
                }
            }
        }
        match (&self.federated, self.filter.is_federated()) {
            (Some(_), false) => {
                return Err(format!(
                    "a [federated] section, but filter = \"{}\"",
                    self.filter.name()
                ))
            }
            (_, true) => {
                let f = self.federated.clone().unwrap_or_default();
                if !(f.fusion_period_s.is_finite() && f.fusion_period_s >= 0.0) {
                    return Err(format!(
                        "federated.fusion_period_s must be ≥ 0, not {}",
                        f.fusion_period_s
                    ));
                }
                positive("federated.detector.timeout_s", f.detector.timeout_s)?;
                positive(
                    "federated.detector.agreement_chi2",
                    f.detector.agreement_chi2,
                )?;
                if !(f.detector.max_exclusion_s.is_finite() && f.detector.max_exclusion_s >= 0.0) {
                    return Err(format!(
                        "federated.detector.max_exclusion_s must be ≥ 0, not {}",
                        f.detector.max_exclusion_s
                    ));
                }
                if !(f.detector.consistency_chi2.is_finite() && f.detector.consistency_chi2 >= 0.0)
                {
                    return Err(format!(
                        "federated.detector.consistency_chi2 must be ≥ 0, not {}",
                        f.detector.consistency_chi2
                    ));
                }
                if self.devices().is_empty() {
                    return Err(
                        "a federated filter needs at least one device besides the master".into(),
                    );
                }
                self.sharing_table()?;
            }
            _ => {}
        }
        Ok(())
    }

    pub fn process_noise(&self) -> Result<ProcessNoise, String> {
        match self.motion {
            MotionConfig::ConstantAcceleration {
                jerk_psd: Some(q),
                jerk_variance: None,
            } => Ok(ProcessNoise::WhiteJerkPsd(positive("motion.jerk_psd", q)?)),
            MotionConfig::ConstantAcceleration {
                jerk_psd: None,
                jerk_variance: Some(v),
            } => Ok(ProcessNoise::PiecewiseJerkVariance(positive(
                "motion.jerk_variance",
                v,
            )?)),
            MotionConfig::ConstantAcceleration { .. } => {
                Err("motion needs exactly one of jerk_psd or jerk_variance".into())
            }
            _ => Err("only the constant-acceleration model takes jerk noise".into()),
        }
    }

    /// Every sensor's calibration states, in state order after the motion states, with the
    /// index of the sensor that owns each.
    pub fn sensor_states(&self) -> Vec<(usize, SensorState)> {
        self.sensor
            .iter()
            .enumerate()
            .flat_map(|(i, s)| s.sensor_states().map(move |st| (i, st)))
            .collect()
    }

    /// Motion states plus sensor states.
    pub fn dimension(&self) -> usize {
        self.motion.dimension() + self.sensor_states().len()
    }

    /// The federated devices (sub-filters) in order of first mention, without the master.
    pub fn devices(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for s in &self.sensor {
            let d = s.device_name();
            if d != MASTER_DEVICE && !names.iter().any(|n| n == d) {
                names.push(d.to_owned());
            }
        }
        names
    }

    /// β by speed band, in device order, from the config or the default for its devices.
    pub fn sharing_table(&self) -> Result<SharingTable, String> {
        let devices = self.devices();
        let bands = self
            .federated
            .as_ref()
            .map(|f| f.band.as_slice())
            .unwrap_or_default();
        if bands.is_empty() {
            let names: Vec<&str> = devices.iter().map(String::as_str).collect();
            return Ok(match names.as_slice() {
                ["ins", "gnss", "radar"] => SharingTable::source_001(),
                ["loop", "radar"] => SharingTable::source_000(),
                _ => SharingTable::even(devices.len()),
            });
        }
        let mut out = Vec::new();
        let mut last_below = 0.0;
        for (i, b) in bands.iter().enumerate() {
            let label = match b.below_kmh {
                Some(v) => format!("federated.band below {v} km/h"),
                None => "the last federated.band".to_owned(),
            };
            let below = match (b.below_kmh, i + 1 == bands.len()) {
                (Some(v), false) if v.is_finite() && v > last_below => v,
                (None, true) => f64::INFINITY,
                (Some(_), true) => return Err(format!("{label}: the last band covers every higher speed, so it takes no below_kmh")),
                (None, false) => return Err(format!("federated.band {}: only the last band may leave out below_kmh", i + 1)),
                (Some(v), false) => return Err(format!("{label}: below_kmh must increase from band to band, not {v} after {last_below}")),
            };
            last_below = below;
            for name in b.beta.keys() {
                if !devices.contains(name) {
                    return Err(format!(
                        "{label}: β for '{name}', which is not a device (devices: {})",
                        devices.join(", ")
                    ));
                }
            }
            let mut beta = Vec::new();
            for d in &devices {
                let v = *b
                    .beta
                    .get(d)
                    .ok_or_else(|| format!("{label}: no β for device '{d}'"))?;
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("{label}: β for '{d}' must be ≥ 0, not {v}"));
                }
                beta.push(v);
            }
            let sum: f64 = beta.iter().sum();
            if (sum - 1.0).abs() > 1e-6 {
                return Err(format!(
                    "{label}: β sums to {}, not 1 (information sharing needs Σβ = 1)",
                    (sum * 1e6).round() / 1e6
                ));
            }
            out.push(SpeedBand {
                below_mps: below / 3.6,
                beta,
            });
        }
        Ok(SharingTable { bands: out })
    }

    /// This pipeline alone, as TOML: what is stored beside its fused channels.
    pub fn to_toml(&self) -> String {
        toml::to_string(&PipelinesConfig {
            pipeline: vec![self.clone()],
        })
        .expect("a config serialises")
    }
}

fn line_column(text: &str, offset: usize) -> (usize, usize) {
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

    const GOOD: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
motion = { model = "constant_acceleration", jerk_psd = 0.05 }

[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"

[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.01
gate_nis = 16.0
"#;

    fn err(text: &str) -> String {
        PipelinesConfig::parse(text, Path::new("p.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_good_config_parses_and_round_trips() {
        let c = PipelinesConfig::parse(GOOD, Path::new("p.toml")).unwrap();
        assert_eq!(
            c.pipeline[0].sensor[0].variance,
            Variance::FromMessage(FromMessage::Message)
        );
        assert_eq!(c.pipeline[0].sensor[1].variance, Variance::Fixed(0.01));
        let again = PipelinesConfig::parse(&c.pipeline[0].to_toml(), Path::new("x")).unwrap();
        assert_eq!(again.pipeline[0], c.pipeline[0]);
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line_and_column() {
        let e = err(&GOOD.replace("gate_nis = 16.0", "gate_nsi = 16.0"));
        assert!(
            e.starts_with("p.toml: line 14, column 1: unknown field `gate_nsi`"),
            "{e}"
        );
    }

    #[test]
    fn a_wrong_type_is_named_with_its_line() {
        let e = err(&GOOD.replace("variance = 0.01", "variance = [1]"));
        assert!(
            e.contains("line 13, column 12") && e.contains("a variance"),
            "{e}"
        );
    }

    #[test]
    fn invalid_values_are_refused_with_the_pipeline_name() {
        assert!(err(&GOOD.replace("variance = 0.01", "variance = -1.0"))
            .contains("pipeline 'kf': sensor /radar/speed: variance must be positive"));
        assert!(
            err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = 0.05, jerk_variance = 1.0"))
                .contains("exactly one")
        );
        assert!(
            err(&GOOD.replace("filter = \"kalman\"", "filter = \"magic\""))
                .contains("unknown variant `magic`")
        );
        assert!(err(&GOOD.replace("name = \"kf\"", "name = \"a/b\"")).contains("letters, digits"));
    }

    const FEDERATED: &str = r#"
[[pipeline]]
name = "fkf"
filter = "federated_kalman"
motion = { model = "singer", time_constant_s = 20.0, acceleration_std_mps2 = 0.3 }

[pipeline.federated]
feedback = "fusion_reset"
fusion_period_s = 1.0

[[pipeline.federated.band]]
below_kmh = 50.0
beta = { ins = 0.6, gnss = 0.3, radar = 0.1 }

[[pipeline.federated.band]]
beta = { ins = 0.4, gnss = 0.4, radar = 0.2 }

[[pipeline.sensor]]
topic = "/imu"
device = "ins"
fields = ["acceleration"]
variance = 0.001

[[pipeline.sensor]]
topic = "/gnss/fix"
device = "gnss"
variance = { chainage = "message", speed = 0.01 }

[[pipeline.sensor]]
topic = "/radar/speed"
device = "radar"
variance = "message"
"#;

    #[test]
    fn federated_bands_parse_into_the_device_order() {
        let c = PipelinesConfig::parse(FEDERATED, Path::new("f.toml")).unwrap();
        let t = c.pipeline[0].sharing_table().unwrap();
        assert_eq!(t.at(10.0), &[0.6, 0.3, 0.1]);
        assert_eq!(t.at(100.0), &[0.4, 0.4, 0.2]);
        assert_eq!(c.pipeline[0].devices(), vec!["ins", "gnss", "radar"]);
    }

    #[test]
    fn bad_federated_and_particle_configs_say_what_is_wrong() {
        let e = PipelinesConfig::parse(
            &FEDERATED.replace("gnss = 0.3, radar = 0.1", "gnss = 0.3, radar = 0.2"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("pipeline 'fkf': federated.band below 50 km/h: β sums to 1.1, not 1"),
            "{e}"
        );
        let e = PipelinesConfig::parse(
            &FEDERATED.replace("ins = 0.4, gnss", "odo = 0.4, gnss"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("β for 'odo', which is not a device"), "{e}");
        let e = PipelinesConfig::parse(
            &FEDERATED.replace("federated_kalman", "federated_kalmann"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 4") && e.contains("unknown variant `federated_kalmann`"),
            "{e}"
        );
        let particle = GOOD.replace(
            "filter = \"kalman\"",
            "filter = \"particle\"\nparticle = { particles = 0 }",
        );
        assert!(err(&particle).contains("particle.particles must be at least 1"));
        assert!(err(&GOOD.replace("variance = 0.01", "variance = -0.01"))
            .contains("variance must be positive, not -0.01"));
        assert!(err(&GOOD.replace(
            "filter = \"kalman\"",
            "filter = \"kalman\"\nsmoother = true\noutput_rate_hz = 0.0"
        ))
        .contains("output_rate_hz must be positive"));
        let e = err(&GOOD.replace(
            "filter = \"kalman\"",
            "filter = \"particle\"\nsmoother = true",
        ));
        assert!(
            e.contains("smoother = true needs filter = \"kalman\""),
            "{e}"
        );
        let e = err(&GOOD.replace("jerk_psd = 0.05", "acceleration_psd = 0.05"));
        assert!(e.contains("unknown field `acceleration_psd`"), "{e}");
        let e = PipelinesConfig::parse(
            &FEDERATED.replace(
                "filter = \"federated_kalman\"",
                "filter = \"federated_kalman\"\ngate_lockout = 5",
            ),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("gate_lockout is for kalman and particle pipelines"),
            "{e}"
        );
    }

    #[test]
    fn sensor_states_parse_count_and_refuse_bad_values() {
        let with = |loop_extra: &str, radar_extra: &str| {
            GOOD.replace(
                "variance = \"message\"\n",
                &format!("variance = \"message\"\n{loop_extra}\n"),
            )
            .replace(
                "gate_nis = 16.0\n",
                &format!("gate_nis = 16.0\n{radar_extra}\n"),
            )
        };
        let good = with(
            "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }",
            "scale_factor = { std = 0.01 }",
        );
        let c = PipelinesConfig::parse(&good, Path::new("p.toml")).unwrap();
        assert_eq!(c.pipeline[0].dimension(), 5);
        let kinds: Vec<_> = c.pipeline[0]
            .sensor_states()
            .iter()
            .map(|(i, s)| (*i, s.kind()))
            .collect();
        assert_eq!(kinds, [(0, "chainage_bias"), (1, "scale_factor")]);
        assert!(err(&with(
            "chainage_bias = { std_m = -2.0, time_constant_s = 60.0 }",
            ""
        ))
        .contains("chainage_bias.std_m must be positive"));
        assert!(err(&with(
            "",
            "scale_factor = { std = 0.01, walk_per_s = -1.0 }"
        ))
        .contains("walk_per_s must be ≥ 0"));
        assert!(err(&with(
            "",
            "fields = [\"speed\"]\nchainage_bias = { std_m = 2.0, time_constant_s = 60.0 }"
        ))
        .contains("chainage is not among its fields"));
        let e = err(&with(
            "",
            "fields = [\"speed\"]\nacceleration_bias = { std_mps2 = 0.01, time_constant_s = 60.0 }",
        ));
        assert!(e.contains("acceleration_bias, but no acceleration"), "{e}");
        let e = err(&with(
            "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }\nscale_factor = { std = 0.01 }",
            "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }\nscale_factor = { std = 0.01 }",
        ));
        assert!(
            e.contains("3 motion states and 4 sensor states: at most 6"),
            "{e}"
        );
    }
}
