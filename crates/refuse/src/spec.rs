//! Pipelines as the replay runs them: the configuration file ([`crate::config`]) parsed once
//! into validated types. A [`PipelineSpec`] holds the estimator and its settings, the motion
//! model with its process noise chosen, where the filter starts, and each sensor's device,
//! fields, variances and calibration states; nothing downstream checks a value again. Every
//! error names the file, the line of the table it is about, and the pipeline.
//!
//! A sensor meets the log's channel in [`PipelineSpec::bind`], once per channel: the channel's
//! schema picks the sensor model, and the fields the sensor asks for must be ones that model
//! gives and the motion model holds.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use toml::Spanned;

pub use crate::base::{InitialSpec, PipelineBase};
use crate::config::{
    line_column, positive, FederatedConfig, FilterKind, InitialConfig, PipelineConfig,
    PipelinesFile, SensorConfig, Variance, VarianceValue,
};
use crate::error::{Error, Result};
use crate::filter::federated::FederatedSettings;
use crate::filter::particle::ParticleSettings;
use crate::filter::sharing::{SharingTable, SpeedBand};
use crate::filter::MASTER;
use crate::kinds::{KindSpec, Outputs, PipelineKind};
use crate::measurement::{Quantity, SensorModel};
use crate::model::{MotionModel, SensorState};
use crate::registry::Registry;

/// The most state components a pipeline may have (motion and sensor states together).
pub const MAX_STATES: usize = 8;

/// The device name reserved for the master filter of a federated pipeline.
pub const MASTER_DEVICE: &str = "master";

/// Gate rejections in a row of one quantity after which a centralised filter takes itself to
/// be locked out.
pub const DEFAULT_GATE_LOCKOUT: u32 = 5;

/// Spread of a start chainage given without one, m: distance from where the log starts is
/// exact.
pub const DEFAULT_CHAINAGE_STD_M: f64 = 0.01;

/// Every pipeline of one configuration file.
#[derive(Debug, Clone)]
pub struct Pipelines {
    /// Where the configuration came from, for messages.
    pub path: PathBuf,
    /// The track map the configuration names (`track = "line.geojson"`), read and checked.
    pub track: Option<railfuse_catalog::messages::TrackMap>,
    pub pipeline: Vec<PipelineSpec>,
}

impl Pipelines {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self> {
        let (file, text) = PipelinesFile::load(path)?;
        Self::from_file(file, &text, path, &Registry::standard())
    }

    /// Parses and validates configuration text; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        Self::parse_with(text, path, &Registry::standard())
    }

    /// [`parse`](Self::parse) with the pipeline kinds of `registry`.
    pub fn parse_with(text: &str, path: &Path, registry: &Registry) -> Result<Self> {
        Self::from_file(PipelinesFile::parse(text, path)?, text, path, registry)
    }

    fn from_file(
        file: PipelinesFile,
        text: &str,
        path: &Path,
        registry: &Registry,
    ) -> Result<Self> {
        if file.pipeline.is_empty() {
            return Err(Error::ConfigSyntax {
                path: path.to_owned(),
                message: "no [[pipeline]] declared".into(),
            });
        }
        let mut pipeline: Vec<PipelineSpec> = Vec::new();
        for p in file.pipeline {
            let place = |span: Range<usize>| {
                let (line, column) = line_column(text, span.start);
                Place {
                    path: path.to_owned(),
                    line,
                    column,
                }
            };
            let invalid = |span: Range<usize>, message: String| {
                let at = place(span);
                Error::ConfigInvalid {
                    path: at.path,
                    line: at.line,
                    column: at.column,
                    pipeline: p.get_ref().name.clone(),
                    message,
                }
            };
            if pipeline.iter().any(|q| q.name == p.get_ref().name) {
                return Err(invalid(p.span(), "declared twice".into()));
            }
            let spec = PipelineSpec::new(&p, &place, registry)
                .map_err(|Invalid { span, message }| invalid(span, message))?;
            pipeline.push(spec);
        }
        // The track file is relative to the configuration.
        let track = match &file.track {
            Some(t) => {
                let at = path.parent().unwrap_or(Path::new("")).join(t);
                let map = railfuse_catalog::track_geojson::read_track_file(&at).map_err(|e| {
                    Error::ConfigSyntax {
                        path: path.to_owned(),
                        message: format!("track: {e}"),
                    }
                })?;
                Some(map)
            }
            None => None,
        };
        Ok(Self {
            path: path.to_owned(),
            track,
            pipeline,
        })
    }

    /// The names of the pipelines, in file order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.pipeline.iter().map(|p| p.name.as_str())
    }
}

/// Where in a configuration file something is declared.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    pub path: PathBuf,
    pub line: usize,
    pub column: usize,
}

impl std::fmt::Display for Place {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} line {}", self.path.display(), self.line)
    }
}

/// A validation failure and the span of the table it is about.
struct Invalid {
    span: Range<usize>,
    message: String,
}

