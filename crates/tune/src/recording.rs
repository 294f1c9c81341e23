//! A log decoded once for tuning: every message of the pipeline's sensors as measurements,
//! the device fault reports, and the reference samples, in file order. An evaluation replays
//! them from memory through a candidate pipeline, exactly as `refuse` feeds it (same sensor
//! models, same track-map context, same log times, same reorder window), and scores it as
//! `eval` does: the figures of a candidate equal those of `refuse` with the same file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use railfuse_catalog::foreign::ForeignChannels;
use railfuse_catalog::log::{ChannelInfo, LogMessage, LogRecord};
use railfuse_catalog::messages::{
    ChannelMessage, Event, EventKind, FusedState, GateDecision, SensorMount, TrackMap,
};
use railfuse_catalog::reference_track::ReferenceSample;
use railfuse_catalog::run::Run;
use serde::Serialize;

use crate::error::{Error, Result};
use railfuse_eval::accuracy::{AccuracyMeter, Consistency, ErrorStats, CHI2_95_1DOF};
use railfuse_eval::fix_match::{FixMeter, FixQuality, FixSample, StateAt};
use railfuse_eval::outages::{Withheld, Withhold};
use railfuse_eval::{self as eval, fix_sample, reference_kind, reference_sample};
use railfuse_refuse::measurement::{Measurement, Quantity, SensorContext, SensorModel};
use railfuse_refuse::pipeline::{AnyPipeline, Fused, PipelineCounts};
use railfuse_refuse::spec::PipelineSpec;

/// One thing that happened in the log, in file order.
#[derive(Debug, Clone)]
pub(super) enum Step {
    /// A message of sensor `sensor` at `log_time_ns`: `measurements[range]`.
    Sensor {
        sensor: usize,
        log_time_ns: u64,
        start: u32,
        end: u32,
    },
    /// A device fault report (`failed`) or recovery, naming device `device`.
    Device { device: usize, failed: bool },
}

/// A log, decoded for one pipeline's sensors.
#[derive(Debug)]
pub struct Recording {
    pub path: PathBuf,
    /// Per sensor of the pipeline: its channel's schema.
    /// Each sensor's channel schema; `None` for one the log lacks.
    pub(super) schemas: Vec<Option<String>>,
    /// Sensors left out because the log lacks their channel, each said as a warning.
    pub missing_sensors: Vec<String>,
    pub(super) steps: Vec<Step>,
    pub(super) measurements: Vec<Measurement>,
    devices: Vec<String>,
    /// The reference, in file order; empty without one or with a GNSS one.
    reference: Vec<ReferenceSample>,
    /// A GNSS reference's fixes, in file order: scored at each fix, the states interpolated
    /// to it (with a withheld sensor, only the fixes the pipeline was not shown).
    fixes: Vec<FixSample>,
    /// The sensor withheld from the pipeline, and when.
    pub withheld: Option<Withheld>,
    pub reference_topic: Option<String>,
    /// The last log time of the file (the pipelines are flushed there).
    end_ns: u64,
    /// How far a state may lag the reference, s.
    lag_s: f64,
    /// Sensor messages that did not decode (skipped, as `refuse` skips them).
    pub undecodable: u64,
    /// The drawing's installation tolerance as a chainage variance, m², added to every
    /// state's as refuse writes it (a consider term), so NEES is scored alike.
    pub installation_variance_m2: f64,
}

/// What one replay of a log did, and how well.
#[derive(Debug, Clone, Default)]
pub struct Score {
    pub position: ErrorStats,
    pub speed: ErrorStats,
    /// NEES of `[s, v]` against the reference.
    pub nees: Consistency,
    /// NIS of every measurement that reached the gate.
    pub nis: Consistency,
    /// −log-likelihood of those innovations, `½ Σ (ln 2πS + ν²/S)`.
    pub nll: f64,
    pub innovations: u64,
    pub states: u64,
    /// States the reference did not cover (outside it, or in one of its gaps); against GNSS
    /// fixes, fixes the states did not cover.
    pub unscored: u64,
    /// Against fixes withheld from the pipeline: `½ Σ (ln 2πv + e²/v)` of each fix as the
    /// states predicted it without it (v the state's variance there plus the fix's), and
    /// how many.
    pub heldout_nll: f64,
    pub heldout_fixes: u64,
    /// A state or innovation that was not a finite number.
    pub non_finite: u64,
    pub counts: PipelineCounts,
}

