//! The pipeline kinds that read whole messages, registered by name.
//!
//! `filter = "<name>"` picks a kind and `[pipeline.<section>]` holds its settings. The four
//! estimators along the track (`kalman`, `particle` and their federated forms) are built into
//! the spec; every other kind brings its own folder (its settings, its checks of the pipeline
//! table, its pipeline) and one line in [`Registry::standard`](crate::registry::Registry).
//!
//! Below the kinds, the registry, the spec and the replay, above the shared types: a kind
//! depends on this module, [`config`](crate::config), [`base`](crate::base) and
//! [`fused`](crate::fused) only.

use std::fmt::Debug;
use std::path::Path;
use std::sync::Arc;

use railfuse_catalog::log::LogMessage;

use crate::base::PipelineBase;
use crate::config::{MotionConfig, PipelineConfig, SensorConfig};
use crate::error::Result;
use crate::fused::{Fused, PipelineCounts};
use crate::measurement::{SensorContext, SensorModel};
use crate::model::{ConstantAcceleration, MotionModel};
use crate::noise::VarianceValue;

/// A pipeline that reads whole messages rather than scalar measurements (source 002's
/// `ekf_safety`, source 003's `gnss_ins`, source 004's `eddy_current`).
pub trait MessagePipeline {
    fn counts(&self) -> &PipelineCounts;
    /// Sensor `sensor` is bound to its channel with this variance setting.
    fn bind(&mut self, sensor: usize, variance: Option<VarianceValue>);
    /// One message of sensor `sensor`; an error only for a message that does not decode.
    fn push(
        &mut self,
        sensor: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
        out: &mut Vec<Fused>,
    ) -> Result<()>;
    /// The end of the log: everything still queued.
    fn finish(&mut self, log_time_ns: u64, context: &SensorContext, out: &mut Vec<Fused>);
    /// One line for the run's report beyond the counts (a GNSS gate's decisions), if any.
    fn report(&self) -> Option<String> {
        None
    }
}

/// Output channels a kind writes beside every pipeline's state and diagnostics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Outputs {
    /// `/fused/<name>/safety`: the safe interval and the checks.
    pub safety: bool,
    /// `/fused/<name>/imu_error_model`: the learnt IMU error model.
    pub imu_error_model: bool,
}

/// One kind of pipeline: its name, its settings table and how a pipeline table becomes one.
pub trait PipelineKind: Send + Sync {
    /// `filter = "<name>"`.
    fn name(&self) -> &'static str;
    /// Its settings table, `[pipeline.<section>]`.
    fn section(&self) -> &'static str;
    /// The pipeline table checked: `settings` is the section as written (`None`: absent, the
    /// defaults). The error says what is wrong; the caller adds the file, line and pipeline.
    fn spec(
        &self,
        pipeline: &PipelineConfig,
        settings: Option<toml::Value>,
    ) -> Result<Arc<dyn KindSpec>, String>;
    /// The JSON schema of its settings table, for the configuration reference (by default:
    /// any table).
    fn settings_schema(&self, _g: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({ "type": "object" })
    }
}

/// A kind whose `[pipeline.<section>]` table is one serde type (each of railfuse's):
/// [`PipelineKind`] follows from its name, its section and its checks of the table read.
pub trait TypedKind: Send + Sync {
    /// `filter = "<NAME>"`.
    const NAME: &'static str;
    /// `[pipeline.<SECTION>]`.
    const SECTION: &'static str;
    type Settings: serde::de::DeserializeOwned + schemars::JsonSchema + Default;
    /// The pipeline table checked, its settings read (the defaults where it has none).
    fn spec(c: &PipelineConfig, settings: Self::Settings) -> Result<Arc<dyn KindSpec>, String>;
}

impl<K: TypedKind> PipelineKind for K {
    fn name(&self) -> &'static str {
        K::NAME
    }
    fn section(&self) -> &'static str {
        K::SECTION
    }
    fn settings_schema(&self, g: &mut schemars::SchemaGenerator) -> schemars::Schema {
        g.subschema_for::<K::Settings>()
    }
    fn spec(
        &self,
        c: &PipelineConfig,
        settings: Option<toml::Value>,
    ) -> Result<Arc<dyn KindSpec>, String> {
        K::spec(c, settings_of(K::SECTION, settings)?)
    }
}

/// A kind's validated settings: what its pipeline is built from.
pub trait KindSpec: Debug + Send + Sync {
    /// The kind's name (`filter = "…"`).
    fn name(&self) -> &'static str;
    /// The settings in full, defaults written out: stored beside the fused channels.
    fn settings(&self) -> toml::Value;
    fn build(&self, base: PipelineBase) -> Result<Box<dyn MessagePipeline>>;
    fn outputs(&self) -> Outputs {
        Outputs::default()
    }
    /// Reads raw eddy-current blocks (which no other pipeline can use).
    fn reads_raw_blocks(&self) -> bool {
        false
    }
    /// Whether sensor `sensor` may be a channel of this model; why not, if it may not.
    fn accepts(&self, _sensor: usize, _model: SensorModel) -> Result<(), String> {
        Ok(())
    }
}

/// A kind's settings table read into its type (`None`: the defaults).
pub fn settings_of<T: serde::de::DeserializeOwned + Default>(
    section: &str,
    value: Option<toml::Value>,
) -> Result<T, String> {
    match value {
        None => Ok(T::default()),
        Some(v) => v.try_into().map_err(|e: toml::de::Error| {
            format!("[pipeline.{section}]: {}", e.message().trim_end())
        }),
    }
}

/// Settings as a TOML value, for [`KindSpec::settings`].
pub fn settings_value<T: serde::Serialize>(settings: &T) -> toml::Value {
    toml::Value::try_from(settings).expect("settings serialise to TOML")
}

/// The sensor on `topic`, by its place among the pipeline's sensors (`role` names the
/// setting that named it).
pub fn sensor_of(c: &PipelineConfig, role: &str, topic: &str) -> Result<usize, String> {
    c.sensor
        .iter()
        .position(|s| s.get_ref().topic == topic)
        .ok_or_else(|| format!("{role} is {topic}, which is not one of the pipeline's sensors"))
}

/// Refuses a sensor with a setting only pipelines along the track read.
pub fn whole_message_sensors(c: &PipelineConfig) -> Result<(), String> {
    c.sensor
        .iter()
        .try_for_each(|s| whole_message_sensor(c.filter.get_ref(), s.get_ref()))
}

/// Refuses one sensor of a `filter` pipeline with a setting only pipelines along the track
/// read.
pub fn whole_message_sensor(filter: &str, s: &SensorConfig) -> Result<(), String> {
    match s.chainage_bias.is_some()
        || s.adaptive_variance.is_some()
        || s.acceleration_bias.is_some()
        || s.scale_factor.is_some()
        || s.speed_window_s.is_some()
        || s.fields.is_some()
    {
        true => Err(format!(
            "sensor {}: an {filter} pipeline's sensors take a topic, a variance and a gate \
             only (no fields, sensor states, adaptive variance or speed window)",
            s.topic
        )),
        false => Ok(()),
    }
}

/// The pipeline's motion model, which must be constant acceleration (`why`: what runs it).
pub fn constant_acceleration(c: &MotionConfig, why: &str) -> Result<ConstantAcceleration, String> {
    match c.model()? {
        MotionModel::ConstantAcceleration(m) => Ok(m),
        _ => Err(format!(
            "{why}: set motion = {{ model = \"constant_acceleration\", jerk_psd = … }}"
        )),
    }
}
