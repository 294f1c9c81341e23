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
use crate::checks::{at_least_zero, positive};
use crate::config::{
    line_column, FilterKind, InitialConfig, PipelineConfig, PipelinesFile, Variance, VarianceValue,
};
use crate::error::{Error, Result};
use crate::filter::federated::FederatedSettings;
use crate::filter::particle::ParticleSettings;
use crate::kinds::{KindSpec, Outputs, PipelineKind};
use crate::measurement::{Quantity, SensorModel};
use crate::model::{MotionModel, SensorState};
use crate::registry::Registry;
use railfuse_eval::outages::Withhold;

mod estimator;
mod sensor;

use estimator::estimator;
use sensor::{devices, sensor};

/// The most state components a pipeline may have (motion and sensor states together).
pub const MAX_STATES: usize = 10;

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
    /// `[run]`: the recorders' clocks given, and how to align them.
    pub clock_offsets: Vec<railfuse_catalog::run::ClockOffset>,
    pub align: Option<railfuse_catalog::run::Align>,
    /// `[can]` and `[sensor."<topic>"]`: sensors made from the CAN bus, the DBC read and the
    /// mapping checked against it.
    pub can: Option<CanSensors>,
    /// `[vehicle]`: the train, checked (it wins over the log's `/vehicle`).
    pub vehicle: Option<railfuse_catalog::messages::Vehicle>,
    /// The confidence of the safe front end interval every pipeline's train channel gives.
    pub confidence: f64,
    pub pipeline: Vec<PipelineSpec>,
}

/// The safe interval's confidence when the configuration states none: 99.99 %, a Gaussian
/// error inside ±3.89 σ.
pub const DEFAULT_CONFIDENCE: f64 = 0.9999;

/// A confidence the safe interval can be taken at: above 50 % (below it the interval would
/// hold the estimate less often than not) and below 1 (the interval would be infinite).
pub fn check_confidence(c: f64) -> std::result::Result<f64, String> {
    match c.is_finite() && (0.5..1.0).contains(&c) {
        true => Ok(c),
        false => Err(format!(
            "{c}: a confidence must be at least 0.5 and below 1 (0.9999 is ±3.89 σ)"
        )),
    }
}

/// The vehicle's DBC and the sensors a configuration makes from its signals.
#[derive(Debug, Clone)]
pub struct CanSensors {
    /// Each bus's DBC (`None`: every bus no other names).
    pub dbs: railfuse_can::dbc::BusDbcs,
    pub sensors: std::collections::BTreeMap<String, crate::config::SensorSource>,
}

impl CanSensors {
    /// The bridge that makes the sensors' messages from frames.
    pub fn bridge(&self) -> railfuse_catalog::foreign::can::SensorBridge {
        railfuse_catalog::foreign::can::SensorBridge::with_databases(
            self.dbs.clone(),
            &self.sensors,
        )
        .expect("checked when the configuration was read")
    }

    /// `[can]` and `[sensor]` of a configuration at `path`: the DBCs (relative to it) read and
    /// every mapping checked.
    fn read(
        path: &Path,
        can: Option<crate::config::CanBuses>,
        sensors: std::collections::BTreeMap<String, crate::config::SensorSource>,
    ) -> Result<Option<Self>> {
        let bad = |message: String| Error::ConfigSyntax {
            path: path.to_owned(),
            message,
        };
        let Some(can) = can else {
            return match sensors.keys().next() {
                None => Ok(None),
                Some(topic) => Err(bad(format!(
                    "[sensor.\"{topic}\"] reads the CAN bus: name the vehicle's DBC in \
                     [can] dbc = \"vehicle.dbc\""
                ))),
            };
        };
        if sensors.is_empty() {
            return Err(bad(
                "[can] names a DBC and no [sensor.\"<topic>\"] reads it: map a signal, \
                 e.g. [sensor.\"/odometer/1\"] from = \"can:WheelSpeed.AxleSpeed1\""
                    .into(),
            ));
        }
        let mut dbs = railfuse_can::dbc::BusDbcs::default();
        for (i, bus) in can.buses().iter().enumerate() {
            if can.buses()[..i].iter().any(|b| b.bus == bus.bus) {
                return Err(bad(format!(
                    "[[can]]: two tables for {}: one DBC a bus",
                    bus.bus
                        .as_deref()
                        .map_or("every bus".to_owned(), |b| format!("bus {b}"))
                )));
            }
            let dbc = path.parent().unwrap_or(Path::new("")).join(&bus.dbc);
            let db = railfuse_can::dbc::Database::open(&dbc)
                .map_err(|e| bad(format!("[can] dbc: {e}")))?;
            dbs.0.push((bus.bus.clone(), std::sync::Arc::new(db)));
        }
        railfuse_catalog::foreign::can::SensorBridge::with_databases(dbs.clone(), &sensors)
            .map_err(|e| bad(e.to_string()))?;
        Ok(Some(Self { dbs, sensors }))
    }
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