impl Score {
    /// Pools `other` (another log's score) into this one.
    pub fn merge(&mut self, other: &Score) {
        self.position.merge(&other.position);
        self.speed.merge(&other.speed);
        self.nees.merge(&other.nees);
        self.nis.merge(&other.nis);
        self.nll += other.nll;
        self.innovations += other.innovations;
        self.states += other.states;
        self.unscored += other.unscored;
        self.heldout_nll += other.heldout_nll;
        self.heldout_fixes += other.heldout_fixes;
        self.non_finite += other.non_finite;
        let (a, b) = (&mut self.counts, &other.counts);
        a.accepted += b.accepted;
        a.accepted_after_lockout += b.accepted_after_lockout;
        a.rejected_gate += b.rejected_gate;
        a.rejected_invalid += b.rejected_invalid;
        a.rejected_late += b.rejected_late;
        a.rejected_device_fault += b.rejected_device_fault;
        a.resets_to_fix += b.resets_to_fix;
        a.before_initialisation += b.before_initialisation;
    }

    /// The figures of this score, as reported.
    pub fn metrics(&self) -> Metrics {
        Metrics {
            position_rmse_m: self.position.summary().map(|s| s.rmse),
            speed_rmse_mps: self.speed.summary().map(|s| s.rmse),
            position_max_m: self.position.summary().map(|s| s.max_abs),
            nees_inside_95: self.nees.summary().map(|s| s.inside_95),
            nis_inside_95: self.nis.summary().map(|s| s.inside_95),
            nis_mean: self.nis.summary().map(|s| s.mean),
            nll: (self.innovations > 0).then_some(self.nll),
            innovations: self.innovations,
            states: self.states,
            gated: self.counts.rejected_gate,
        }
    }
}

/// The figures of a score.
#[derive(Debug, Clone, Serialize)]
pub struct Metrics {
    pub position_rmse_m: Option<f64>,
    pub speed_rmse_mps: Option<f64>,
    pub position_max_m: Option<f64>,
    /// Share of epochs whose NEES lies in the 95 % χ²₂ interval (0.95 when consistent).
    pub nees_inside_95: Option<f64>,
    /// Share of innovations whose NIS lies in the 95 % χ²₁ interval.
    pub nis_inside_95: Option<f64>,
    /// Mean NIS (1 when consistent).
    pub nis_mean: Option<f64>,
    pub nll: Option<f64>,
    pub innovations: u64,
    pub states: u64,
    pub gated: u64,
}

impl Recording {
    /// Reads `path` (a file, a directory of parts, a bag) once: the measurements of `spec`'s sensors and, when `reference` is
    /// given, its samples. Every sensor's channel must be in the log, and the reference too.
    ///
    /// Other tools' channels (a ROS 2 bag's) are read as the catalogue kinds they translate
    /// to, with the role their sensor table gives; `track` is the configuration's track, for
    /// a log without one.
    pub fn load(
        path: &Path,
        formats: &railfuse_catalog::formats::FormatOptions,
        spec: &PipelineSpec,
        reference: Option<&str>,
        track: Option<&TrackMap>,
        withhold: Option<&Withhold>,
    ) -> Result<Self> {
        // A sensor withheld from the pipeline may score it where it was withheld.
        let withheld_reference = withhold.is_some_and(|w| Some(w.topic.as_str()) == reference);
        if let Some(si) = reference
            .and_then(|r| spec.sensor_for(r))
            .filter(|_| !withheld_reference)
        {
            return Err(spec
                .channel_error(
                    path,
                    si,
                    "is also the reference: a sensor cannot score the filter it feeds (name \
                     another with --reference)"
                        .into(),
                )
                .into());
        }
        // A log is one run: a file, a directory of its parts, or a bag.
        let options = railfuse_catalog::run::RunOptions {
            formats: formats.clone(),
            ..Default::default()
        };
        let run = Run::open(&[path.to_owned()], &options)?;
        let mut reader = run.reader()?;
        let span = reader.summary().and_then(|s| s.message_span_ns);
        let withheld = withhold
            .map(|w| w.place(span))
            .transpose()
            .map_err(|message| Error::Recording {
                input: path.to_owned(),
                message,
            })?;
        let mut loader = Loader::new(path, spec, reference, track);
        loader.rec.withheld = withheld;
        while let Some(record) = reader.next() {
            match record? {
                LogRecord::Channel(c) => loader.channel(c)?,
                LogRecord::Message(m) => loader.message(m)?,
                _ => {}
            }
        }
        loader.finish()
    }