/// The estimator of a pipeline, with its settings.
#[derive(Debug, Clone)]
pub enum EstimatorSpec {
    Kalman {
        gate_lockout: u32,
        /// Also write the fixed-interval RTS smoothed states.
        smoother: bool,
    },
    Particle {
        particle: ParticleSettings,
        gate_lockout: u32,
    },
    FederatedKalman {
        federated: FederatedSettings,
    },
    FederatedParticle {
        federated: FederatedSettings,
        particle: ParticleSettings,
    },
    /// A registered kind that reads whole messages ([`crate::kinds`]).
    Messages(Arc<dyn KindSpec>),
}

impl EstimatorSpec {
    /// `filter = "…"`.
    pub fn name(&self) -> &'static str {
        match self {
            EstimatorSpec::Messages(k) => k.name(),
            e => e
                .filter_kind()
                .expect("an estimator along the track")
                .name(),
        }
    }

    /// The estimator along the track, `None` for a kind that reads whole messages.
    pub fn filter_kind(&self) -> Option<FilterKind> {
        Some(match self {
            EstimatorSpec::Kalman { .. } => FilterKind::Kalman,
            EstimatorSpec::Particle { .. } => FilterKind::Particle,
            EstimatorSpec::FederatedKalman { .. } => FilterKind::FederatedKalman,
            EstimatorSpec::FederatedParticle { .. } => FilterKind::FederatedParticle,
            EstimatorSpec::Messages(_) => return None,
        })
    }

    /// The pipeline reads whole messages (in the plane), not scalar measurements.
    pub fn reads_whole_messages(&self) -> bool {
        matches!(self, EstimatorSpec::Messages(_))
    }

    /// Output channels beside the state and diagnostics.
    pub fn outputs(&self) -> Outputs {
        match self {
            EstimatorSpec::Messages(k) => k.outputs(),
            _ => Outputs::default(),
        }
    }

    pub fn smoother(&self) -> bool {
        matches!(self, EstimatorSpec::Kalman { smoother: true, .. })
    }
}

/// One sensor of a pipeline: a channel and what to take from it.
#[derive(Debug, Clone)]
pub struct SensorSpec {
    pub topic: String,
    /// What the sensor is, for a foreign channel whose schema cannot say (config `role`).
    pub role: Option<railfuse_catalog::foreign::Role>,
    /// Federated pipelines: the device index ([`MASTER`] for the master filter) and name.
    /// Centralised pipelines: 0 and no name.
    pub device: usize,
    pub device_name: Option<String>,
    /// The quantities asked for; `None`: all its sensor model gives.
    pub fields: Option<Vec<Quantity>>,
    pub variance: Variance,
    pub gate_nis: Option<f64>,
    /// Its calibration states, in state order.
    pub states: Vec<SensorState>,
    /// The window its speed is the mean over, s (config `speed_window_s`).
    pub speed_window_s: Option<f64>,
    /// A log without its channel is an error (config `required`), not a warning.
    pub required: bool,
    /// Where its table is.
    pub declared: Place,
}

/// A sensor bound to its channel: the sensor model that reads the channel, and each field
/// used with its variance setting.
#[derive(Debug, Clone)]
pub struct SensorBinding {
    pub model: SensorModel,
    pub fields: Vec<(Quantity, VarianceValue)>,
}

/// One pipeline, validated.
#[derive(Debug, Clone)]
pub struct PipelineSpec {
    /// Names the output channels `/fused/<name>/…`: letters, digits, `_` and `-`.
    pub name: String,
    pub estimator: EstimatorSpec,
    pub motion: MotionModel,
    pub initial: InitialSpec,
    /// Measurements are released in sensor-time order once the replay is this far past them.
    pub reorder_window_ns: u64,
    /// Fused states on a regular grid of this period instead of one per accepted measurement.
    pub output_period_ns: Option<u64>,
    pub sensors: Vec<SensorSpec>,
    /// Federated pipelines: the devices (sub-filters) in order of first mention, without the
    /// master. Empty for centralised pipelines.
    pub devices: Vec<String>,
    /// The table as written, stored beside the fused channels.
    source: PipelineConfig,
}

fn at_least_zero(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be ≥ 0, not {v}"))
    }
}

impl PipelineSpec {
    /// What a pipeline that reads whole messages is given of its spec.
    pub fn base(&self) -> PipelineBase {
        PipelineBase {
            name: self.name.clone(),
            topics: self.sensors.iter().map(|s| s.topic.clone()).collect(),
            gates: self.sensors.iter().map(|s| s.gate_nis).collect(),
            reorder_window_ns: self.reorder_window_ns,
            initial: self.initial,
        }
    }