    /// Takes the `[vehicle]` table of the TOML file `path` (what `railfuse calibrate` writes,
    /// or another configuration) over this configuration's own, checked as its own is: the
    /// command line's `--vehicle` wins over the file's value. The file is the train's, which
    /// may carry sensors this configuration does not read: those are left aside and their
    /// topics returned (for the caller to say), where a configuration's own `[vehicle]`
    /// refuses them.
    pub fn set_vehicle_from(&mut self, path: &Path) -> Result<Vec<String>> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::ConfigRead {
            path: path.to_owned(),
            source,
        })?;
        #[derive(serde::Deserialize)]
        struct VehicleFile {
            vehicle: Option<Spanned<crate::config::VehicleConfig>>,
        }
        let file: VehicleFile = toml::from_str(&text).map_err(|e| Error::ConfigSyntax {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        if file.vehicle.is_none() {
            return Err(Error::ConfigSyntax {
                path: path.to_owned(),
                message: "has no [vehicle] table".into(),
            });
        }
        let mut unread = Vec::new();
        let table = file.vehicle.as_ref();
        self.vehicle = read_vehicle(path, &text, table, &self.pipeline, Some(&mut unread))?;
        Ok(unread)
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
        let track = read_track(path, file.track.as_deref())?;
        let vehicle = read_vehicle(path, text, file.vehicle.as_ref(), &pipeline, None)?;
        let can = CanSensors::read(path, file.can, file.sensor)?;
        let (clock_offsets, align) = read_run(path, file.run.unwrap_or_default())?;
        let confidence =
            check_confidence(file.confidence.unwrap_or(DEFAULT_CONFIDENCE)).map_err(|message| {
                Error::ConfigSyntax {
                    path: path.to_owned(),
                    message,
                }
            })?;
        Ok(Self {
            path: path.to_owned(),
            track,
            clock_offsets,
            align,
            can,
            vehicle,
            confidence,
            pipeline,
        })
    }

    /// Every topic a pipeline reads, once each.
    pub fn read_topics(&self) -> Vec<String> {
        let mut topics: Vec<String> = self
            .pipeline
            .iter()
            .flat_map(|p| p.sensors.iter().map(|s| s.topic.clone()))
            .collect();
        topics.sort();
        topics.dedup();
        topics
    }

    /// The names of the pipelines, in file order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.pipeline.iter().map(|p| p.name.as_str())
    }
}

/// `[vehicle]`, checked: a length a train has, every sensor on the train and turned less than
/// 45°, and each placed topic one a pipeline reads (a lever arm for anything else is a
/// misspelt topic, which would leave the sensor it meant at the front end), unless `unread`
/// takes such topics (a whole train's file beside a configuration that reads some of them).
fn read_vehicle(
    path: &Path,
    text: &str,
    table: Option<&toml::Spanned<crate::config::VehicleConfig>>,
    pipelines: &[PipelineSpec],
    unread: Option<&mut Vec<String>>,
) -> Result<Option<railfuse_catalog::messages::Vehicle>> {
    let Some(table) = table else {
        return Ok(None);
    };
    let (line, _) = line_column(text, table.span().start);
    let fail = |message: String| Error::ConfigSyntax {
        path: path.to_owned(),
        message: format!("line {line}: [vehicle]: {message}"),
    };
    let mut vehicle = table.get_ref().vehicle();
    vehicle.check().map_err(|e| fail(e.to_string()))?;
    let read = |topic: &str| pipelines.iter().any(|p| p.sensor_for(topic).is_some());
    match unread {
        Some(unread) => {
            unread.extend(
                vehicle
                    .sensors
                    .iter()
                    .filter(|s| !read(&s.topic))
                    .map(|s| s.topic.clone()),
            );
            vehicle.sensors.retain(|s| read(&s.topic));
        }
        None => {
            if let Some(s) = vehicle.sensors.iter().find(|s| !read(&s.topic)) {
                return Err(fail(format!(
                    "sensor '{}' has a lever arm but no pipeline reads that topic",
                    s.topic
                )));
            }
        }
    }
    Ok(Some(vehicle))
}

/// The configuration's track file (relative to it), read and checked.
fn read_track(
    path: &Path,
    track: Option<&Path>,
) -> Result<Option<railfuse_catalog::messages::TrackMap>> {
    let Some(t) = track else {
        return Ok(None);
    };
    let at = path.parent().unwrap_or(Path::new("")).join(t);
    railfuse_catalog::track_geojson::read_track_file(&at)
        .map(Some)
        .map_err(|e| Error::ConfigSyntax {
            path: path.to_owned(),
            message: format!("track: {e}"),
        })
}