    /// Sensor messages held.
    pub fn messages(&self) -> usize {
        self.steps
            .iter()
            .filter(|s| matches!(s, Step::Sensor { .. }))
            .count()
    }

    /// Replays the log through `spec` (its sensors those the recording was made for) and
    /// scores it. The smoother, if the pipeline has one, is not run: states are scored.
    pub fn replay(&self, spec: &PipelineSpec) -> Result<Score> {
        if spec.estimator.reads_whole_messages() {
            return Err(Error::Recording {
                input: self.path.clone(),
                message: format!(
                    "pipeline '{}' is an {} pipeline, which reads whole messages: tune \
                     replays scalar measurements only",
                    spec.name,
                    spec.estimator.name()
                ),
            });
        }
        let mut pipeline = AnyPipeline::new(spec.without_smoother())?;
        for (si, schema) in self.schemas.iter().enumerate() {
            if let Some(schema) = schema {
                pipeline.bind(si, &spec.bind(&self.path, si, schema)?);
            }
        }
        let mut scorer = Scorer::new(self);
        let mut fused = Vec::new();
        for step in &self.steps {
            match *step {
                Step::Sensor {
                    sensor,
                    log_time_ns,
                    start,
                    end,
                } => {
                    let m = &self.measurements[start as usize..end as usize];
                    pipeline.push(sensor, m, log_time_ns, &mut fused);
                    scorer.take(&mut fused);
                }
                Step::Device { device, failed } => {
                    pipeline.device_event(&self.devices[device], failed)
                }
            }
        }
        pipeline.finish(self.end_ns, &Default::default(), &mut fused);
        scorer.take(&mut fused);
        Ok(scorer.finish(pipeline.counts().clone()))
    }
}

/// Scores fused output as it comes, walking the reference in step with the states.
struct Scorer<'a> {
    rec: &'a Recording,
    meter: AccuracyMeter,
    /// Against GNSS fixes.
    fixes: FixMeter,
    next_reference: usize,
    score: Score,
}

impl<'a> Scorer<'a> {
    fn new(rec: &'a Recording) -> Self {
        Self {
            rec,
            meter: AccuracyMeter::new(rec.lag_s),
            fixes: FixMeter::new(FixQuality::Auto, rec.lag_s),
            next_reference: 0,
            score: Score::default(),
        }
    }

    fn take(&mut self, fused: &mut Vec<Fused>) {
        for f in fused.drain(..) {
            if let Some(d) = &f.diagnostics {
                if let GateDecision::Accepted | GateDecision::RejectedGate = d.decision {
                    if let (Some(nu), Some(s)) = (d.innovation, d.innovation_variance) {
                        if nu.is_finite() && s.is_finite() && s > 0.0 {
                            self.score.nll +=
                                0.5 * ((std::f64::consts::TAU * s).ln() + nu * nu / s);
                            self.score.innovations += 1;
                            self.score.nis.add(nu * nu / s, CHI2_95_1DOF);
                        } else {
                            self.score.non_finite += 1;
                        }
                    }
                }
            }
            if let Some(state) = &f.state {
                self.state(state);
            }
        }
    }