    fn new(
        table: &Spanned<PipelineConfig>,
        place: &dyn Fn(Range<usize>) -> Place,
        registry: &Registry,
    ) -> Result<Self, Invalid> {
        let c = table.get_ref();
        let here = |message: String| Invalid {
            span: table.span(),
            message,
        };
        if c.name.is_empty()
            || !c
                .name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-')
        {
            return Err(here(
                "the name may hold only letters, digits, '_' and '-'".into(),
            ));
        }
        let (filter, kind) = filter_and_kind(c, registry)?;
        let motion = c.motion.model().map_err(here)?;
        let reorder_window_s =
            at_least_zero("reorder_window_s", c.reorder_window_s).map_err(here)?;
        let output_period_ns = c
            .output_rate_hz
            .map(|r| positive("output_rate_hz", r).map(|r| (1e9 / r).round().max(1.0) as u64))
            .transpose()
            .map_err(here)?;
        let initial = initial(&c.initial).map_err(here)?;
        if c.sensor.is_empty() {
            return Err(here("no [[pipeline.sensor]]: nothing to fuse".into()));
        }
        let devices = match filter.is_some_and(FilterKind::is_federated) {
            true => devices(&c.sensor),
            false => Vec::new(),
        };
        let sensors = c
            .sensor
            .iter()
            .map(|s| {
                sensor(
                    s.get_ref(),
                    filter,
                    motion.dimension(),
                    &devices,
                    place(s.span()),
                )
                .map_err(|message| Invalid {
                    span: s.span(),
                    message: format!("sensor {}: {message}", s.get_ref().topic),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let states: usize = sensors.iter().map(|s| s.states.len()).sum();
        if motion.dimension() + states > MAX_STATES {
            return Err(here(format!(
                "{} motion states and {states} sensor states: at most {MAX_STATES} state \
                 components in all",
                motion.dimension()
            )));
        }
        let estimator = estimator(c, filter, kind, &devices).map_err(here)?;
        // Stored beside the fused channels with every setting written out.
        let mut source = c.clone();
        if let (EstimatorSpec::Messages(k), Some(kind)) = (&estimator, kind) {
            if let Some(t) = source.sections.get_mut(kind.section()) {
                *t = Spanned::new(t.span(), k.settings());
            }
        }
        Ok(Self {
            name: c.name.clone(),
            estimator,
            motion,
            initial,
            reorder_window_ns: (reorder_window_s * 1e9) as u64,
            output_period_ns,
            sensors,
            devices,
            source,
        })
    }

    /// Motion states plus sensor states.
    pub fn dimension(&self) -> usize {
        self.motion.dimension() + self.sensors.iter().map(|s| s.states.len()).sum::<usize>()
    }

    /// Every sensor's calibration states, in state order after the motion states, with the
    /// index of the sensor that owns each.
    pub fn sensor_states(&self) -> Vec<(usize, SensorState)> {
        self.sensors
            .iter()
            .enumerate()
            .flat_map(|(i, s)| s.states.iter().map(move |st| (i, *st)))
            .collect()
    }

    /// Index of the sensor reading `topic`.
    pub fn sensor_for(&self, topic: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s.topic == topic)
    }

    /// This pipeline as TOML, as it was written (under its current name).
    pub fn to_toml(&self) -> String {
        self.source.to_toml()
    }

    /// The same pipeline without its RTS smoother (tuning scores the filter's own states).
    pub fn without_smoother(&self) -> Self {
        let mut p = self.clone();
        if let EstimatorSpec::Kalman { smoother, .. } = &mut p.estimator {
            *smoother = false;
        }
        p
    }

    /// Its `[pipeline.tune]` table, if it has one.
    pub fn tune(&self) -> Option<&crate::config::TuneConfig> {
        self.source.tune.as_ref()
    }

    /// The same pipeline under another name (benchmarks, side-by-side runs).
    pub fn renamed(&self, name: &str) -> Self {
        let mut p = self.clone();
        p.name = name.to_owned();
        p.source.name = name.to_owned();
        p
    }

    /// Binds sensor `sensor` to a channel of `schema` in log `input`: its sensor model and
    /// the fields it uses with their variances.
    pub fn bind(&self, input: &Path, sensor: usize, schema: &str) -> Result<SensorBinding> {
        let s = &self.sensors[sensor];
        let fail = |problem: String| self.channel_error(input, sensor, problem);
        let Some(model) = SensorModel::for_schema(schema) else {
            let supported: Vec<&str> = SensorModel::SUPPORTED
                .iter()
                .map(|k| k.schema_name())
                .collect();
            return Err(fail(format!(
                "has schema '{schema}', which no sensor model reads (supported: {}; and, \
                 read as those, {})",
                supported.join(", "),
                railfuse_catalog::foreign::Translator::schemas().join(", ")
            )));
        };
        let eddy = matches!(&self.estimator, EstimatorSpec::Messages(k) if k.reads_raw_blocks());
        if eddy != (model == SensorModel::EddyCurrent) {
            return Err(fail(match eddy {
                true => format!(
                    "has schema '{schema}'; an eddy_current pipeline reads {}",
                    railfuse_catalog::messages::MessageKind::EddyCurrentBlock.schema_name()
                ),
                false => "carries raw eddy-current blocks, which only an eddy_current \
                          pipeline reads"
                    .into(),
            }));
        }
        let gives: Vec<&str> = model.quantities().iter().map(|q| q.name()).collect();
        let wanted = s.fields.as_deref().unwrap_or(model.quantities());
        let mut fields = Vec::new();
        for q in wanted {
            if !model.quantities().contains(q) {
                return Err(fail(format!(
                    "gives {} but not {}",
                    gives.join(" and "),
                    q.name()
                )));
            }
            if q.index() >= self.motion.dimension() {
                return Err(fail(format!(
                    "gives {}, which the {}-state motion model does not hold: set fields",
                    q.name(),
                    self.motion.dimension()
                )));
            }
            let Some(variance) = s.variance.of(*q) else {
                return Err(fail(format!(
                    "gives {}, and the sensor's variance table has no entry for it",
                    q.name()
                )));
            };
            fields.push((*q, variance));
        }
        for state in &s.states {
            let q = state.quantity();
            if !wanted.contains(&q) {
                return Err(fail(format!(
                    "has a {} state but gives no {} to observe it",
                    state.kind(),
                    q.name()
                )));
            }
        }
        Ok(SensorBinding { model, fields })
    }

    /// An error about sensor `sensor`'s channel in log `input`.
    /// A sensor whose channel the log `input` lacks (`have`: the channels it has): an error
    /// if the configuration marks it required, else the warning to give, the pipeline
    /// running on its other sensors.
    pub fn missing_channel(&self, input: &Path, sensor: usize, have: &[&str]) -> Result<String> {
        let problem = match have.is_empty() {
            true => "is not in the file".to_owned(),
            false => format!("is not in the file (it has {})", have.join(", ")),
        };
        if self.sensors[sensor].required {
            return Err(self.channel_error(input, sensor, problem));
        }
        let problem =
            format!("{problem}: it runs without it (required = true makes this an error)");
        Ok(self.channel_error(input, sensor, problem).to_string())
    }

    pub fn channel_error(&self, input: &Path, sensor: usize, problem: String) -> Error {
        let s = &self.sensors[sensor];
        Error::Channel {
            input: input.to_owned(),
            pipeline: self.name.clone(),
            topic: s.topic.clone(),
            declared: s.declared.to_string(),
            problem,
        }
    }
}

fn initial(i: &InitialConfig) -> Result<InitialSpec, String> {
    if !(i.speed_mps.is_finite() && i.acceleration_mps2.is_finite()) {
        return Err("initial speed_mps and acceleration_mps2 must be finite".into());
    }
    let chainage_std = positive(
        "initial.chainage_std_m",
        i.chainage_std_m.unwrap_or(DEFAULT_CHAINAGE_STD_M),
    )?;
    let chainage = match i.chainage_m {
        Some(c) if !c.is_finite() => {
            return Err(format!("initial.chainage_m must be finite, not {c}"))
        }
        c => c,
    };
    Ok(InitialSpec {
        chainage: chainage.map(|c| (c, chainage_std.powi(2))),
        distance_variance: chainage_std.powi(2),
        speed_mps: i.speed_mps,
        speed_variance: positive("initial.speed_std_mps", i.speed_std_mps)?.powi(2),
        acceleration_mps2: i.acceleration_mps2,
        acceleration_variance: positive("initial.acceleration_std_mps2", i.acceleration_std_mps2)?
            .powi(2),
    })
}

/// The federated devices (sub-filters) in order of first mention, without the master.
fn devices(sensors: &[Spanned<SensorConfig>]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for s in sensors {
        let d = s.get_ref().device_name();
        if d != MASTER_DEVICE && !names.iter().any(|n| n == d) {
            names.push(d.to_owned());
        }
    }
    names
}

/// What `filter` names: an estimator along the track, or a registered kind; and every
/// other key of the table a kind's settings table, the one of this pipeline's kind.
fn filter_and_kind<'r>(
    c: &PipelineConfig,
    registry: &'r Registry,
) -> Result<(Option<FilterKind>, Option<&'r dyn PipelineKind>), Invalid> {
    let name = c.filter.get_ref().as_str();
    let (filter, kind) = (FilterKind::parse(name), registry.get(name));
    if filter.is_none() && kind.is_none() {
        let known: Vec<String> = FilterKind::ALL
            .iter()
            .map(|k| k.name())
            .chain(registry.names())
            .map(|n| format!("`{n}`"))
            .collect();
        return Err(Invalid {
            span: c.filter.span(),
            message: format!(
                "filter: unknown kind `{name}`, expected one of {}",
                known.join(", ")
            ),
        });
    }
    for (key, table) in &c.sections {
        let Some(owner) = registry.by_section(key) else {
            let known: Vec<String> = PipelineConfig::FIELDS
                .iter()
                .copied()
                .chain(registry.sections())
                .map(|n| format!("`{n}`"))
                .collect();
            return Err(Invalid {
                span: table.span(),
                message: format!(
                    "unknown field `{key}`, expected one of {}",
                    known.join(", ")
                ),
            });
        };
        if owner.name() != name {
            let article = if key.starts_with(['a', 'e', 'i', 'o', 'u']) {
                "an"
            } else {
                "a"
            };
            return Err(Invalid {
                span: table.span(),
                message: format!("{article} [{key}] section, but filter = \"{name}\""),
            });
        }
    }
    Ok((filter, kind))
}

/// One sensor table, validated against its pipeline's filter and motion model.
fn sensor(
    s: &SensorConfig,
    filter: Option<FilterKind>,
    motion: usize,
    devices: &[String],
    declared: Place,
) -> Result<SensorSpec, String> {
    let values: Vec<VarianceValue> = match &s.variance {
        Variance::PerField(m) => m.values().copied().collect(),
        v => v.of(Quantity::Chainage).into_iter().collect(),
    };
    for v in values {
        if let VarianceValue::Fixed(v) = v {
            positive("variance", v)?;
        }
    }
    let gate_nis = s.gate_nis.map(|g| positive("gate_nis", g)).transpose()?;
    let measures = |q: Quantity| s.fields.as_ref().is_none_or(|f| f.contains(&q));
    if let Some(fields) = &s.fields {
        if fields.is_empty() {
            return Err("fields is empty".into());
        }
        if motion < 3 && fields.contains(&Quantity::Acceleration) {
            return Err("the constant-velocity model has no acceleration to measure".into());
        }
        if let Variance::PerField(m) = &s.variance {
            if let Some(q) = fields.iter().find(|q| !m.contains_key(q)) {
                return Err(format!("no variance for field {}", q.name()));
            }
        }
    }
    if s.device.is_some() && !filter.is_some_and(FilterKind::is_federated) {
        return Err("device is for federated filters only".into());
    }
    let mut states = Vec::new();
    if let Some(b) = s.chainage_bias {
        if !measures(Quantity::Chainage) {
            return Err("chainage_bias, but chainage is not among its fields".into());
        }
        states.push(SensorState::ChainageBias {
            std_m: positive("chainage_bias.std_m", b.std_m)?,
            time_constant_s: positive("chainage_bias.time_constant_s", b.time_constant_s)?,
        });
    }
    if let Some(b) = s.acceleration_bias {
        if motion < 3 || !measures(Quantity::Acceleration) {
            return Err("acceleration_bias, but no acceleration is measured".into());
        }
        states.push(SensorState::AccelerationBias {
            std_mps2: positive("acceleration_bias.std_mps2", b.std_mps2)?,
            time_constant_s: positive("acceleration_bias.time_constant_s", b.time_constant_s)?,
        });
    }
    if let Some(k) = s.scale_factor {
        let quantity = k.quantity.unwrap_or(Quantity::Speed);
        if quantity == Quantity::Acceleration {
            return Err("scale_factor.quantity must be speed or chainage".into());
        }
        if !measures(quantity) {
            return Err(format!(
                "scale_factor of {}, but {} is not among its fields",
                quantity.name(),
                quantity.name()
            ));
        }
        states.push(SensorState::ScaleFactor {
            quantity,
            std: positive("scale_factor.std", k.std)?,
            walk_per_s: at_least_zero("scale_factor.walk_per_s", k.walk_per_s)?,
        });
    }
    let speed_window_s = match s.speed_window_s {
        None => None,
        Some(_) if motion < 3 => {
            return Err("speed_window_s needs the acceleration of a 3-state motion model".into())
        }
        Some(_) if !measures(Quantity::Speed) => {
            return Err("speed_window_s, but speed is not among its fields".into())
        }
        Some(w) => Some(positive("speed_window_s", w)?),
    };
    let (device, device_name) = match filter.is_some_and(FilterKind::is_federated) {
        false => (0, None),
        true => match s.device_name() {
            MASTER_DEVICE => (MASTER, Some(MASTER_DEVICE.to_owned())),
            d => (
                devices.iter().position(|n| n == d).unwrap_or_default(),
                Some(d.to_owned()),
            ),
        },
    };
    Ok(SensorSpec {
        topic: s.topic.clone(),
        role: s.role,
        device,
        device_name,
        fields: s.fields.clone(),
        variance: s.variance.clone(),
        gate_nis,
        states,
        speed_window_s,
        required: s.required,
        declared,
    })
}

/// The estimator: one along the track with its settings, or the registered kind `kind` built
/// from its table.
fn estimator(
    c: &PipelineConfig,
    filter: Option<FilterKind>,
    kind: Option<&dyn PipelineKind>,
    devices: &[String],
) -> Result<EstimatorSpec, String> {
    let lockout = c.gate_lockout.unwrap_or(DEFAULT_GATE_LOCKOUT);
    let federated_filter = filter.is_some_and(FilterKind::is_federated);
    if c.gate_lockout.is_some() && federated_filter {
        return Err(
            "gate_lockout is for kalman and particle pipelines; a federated pipeline's \
                    devices have [federated] detector.gate_failures"
                .into(),
        );
    }
    if c.smoother && filter != Some(FilterKind::Kalman) {
        return Err(format!(
            "smoother = true needs filter = \"kalman\" (the RTS smoother is linear), not \"{}\"",
            c.filter.get_ref()
        ));
    }
    if c.particle.is_some() && !filter.is_some_and(FilterKind::is_particle) {
        return Err(format!(
            "a [particle] section, but filter = \"{}\"",
            c.filter.get_ref()
        ));
    }
    if c.federated.is_some() && !federated_filter {
        return Err(format!(
            "a [federated] section, but filter = \"{}\"",
            c.filter.get_ref()
        ));
    }
    let particle = || {
        let p = c.particle.unwrap_or_default();
        p.check().map(|()| p)
    };
    let federated = || federated(&c.federated.clone().unwrap_or_default(), devices);
    Ok(match (filter, kind) {
        (Some(FilterKind::Kalman), _) => EstimatorSpec::Kalman {
            gate_lockout: lockout,
            smoother: c.smoother,
        },
        (Some(FilterKind::Particle), _) => EstimatorSpec::Particle {
            particle: particle()?,
            gate_lockout: lockout,
        },
        (Some(FilterKind::FederatedKalman), _) => EstimatorSpec::FederatedKalman {
            federated: federated()?,
        },
        (Some(FilterKind::FederatedParticle), _) => EstimatorSpec::FederatedParticle {
            federated: federated()?,
            particle: particle()?,
        },
        (None, Some(kind)) => {
            let settings = c.sections.get(kind.section()).map(|t| t.get_ref().clone());
            EstimatorSpec::Messages(kind.spec(c, settings)?)
        }
        (None, None) => unreachable!("the filter was looked up in the registry"),
    })
}

fn federated(f: &FederatedConfig, devices: &[String]) -> Result<FederatedSettings, String> {
    let fusion_period_s = at_least_zero("federated.fusion_period_s", f.fusion_period_s)?;
    positive("federated.detector.timeout_s", f.detector.timeout_s)?;
    positive(
        "federated.detector.agreement_chi2",
        f.detector.agreement_chi2,
    )?;
    at_least_zero(
        "federated.detector.max_exclusion_s",
        f.detector.max_exclusion_s,
    )?;
    at_least_zero(
        "federated.detector.consistency_chi2",
        f.detector.consistency_chi2,
    )?;
    if devices.is_empty() {
        return Err("a federated filter needs at least one device besides the master".into());
    }
    Ok(FederatedSettings {
        feedback: f.feedback,
        fusion: f.fusion,
        fusion_period_ns: (fusion_period_s * 1e9).round() as u64,
        sharing: sharing_table(f, devices)?,
        redistribution: f.redistribution,
        detector: f.detector,
    })
}

/// β by speed band, in device order: the configured bands, or the named table (equal shares
/// when none is named).
fn sharing_table(f: &FederatedConfig, devices: &[String]) -> Result<SharingTable, String> {
    let bands = f.band.as_slice();
    if bands.is_empty() {
        let name = f.sharing.unwrap_or_default();
        return SharingTable::named(name, devices).map_err(|e| format!("federated.{e}"));
    }
    if let Some(name) = f.sharing {
        return Err(format!(
            "federated: sharing = \"{}\" and [[pipeline.federated.band]] tables: give one or \
             the other",
            name.key()
        ));
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
            (Some(_), true) => {
                return Err(format!(
                    "{label}: the last band covers every higher speed, so it takes no below_kmh"
                ))
            }
            (None, false) => {
                return Err(format!(
                    "federated.band {}: only the last band may leave out below_kmh",
                    i + 1
                ))
            }
            (Some(v), false) => {
                return Err(format!(
                    "{label}: below_kmh must increase from band to band, not {v} after \
                     {last_below}"
                ))
            }
        };
        last_below = below;
        if let Some(name) = b.beta.keys().find(|n| !devices.contains(n)) {
            return Err(format!(
                "{label}: β for '{name}', which is not a device (devices: {})",
                devices.join(", ")
            ));
        }
        let mut beta = Vec::new();
        for d in devices {
            let v = *b
                .beta
                .get(d)
                .ok_or_else(|| format!("{label}: no β for device '{d}'"))?;
            beta.push(at_least_zero(&format!("{label}: β for '{d}'"), v)?);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::FromMessage;

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
        Pipelines::parse(text, Path::new("p.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_good_config_parses_and_round_trips() {
        let c = Pipelines::parse(GOOD, Path::new("p.toml")).unwrap();
        assert_eq!(
            c.pipeline[0].sensors[0].variance,
            Variance::FromMessage(FromMessage::Message)
        );
        assert_eq!(c.pipeline[0].sensors[1].variance, Variance::Fixed(0.01));
        assert_eq!(c.pipeline[0].sensors[1].gate_nis, Some(16.0));
        let toml = c.pipeline[0].to_toml();
        let again = Pipelines::parse(&toml, Path::new("x")).unwrap();
        assert_eq!(again.pipeline[0].to_toml(), toml);
        assert_eq!(c.pipeline[0].sensors[1].declared.line, 11);
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
    fn invalid_values_are_refused_with_the_line_of_their_table_and_the_pipeline_name() {
        let e = err(&GOOD.replace("variance = 0.01", "variance = -1.0"));
        assert!(
            e.starts_with(
                "p.toml: line 11, column 1: pipeline 'kf': sensor /radar/speed: variance must be \
                 positive"
            ),
            "{e}"
        );
        let e = err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = -0.05"));
        assert!(
            e.starts_with(
                "p.toml: line 2, column 1: pipeline 'kf': motion.jerk_psd must be positive"
            ),
            "{e}"
        );
        assert!(
            err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = 0.05, jerk_variance = 1.0"))
                .contains("exactly one")
        );
        assert!(
            err(&GOOD.replace("filter = \"kalman\"", "filter = \"magic\""))
                .contains("unknown kind `magic`")
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
        let c = Pipelines::parse(FEDERATED, Path::new("f.toml")).unwrap();
        let EstimatorSpec::FederatedKalman { federated } = &c.pipeline[0].estimator else {
            panic!("a federated Kalman pipeline");
        };
        let t = &federated.sharing;
        assert_eq!(t.at(10.0), &[0.6, 0.3, 0.1]);
        assert_eq!(t.at(100.0), &[0.4, 0.4, 0.2]);
        assert_eq!(c.pipeline[0].devices, vec!["ins", "gnss", "radar"]);
        let devices: Vec<_> = c.pipeline[0].sensors.iter().map(|s| s.device).collect();
        assert_eq!(devices, [0, 1, 2]);
    }

    #[test]
    fn bad_federated_and_particle_configs_say_what_is_wrong() {
        let e = Pipelines::parse(
            &FEDERATED.replace("gnss = 0.3, radar = 0.1", "gnss = 0.3, radar = 0.2"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("pipeline 'fkf': federated.band below 50 km/h: β sums to 1.1, not 1"),
            "{e}"
        );
        let e = Pipelines::parse(
            &FEDERATED.replace("ins = 0.4, gnss", "odo = 0.4, gnss"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("β for 'odo', which is not a device"), "{e}");
        let e = Pipelines::parse(
            &FEDERATED.replace("federated_kalman", "federated_kalmann"),
            Path::new("f.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 4") && e.contains("unknown kind `federated_kalmann`"),
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
        let e = Pipelines::parse(
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
        let c = Pipelines::parse(&good, Path::new("p.toml")).unwrap();
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
        // A chainage scale for the loop; a speed window for a speed sensor only, on a model
        // with acceleration.
        let c = Pipelines::parse(
            &with(
                "scale_factor = { std = 1e-4, quantity = \"chainage\" }",
                "speed_window_s = 0.2",
            ),
            Path::new("p.toml"),
        )
        .unwrap();
        assert_eq!(
            c.pipeline[0].sensor_states()[0].1.quantity(),
            Quantity::Chainage
        );
        assert_eq!(c.pipeline[0].sensors[1].speed_window_s, Some(0.2));
        let e = err(&with(
            "scale_factor = { std = 1e-4, quantity = \"acceleration\" }",
            "",
        ));
        assert!(e.contains("must be speed or chainage"), "{e}");
        let e = err(&with("fields = [\"chainage\"]\nspeed_window_s = 0.2", ""));
        assert!(
            e.contains("speed_window_s, but speed is not among its fields"),
            "{e}"
        );
        let e = err(&with("", "speed_window_s = 0.2").replace(
            "model = \"constant_acceleration\", jerk_psd = 0.05",
            "model = \"constant_velocity\", acceleration_psd = 0.05",
        ));
        assert!(e.contains("needs the acceleration"), "{e}");
        let e = err(&with("", "speed_window_s = -0.2"));
        assert!(e.contains("speed_window_s must be positive"), "{e}");
        let e = err(&with(
            "",
            "fields = [\"speed\"]\nacceleration_bias = { std_mps2 = 0.01, time_constant_s = 60.0 }",
        ));
        assert!(e.contains("acceleration_bias, but no acceleration"), "{e}");
        // The loop's bias and scale, the radar's scale and three odometers' scales:
        // 3 + 2 + 1 + 3 = 9 states.
        let odometer = |n: u32| {
            format!(
                "\n[[pipeline.sensor]]\ntopic = \"/odometer/{n}\"\nvariance = 0.1\n\
                 scale_factor = {{ std = 0.01 }}\n"
            )
        };
        let e = err(&format!(
            "{}{}{}{}",
            with(
                "chainage_bias = { std_m = 2.0, time_constant_s = 60.0 }\nscale_factor = { std = 1e-4, quantity = \"chainage\" }",
                "scale_factor = { std = 0.01 }",
            ),
            odometer(1),
            odometer(2),
            odometer(3)
        ));
        assert!(
            e.contains("3 motion states and 6 sensor states: at most 8"),
            "{e}"
        );
    }

    #[test]
    fn a_sensor_binds_to_a_channel_whose_model_gives_its_fields_or_says_why_not() {
        use railfuse_catalog::messages::MessageKind;
        let input = Path::new("run.mcap");
        let c = Pipelines::parse(GOOD, Path::new("p.toml")).unwrap();
        let p = &c.pipeline[0];
        let b = p
            .bind(input, 1, MessageKind::RadarSpeed.schema_name())
            .unwrap();
        assert_eq!(b.fields, [(Quantity::Speed, VarianceValue::Fixed(0.01))]);
        let e = p
            .bind(input, 1, MessageKind::Event.schema_name())
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(
                "run.mcap: pipeline 'kf' reads channel /radar/speed (p.toml line 11), which has \
                 schema"
            ),
            "{e}"
        );
        let with = |extra: &str| {
            let text = GOOD.replace("gate_nis = 16.0", &format!("gate_nis = 16.0\n{extra}"));
            let c = Pipelines::parse(&text, Path::new("p.toml")).unwrap();
            c.pipeline[0]
                .bind(input, 1, MessageKind::RadarSpeed.schema_name())
                .unwrap_err()
                .to_string()
        };
        assert!(with("fields = [\"chainage\"]").ends_with("gives speed but not chainage"));
        let e = with("chainage_bias = { std_m = 1.0, time_constant_s = 10.0 }");
        assert!(
            e.ends_with("has a chainage_bias state but gives no chainage to observe it"),
            "{e}"
        );
        let text = GOOD.replace("variance = 0.01", "variance = { chainage = 0.01 }");
        let c = Pipelines::parse(&text, Path::new("p.toml")).unwrap();
        let e = c.pipeline[0]
            .bind(input, 1, MessageKind::RadarSpeed.schema_name())
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with("the sensor's variance table has no entry for it"),
            "{e}"
        );
    }

    /// FEDERATED without its band tables, with `sharing` set to `name` (or unset).
    fn federated_named(name: Option<&str>, devices: [&str; 3]) -> Result<Pipelines> {
        let start = FEDERATED.find("[[pipeline.federated.band]]").unwrap();
        let end = FEDERATED.find("[[pipeline.sensor]]").unwrap();
        let mut text = format!("{}{}", &FEDERATED[..start], &FEDERATED[end..]);
        if let Some(name) = name {
            text = text.replace(
                "fusion_period_s = 1.0",
                &format!("fusion_period_s = 1.0\nsharing = \"{name}\""),
            );
        }
        // Through numbered tokens, so that renaming one device cannot rename another.
        for (i, from) in ["ins", "gnss", "radar"].iter().enumerate() {
            text = text.replace(&format!("device = \"{from}\""), &format!("device = #{i}#"));
        }
        for (i, to) in devices.iter().enumerate() {
            text = text.replace(&format!("device = #{i}#"), &format!("device = \"{to}\""));
        }
        Pipelines::parse(&text, Path::new("f.toml"))
    }

    fn sharing(c: &Pipelines) -> &SharingTable {
        match &c.pipeline[0].estimator {
            EstimatorSpec::FederatedKalman { federated } => &federated.sharing,
            _ => panic!("a federated Kalman pipeline"),
        }
    }

    #[test]
    fn a_named_sharing_table_fits_the_device_names_or_is_refused_naming_them() {
        // Source 001's table, β mapped to the pipeline's device order by name.
        let c = federated_named(Some("source_001"), ["radar", "ins", "gnss"]).unwrap();
        assert_eq!(sharing(&c).at(10.0), &[0.1, 0.6, 0.3]);
        assert_eq!(sharing(&c).at(100.0), &[0.2, 0.4, 0.4]);
        // No table named: equal shares, whatever the devices are called.
        let c = federated_named(None, ["ins", "gnss", "radar"]).unwrap();
        assert_eq!(sharing(&c).at(10.0), &[1.0 / 3.0; 3]);
        // A table for other devices is an error naming both sets, never a silent fallback.
        let e = federated_named(Some("source_001"), ["imu", "gnss", "radar"])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "sharing = \"source_001\" is for the devices ins, gnss, radar, but this \
                 pipeline's devices are imu, gnss, radar"
            ),
            "{e}"
        );
        let e = federated_named(Some("source_000"), ["ins", "gnss", "radar"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is for the devices loop, radar"), "{e}");
        // Both a name and bands: refused.
        let both = FEDERATED.replace(
            "fusion_period_s = 1.0",
            "fusion_period_s = 1.0\nsharing = \"even\"",
        );
        let e = Pipelines::parse(&both, Path::new("f.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("give one or the other"), "{e}");
    }
}