/// `[run]`: the recorders' clock offsets and the alignment, parsed.
fn read_run(
    path: &Path,
    run: crate::config::RunSettings,
) -> Result<(
    Vec<railfuse_catalog::run::ClockOffset>,
    Option<railfuse_catalog::run::Align>,
)> {
    let bad_run = |message: String| Error::ConfigSyntax {
        path: path.to_owned(),
        message: format!("[run] {message}"),
    };
    let clock_offsets = run
        .clock_offsets
        .iter()
        .map(|c| {
            c.parse()
                .map_err(|e| bad_run(format!("clock_offsets: {e}")))
        })
        .collect::<Result<_>>()?;
    let align = run
        .align
        .as_deref()
        .map(|a| a.parse().map_err(|e| bad_run(format!("align: {e}"))))
        .transpose()?;
    Ok((clock_offsets, align))
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
    /// Gate rejections in a row of its chainage after which the estimate is reset to it
    /// (config `reset_after`; `None`: its sensor model's default).
    pub reset_after: Option<u32>,
    /// Its variance estimated from its last this many innovations (config
    /// `adaptive_variance`), never below the stated one.
    pub adaptive_window: Option<usize>,
    /// Its calibration states, in state order.
    pub states: Vec<SensorState>,
    /// The window its speed is the mean over, s (config `speed_window_s`).
    pub speed_window_s: Option<f64>,
    /// How late its stamps are (config `time_offset_s`): measurement time = stamp − this.
    pub time_offset_ns: i64,
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
    /// `[pipeline.eval]`: a sensor withheld from it in outages, to score it against.
    pub withhold: Option<Withhold>,
    /// The table as written, stored beside the fused channels.
    source: PipelineConfig,
}

/// Each sensor's `time_offset_s` can be honoured: its pipeline fuses measurements along the
/// track (a message pipeline reads its messages' own times) and holds them back long enough.
fn check_latencies(
    sensors: &[SensorSpec],
    tables: &[Spanned<crate::config::SensorConfig>],
    estimator: &EstimatorSpec,
    reorder_window_s: f64,
) -> Result<(), Invalid> {
    for (s, table) in sensors.iter().zip(tables) {
        let late_s = s.time_offset_ns as f64 / 1e9;
        let problem = if s.time_offset_ns == 0 {
            continue;
        } else if estimator.reads_whole_messages() {
            format!(
                "time_offset_s: an {} pipeline reads its messages' own times; give the \
                 latency to an along-track pipeline",
                estimator.name()
            )
        } else if late_s > reorder_window_s {
            format!(
                "time_offset_s = {late_s} is longer than reorder_window_s = \
                 {reorder_window_s}: its measurements would come after their time was \
                 fused; raise reorder_window_s"
            )
        } else {
            continue;
        };
        return Err(Invalid {
            span: table.span(),
            message: format!("sensor {}: {problem}", s.topic),
        });
    }
    Ok(())
}

/// `[pipeline.eval]` checked: the topic withheld is one of the pipeline's sensors, the
/// outages parse.
fn withhold(e: &crate::config::EvalConfig, sensors: &[SensorSpec]) -> Result<Withhold, Invalid> {
    let topic = e.withhold.get_ref();
    if !sensors.iter().any(|s| &s.topic == topic) {
        let have: Vec<&str> = sensors.iter().map(|s| s.topic.as_str()).collect();
        return Err(Invalid {
            span: e.withhold.span(),
            message: format!(
                "eval.withhold: {topic} is not a sensor of this pipeline ({})",
                have.join(", ")
            ),
        });
    }
    let outages = e
        .outages
        .as_ref()
        .map(|o| {
            o.get_ref().parse().map_err(|message: String| Invalid {
                span: o.span(),
                message: format!("eval.{message}"),
            })
        })
        .transpose()?;
    Ok(Withhold {
        topic: topic.clone(),
        outages,
    })
}

/// A pipeline's name is part of its channels' topics (`/fused/<name>/state`): letters, digits,
/// '_' and '-' only.
fn check_name(name: &str) -> Result<(), String> {
    let fits = |ch: char| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-';
    match !name.is_empty() && name.chars().all(fits) {
        true => Ok(()),
        false => Err("the name may hold only letters, digits, '_' and '-'".into()),
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
        check_name(&c.name).map_err(here)?;
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
        let withhold = c.eval.as_ref().map(|e| withhold(e, &sensors)).transpose()?;
        check_latencies(&sensors, &c.sensor, &estimator, reorder_window_s)?;
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
            withhold,
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
        // An eddy_current pipeline says which of its sensors is the block channel (`accepts`).
        let eddy = matches!(&self.estimator, EstimatorSpec::Messages(k) if k.reads_raw_blocks());
        if !eddy && model == SensorModel::EddyCurrent {
            return Err(fail(
                "carries raw eddy-current blocks, which only an eddy_current pipeline reads".into(),
            ));
        }
        if let EstimatorSpec::Messages(k) = &self.estimator {
            k.accepts(sensor, model)
                .map_err(|why| fail(format!("has schema '{schema}': {why}")))?;
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

#[cfg(test)]
mod tests;