    fn state(&mut self, state: &FusedState) {
        self.score.states += 1;
        if !(state.chainage_m.is_finite() && state.speed_mps.is_finite()) {
            self.score.non_finite += 1;
            return;
        }
        let fixes = &self.rec.fixes;
        if !fixes.is_empty() {
            while self.next_reference < fixes.len()
                && fixes[self.next_reference].stamp_ns <= state.stamp_ns
            {
                self.fixes.add_fix(fixes[self.next_reference], &[]);
                self.next_reference += 1;
            }
            let at = StateAt {
                stamp_ns: state.stamp_ns,
                chainage_m: state.chainage_m,
                speed_mps: state.speed_mps,
                variance_m2: state.covariance[0] + self.rec.installation_variance_m2,
                lateral_m: None,
            };
            self.fixes.add_state(&at, &[]);
            return;
        }
        let reference = &self.rec.reference;
        if reference.is_empty() {
            return;
        }
        while self.next_reference < reference.len()
            && self
                .meter
                .reference_newest_ns()
                .is_none_or(|n| n < state.stamp_ns)
        {
            let r = reference[self.next_reference];
            self.meter
                .add_reference(r.stamp_ns, r.chainage_m, r.speed_mps, &[]);
            self.next_reference += 1;
        }
        match self.rec.installation_variance_m2 {
            0.0 => self.meter.add_estimate(state, &[]),
            v => {
                let mut state = state.clone();
                state.covariance[0] += v;
                self.meter.add_estimate(&state, &[]);
            }
        }
    }

    fn finish(mut self, counts: PipelineCounts) -> Score {
        self.score.counts = counts;
        if !self.rec.fixes.is_empty() {
            for &fix in &self.rec.fixes[self.next_reference..] {
                self.fixes.add_fix(fix, &[]);
            }
            self.fixes.finish(&[]);
            self.score.position = self.fixes.position_stats().clone();
            self.score.speed = self.fixes.speed_stats().clone();
            let r = self.fixes.report();
            self.score.unscored = r.in_state_gaps + r.outside_states;
            if self.rec.withheld.is_some() {
                (self.score.heldout_nll, self.score.heldout_fixes) = self.fixes.nll();
            }
            return self.score;
        }
        self.meter.finish();
        self.score.position = self.meter.position;
        self.score.speed = self.meter.speed;
        self.score.nees = self.meter.nees;
        self.score.unscored = self.meter.unmatched + self.meter.in_reference_gaps;
        self.score
    }
}

/// A reference message into the recording: a GNSS fix as a fix (scored where it is), any
/// other reference as a sample of the trajectory.
fn reference_message(
    rec: &mut Recording,
    kind: eval::ReferenceKind,
    m: &LogMessage<'_>,
    path: &Path,
    place: (Option<&TrackMap>, Option<&SensorMount>),
) -> Result<()> {
    if kind == eval::ReferenceKind::Gnss {
        rec.fixes.extend(fix_sample(m, path, place)?);
    } else if let Some((t, s, v)) = reference_sample(kind, m, path, place)? {
        rec.reference.push(ReferenceSample {
            stamp_ns: t,
            chainage_m: s,
            speed_mps: v,
        });
    }
    Ok(())
}

/// What a channel is to a recording.
enum Role {
    /// A sensor; the reference too where it is withheld (its withheld messages score).
    Sensor(usize, SensorModel, Option<eval::ReferenceKind>),
    Map,
    /// The log's installation drawing: where each sensor sits.
    Vehicle,
    Events,
    Reference(eval::ReferenceKind),
}

/// One log being read into a [`Recording`]: each channel's role as it is met, then its
/// messages decoded into measurements, device events and reference samples.
struct Loader<'a> {
    path: &'a Path,
    spec: &'a PipelineSpec,
    reference: Option<&'a str>,
    topics_seen: Vec<String>,
    /// Channel id → what it is to this recording.
    roles: HashMap<u16, Role>,
    foreign: ForeignChannels,
    translated: Vec<u8>,
    context: SensorContext,
    reference_channel: bool,
    out: Vec<Measurement>,
    rec: Recording,
}

impl<'a> Loader<'a> {
    fn new(
        path: &'a Path,
        spec: &'a PipelineSpec,
        reference: Option<&'a str>,
        track: Option<&TrackMap>,
    ) -> Self {
        let rec = Recording {
            path: path.to_owned(),
            schemas: vec![None; spec.sensors.len()],
            missing_sensors: Vec::new(),
            steps: Vec::new(),
            measurements: Vec::new(),
            devices: Vec::new(),
            reference: Vec::new(),
            fixes: Vec::new(),
            withheld: None,
            reference_topic: reference.map(str::to_owned),
            end_ns: 0,
            lag_s: eval::lag_allowance_s(None) + spec.reorder_window_ns as f64 / 1e9,
            undecodable: 0,
            installation_variance_m2: 0.0,
        };
        Self {
            path,
            spec,
            reference,
            topics_seen: Vec::new(),
            roles: HashMap::new(),
            foreign: ForeignChannels::default(),
            translated: Vec::new(),
            context: SensorContext {
                track: track.cloned(),
                ..SensorContext::default()
            },
            reference_channel: false,
            out: Vec::new(),
            rec,
        }
    }

    /// A channel met: what it is (a sensor, the map, events, the reference), read as the
    /// catalogue kind it translates to where another tool wrote it.
    fn channel(&mut self, c: Arc<ChannelInfo>) -> Result<()> {
        let (path, spec, reference) = (self.path, self.spec, self.reference);
        self.topics_seen.push(c.topic.clone());
        let sensor = spec.sensor_for(&c.topic);
        let role = sensor.and_then(|si| spec.sensors[si].role);
        // Only what the pipeline reads is translated.
        let read = sensor.is_some() || Some(c.topic.as_str()) == reference;
        let c = match read {
            false => c,
            true => self.foreign.channel(c, role).map_err(|why| match sensor {
                Some(si) => spec.channel_error(path, si, why).into(),
                None => Error::Recording {
                    input: path.to_owned(),
                    message: format!("reference: {why}"),
                },
            })?,
        };
        let schema = c.schema_name();
        let kind = match Some(c.topic.as_str()) == reference {
            true => {
                self.reference_channel = true;
                Some(reference_kind(schema).ok_or_else(|| Error::Recording {
                    input: path.to_owned(),
                    message: format!(
                        "reference {} has schema '{schema}', not ground truth, a GNSS fix or a \
                         fused state",
                        c.topic
                    ),
                })?)
            }
            false => None,
        };
        let role = if let Some(si) = sensor {
            let binding = spec.bind(path, si, schema)?;
            self.rec.schemas[si] = Some(schema.to_owned());
            Some(Role::Sensor(si, binding.model, kind))
        } else if let Some(kind) = kind {
            Some(Role::Reference(kind))
        } else if schema == TrackMap::SCHEMA_NAME {
            Some(Role::Map)
        } else if schema == railfuse_catalog::messages::Vehicle::SCHEMA_NAME {
            Some(Role::Vehicle)
        } else if schema == Event::SCHEMA_NAME {
            Some(Role::Events)
        } else {
            None
        };
        if let Some(r) = role {
            self.roles.insert(c.id, r);
        }
        Ok(())
    }

    /// A message: measurements of a sensor, the track, a device event or a reference sample.
    fn message(&mut self, m: LogMessage<'_>) -> Result<()> {
        let path = self.path;
        let rec = &mut self.rec;
        rec.end_ns = rec.end_ns.max(m.log_time_ns);
        let m = match self.foreign.message(m, &mut self.translated) {
            Ok(Some(m)) => m,
            Ok(None) => return Ok(()),
            Err(_) => {
                rec.undecodable += 1;
                return Ok(());
            }
        };
        match self.roles.get(&m.channel.id) {
            Some(Role::Sensor(_, _, kind))
                if rec
                    .withheld
                    .as_ref()
                    .is_some_and(|w| w.topic == m.channel.topic && w.hides(m.log_time_ns)) =>
            {
                // Not shown to the pipeline; where it is the reference, it scores it.
                if let Some(kind) = *kind {
                    let antenna = self.context.vehicle.mount(&m.channel.topic);
                    let place = (self.context.track.as_ref(), antenna);
                    reference_message(rec, kind, &m, path, place)?;
                }
            }
            Some(Role::Sensor(si, model, _)) => {
                if model
                    .decode(&m, path, &self.context, &mut self.out)
                    .is_err()
                {
                    rec.undecodable += 1;
                    return Ok(());
                }
                follow(&self.out, &mut self.context.whereabouts);
                let start = rec.measurements.len() as u32;
                rec.measurements.extend_from_slice(&self.out);
                rec.steps.push(Step::Sensor {
                    sensor: *si,
                    log_time_ns: m.log_time_ns,
                    start,
                    end: rec.measurements.len() as u32,
                });
            }
            Some(Role::Map) => self.context.track = Some(m.decode(path)?),
            Some(Role::Vehicle) => {
                self.context.vehicle = m.decode(path)?;
                rec.installation_variance_m2 = self.context.vehicle.installation_variance();
            }
            Some(Role::Events) => {
                let e: Event = m.decode(path)?;
                let failed = match e.kind {
                    EventKind::DeviceFault => true,
                    EventKind::DeviceRecovered => false,
                    _ => return Ok(()),
                };
                let device = match rec.devices.iter().position(|d| *d == e.text) {
                    Some(i) => i,
                    None => {
                        rec.devices.push(e.text.clone());
                        rec.devices.len() - 1
                    }
                };
                rec.steps.push(Step::Device { device, failed });
            }
            Some(Role::Reference(kind)) => {
                let antenna = self.context.vehicle.mount(&m.channel.topic);
                let place = (self.context.track.as_ref(), antenna);
                reference_message(rec, *kind, &m, path, place)?
            }
            None => {}
        }
        Ok(())
    }

    /// The recording, once every sensor met its channel or was said missing, and the
    /// reference (if one was named) gave samples.
    fn finish(mut self) -> Result<Recording> {
        let (path, spec) = (self.path, self.spec);
        let n = spec.sensors.len();
        let have: Vec<&str> = self.topics_seen.iter().map(String::as_str).collect();
        for si in (0..n).filter(|&si| self.rec.schemas[si].is_none()) {
            let warning = spec.missing_channel(path, si, &have)?;
            self.rec.missing_sensors.push(warning);
        }
        if n > 0 && self.rec.missing_sensors.len() == n {
            return Err(spec
                .channel_error(
                    path,
                    0,
                    "is not in the file, nor is any other channel of the pipeline".into(),
                )
                .into());
        }
        if let Some(topic) = self.reference {
            let message = match self.reference_channel {
                false => format!("has no reference channel {topic}"),
                true if self.rec.reference.is_empty() && self.rec.fixes.is_empty() => {
                    format!("reference channel {topic} has no usable samples")
                }
                true => String::new(),
            };
            if !message.is_empty() {
                return Err(Error::Recording {
                    input: path.to_owned(),
                    message,
                });
            }
        }
        let mut rec = self.rec;
        rec.measurements.shrink_to_fit();
        rec.steps.shrink_to_fit();
        Ok(rec)
    }
}

/// Where the train is, from the measurements just decoded: a recording is made before any
/// filter runs, so the place-dependent corrections (a gradient's gravity, the rail's
/// length) are taken at the last absolute chainage measured, carried at the last speed.
fn follow(out: &[Measurement], w: &mut Option<railfuse_refuse::measurement::Whereabouts>) {
    let speed = out
        .iter()
        .find(|m| m.valid && m.quantity == Quantity::Speed && m.value.is_finite())
        .map(|m| m.value);
    if let (Some(w), Some(v)) = (w.as_mut(), speed) {
        w.speed_mps = v;
    }
    if let Some(c) = out
        .iter()
        .find(|m| m.valid && m.quantity == Quantity::Chainage && m.value.is_finite())
    {
        *w = Some(railfuse_refuse::measurement::Whereabouts {
            stamp_ns: c.stamp_ns,
            chainage_m: c.value,
            speed_mps: w.map_or(0.0, |w| w.speed_mps),
        });
    }
}
