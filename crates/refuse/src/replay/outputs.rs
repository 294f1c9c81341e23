//! What the replay writes besides the input's records: each pipeline's channels (state,
//! diagnostics, smoothed states, safety status, IMU error model, Foxglove and ROS twins), the
//! configuration's track, and the channel ids they take.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;

use railfuse_catalog::foreign::ros2;
use railfuse_catalog::foxglove::TwinKind;
use railfuse_catalog::log::{ChannelId, ChannelInfo, LogWriter};
use railfuse_catalog::messages::{
    ChannelMessage, FusedDiagnostics, FusedState, ImuErrorModel, MessageKind, SafetyStatus,
    TrackMap, TrainPosition,
};
use railfuse_catalog::topics;

use crate::error::{Error, Result};
use crate::spec::PipelineSpec;
use railfuse_eval::Evaluator;

use super::can_sensors::CanSensors;
use super::{observe, RefuseOptions, Replay, LOCATION_TWIN_EVERY_NS};

pub(super) struct Output {
    state: ChannelId,
    /// The pipeline's position as a Foxglove LocationFix, when twins are on, and the stamp of
    /// the last one written.
    location: Option<ChannelId>,
    last_location_ns: Option<u64>,
    diagnostics: ChannelId,
    smoothed: Option<ChannelId>,
    /// Pipelines with safety checks: `/fused/<name>/safety`.
    safety: Option<ChannelId>,
    /// GNSS/INS pipelines: `/fused/<name>/imu_error_model`.
    imu_error_model: Option<ChannelId>,
    /// `/fused/<name>/train`: the whole train after its states, and the stamp of the last one
    /// written.
    train: Option<ChannelId>,
    last_train_ns: Option<u64>,
    pub(super) states: u64,
    pub(super) smoothed_states: u64,
}

impl Replay<'_> {
    /// Each pipeline's NavSatFix and Odometry channels (CDR, `ros2msg` schemas), on ids below
    /// the other fused channels' that the input has not used so far.
    pub(super) fn register_ros_outputs(&mut self) -> Result<()> {
        let lowest = self
            .outputs
            .iter()
            .flat_map(|o| {
                [
                    Some(o.state),
                    o.location,
                    Some(o.diagnostics),
                    o.smoothed,
                    o.safety,
                ]
                .into_iter()
                .chain([o.imu_error_model, o.train])
            })
            .flatten()
            .map(|c| c.0)
            .chain(self.track_output.iter().flat_map(TrackOutput::ids))
            .min()
            .unwrap_or(u16::MAX);
        let needed = 2 + 2 * self.pipelines.len();
        let ids: Vec<u16> = (1..lowest)
            .rev()
            .filter(|id| !self.channels.contains_key(id) && !self.schemas.contains_key(id))
            .take(needed)
            .collect();
        if ids.len() < needed {
            return Err(Error::Log(ids_exhausted(self.opts.output)));
        }
        let (nav_schema, odom_schema) = (ids[0], ids[1]);
        let w = &mut self.writer;
        w.copy_schema(
            nav_schema,
            ros2::NAV_SAT_FIX,
            "ros2msg",
            ros2::NAV_SAT_FIX_DEFINITION.as_bytes(),
        )?;
        w.copy_schema(
            odom_schema,
            ros2::ODOMETRY,
            "ros2msg",
            ros2::ODOMETRY_DEFINITION.as_bytes(),
        )?;
        let none = BTreeMap::new();
        for (k, p) in self.pipelines.iter().enumerate() {
            let (nav, odom) = (ids[2 + 2 * k], ids[3 + 2 * k]);
            let name = p.name();
            w.copy_channel(
                nav,
                nav_schema,
                &topics::fused_nav_sat_fix(name),
                ros2::ENCODING,
                &none,
            )?;
            w.copy_channel(
                odom,
                odom_schema,
                &topics::fused_odometry(name),
                ros2::ENCODING,
                &none,
            )?;
            self.ros_outputs.push((ChannelId(nav), ChannelId(odom)));
        }
        Ok(())
    }

    /// Writes and scores what pipeline `pi` released.
    pub(super) fn emit(&mut self, pi: usize) -> Result<()> {
        let out = &mut self.outputs[pi];
        let observer = self.opts.observer;
        let name = self.pipelines[pi].name();
        for mut f in self.fused.drain(..) {
            if let Some(s) = &mut f.state {
                with_installation(s, &self.context.vehicle);
            }
            if let (0, Some(s)) = (pi, &f.state) {
                note_whereabouts(&mut self.context, s);
            }
            if observer.is_some() {
                if let Some(state) = &f.state {
                    observe(observer, &topics::fused_state(name), f.log_time_ns, state);
                }
                if let Some(d) = &f.diagnostics {
                    observe(observer, &topics::fused_diagnostics(name), f.log_time_ns, d);
                }
            }
            if let Some(state) = &f.state {
                let map = self.context.track.as_ref();
                write_location(out, &mut self.writer, map, name, f.log_time_ns, state)?;
            }
            if let (Some(state), Some(&(nav, odom))) = (&f.state, self.ros_outputs.get(pi)) {
                let map = self.context.track.as_ref();
                if let Some(fix) = ros2::fused_nav_sat_fix(name, state, map) {
                    self.writer
                        .write_encoded(nav, f.log_time_ns, state.stamp_ns, &fix)?;
                }
                let odometry = ros2::fused_odometry(state, map);
                self.writer
                    .write_encoded(odom, f.log_time_ns, state.stamp_ns, &odometry)?;
            }
            if let Some(state) = &f.state {
                self.writer.write(out.state, f.log_time_ns, state)?;
                self.eval.fused_state(out.state.0, state);
                out.states += 1;
                self.report.fused_messages += 1;
                let confidence = self.opts.config.confidence;
                let (writer, eval, context) = (&mut self.writer, &mut self.eval, &self.context);
                if write_train(
                    out,
                    (writer, eval),
                    context,
                    confidence,
                    f.log_time_ns,
                    state,
                )? {
                    self.report.fused_messages += 1;
                }
            }
            if let Some(d) = &f.diagnostics {
                self.writer.write(out.diagnostics, f.log_time_ns, d)?;
                self.eval.fused_diagnostics(out.diagnostics.0, d);
                self.report.fused_messages += 1;
            }
            if let (Some(safety), Some(channel)) = (&f.safety, out.safety) {
                if observer.is_some() {
                    observe(observer, &topics::fused_safety(name), f.log_time_ns, safety);
                }
                self.writer.write(channel, f.log_time_ns, safety)?;
                self.eval.safety_status(channel.0, safety);
                self.report.fused_messages += 1;
            }
            if let (Some(model), Some(channel)) = (&f.imu_error_model, out.imu_error_model) {
                self.writer.write(channel, f.log_time_ns, model)?;
                self.report.fused_messages += 1;
            }
        }
        Ok(())
    }

    pub(super) fn write_smoothed(&mut self, pi: usize) -> Result<()> {
        let (Some(channel), Some(smoothed)) =
            (self.outputs[pi].smoothed, self.pipelines[pi].smoothed())
        else {
            return Ok(());
        };
        let name = self.pipelines[pi].name().to_owned();
        let spill = |source| Error::Spill {
            pipeline: name.clone(),
            source,
        };
        for state in smoothed.map_err(spill)? {
            let mut state = state.map_err(spill)?;
            with_installation(&mut state, &self.context.vehicle);
            observe(
                self.opts.observer,
                &topics::fused_smoothed(&name),
                state.stamp_ns,
                &state,
            );
            self.writer.write(channel, state.stamp_ns, &state)?;
            if !self.reference_is_ours() {
                self.eval.smoothed_state(channel.0, &state, self.opts.run)?;
            }
            self.report.fused_messages += 1;
            self.outputs[pi].smoothed_states += 1;
        }
        Ok(())
    }
}

/// A state as written: its chainage variance with the drawing's installation tolerance
/// ([`Vehicle::installation_variance`](railfuse_catalog::messages::Vehicle)), which the
/// pipeline cannot see (a sensor's lever arm off by its tolerance moves the front end it
/// finds by as much, for good).
fn with_installation(state: &mut FusedState, vehicle: &railfuse_catalog::messages::Vehicle) {
    state.covariance[0] += vehicle.installation_variance();
}

/// The first pipeline's estimate: where place-dependent corrections are taken.
fn note_whereabouts(context: &mut crate::measurement::SensorContext, s: &FusedState) {
    if s.chainage_m.is_finite() && s.speed_mps.is_finite() {
        context.whereabouts = Some(crate::measurement::Whereabouts {
            stamp_ns: s.stamp_ns,
            chainage_m: s.chainage_m,
            speed_mps: s.speed_mps,
        });
    }
}

/// The state's Foxglove location twin: a map needs no more than 10 positions a second (the
/// fused state keeps every one).
fn write_location(
    out: &mut Output,
    writer: &mut LogWriter,
    map: Option<&railfuse_catalog::messages::TrackMap>,
    name: &str,
    log_time_ns: u64,
    state: &FusedState,
) -> Result<()> {
    let Some(channel) = out.location else {
        return Ok(());
    };
    let due = out
        .last_location_ns
        .is_none_or(|last| state.stamp_ns >= last + LOCATION_TWIN_EVERY_NS);
    let twin = due
        .then(|| railfuse_catalog::foxglove::fused_location(name, state, map))
        .flatten();
    if let Some(twin) = twin {
        writer.write_twin(channel, log_time_ns, &twin)?;
        out.last_location_ns = Some(state.stamp_ns);
    }
    Ok(())
}

/// The whole train after a pipeline's `state` on its train channel, at most ten times a
/// second (a map needs no more; the state keeps every estimate); whether one was written.
fn write_train(
    out: &mut Output,
    (writer, eval): (&mut LogWriter, &mut Evaluator),
    context: &crate::measurement::SensorContext,
    confidence: f64,
    log_time_ns: u64,
    state: &FusedState,
) -> Result<bool> {
    let Some(channel) = out.train else {
        return Ok(false);
    };
    let due = out
        .last_train_ns
        .is_none_or(|last| state.stamp_ns >= last + LOCATION_TWIN_EVERY_NS);
    let map = context.track.as_ref();
    let train = due
        .then(|| TrainPosition::of(state, &context.vehicle, map, confidence))
        .flatten();
    let Some(train) = train else {
        return Ok(false);
    };
    writer.write(channel, log_time_ns, &train)?;
    eval.train_position(channel.0, &train);
    out.last_train_ns = Some(state.stamp_ns);
    Ok(true)
}

/// Registers every pipeline's fused channels with the writer and the evaluation. They take
/// the highest ids the input (`known`, its summary's channels) does not use, so copied
/// records keep theirs (replaced channels' ids too: their records may sit in chunks copied
/// whole).
/// Each pipeline's fused channels and, for a configuration's track that the input (whose
/// summary lists its channels) lacks, a `/track/map` channel to write it on.
pub(super) fn register_outputs(
    opts: &RefuseOptions<'_>,
    known: Option<&[Arc<ChannelInfo>]>,
    writer: &mut LogWriter,
    eval: &mut Evaluator,
) -> Result<(Vec<Output>, Option<TrackOutput>, Option<CanSensors>)> {
    let mut ids = FreeIds::new(known, opts.output);
    let (state, diagnostics, location) = (ids.next()?, ids.next()?, ids.next()?);
    let safety = ids.next()?;
    // Only when needed, so that the other pipelines' channel ids stay as they were.
    let any_gnss_ins = opts
        .config
        .pipeline
        .iter()
        .any(|p| p.estimator.outputs().imu_error_model);
    let imu_error_model = match any_gnss_ins {
        true => Some(ids.next()?),
        false => None,
    };
    let schemas = Schemas {
        state,
        diagnostics,
        location,
        safety,
        imu_error_model,
    };
    let mut outputs = Vec::new();
    for p in &opts.config.pipeline {
        outputs.push(pipeline_output(p, &schemas, &mut ids, writer, eval)?);
    }
    // After the others, so that their ids stay as they were before trains were written.
    let train_schema = ids.next()?;
    for (o, p) in outputs.iter_mut().zip(&opts.config.pipeline) {
        let topic = topics::fused_train(&p.name);
        let id = writer.add_channel_with_ids::<TrainPosition>(train_schema, ids.next()?, &topic)?;
        eval.channel(id.0, &topic, TrainPosition::SCHEMA_NAME);
        o.train = Some(id);
    }
    let input_has_track = |channels: &[Arc<ChannelInfo>]| {
        channels
            .iter()
            .any(|c| c.kind() == Some(MessageKind::TrackMap))
    };
    let track = match (&opts.config.track, known) {
        (Some(_), Some(channels)) if !input_has_track(channels) => {
            let (schema, id) = (ids.next()?, ids.next()?);
            let map = writer.add_channel_with_ids::<TrackMap>(schema, id, topics::TRACK_MAP)?;
            let twin = match railfuse_catalog::foxglove::twins_by_default() {
                true => Some(writer.add_twin_channel_with_ids(
                    TwinKind::GeoJson,
                    ids.next()?,
                    ids.next()?,
                    &railfuse_catalog::foxglove::twin_topic(topics::TRACK_MAP),
                )?),
                false => None,
            };
            Some(TrackOutput { map, twin })
        }
        _ => None,
    };
    let can = match &opts.config.can {
        Some(spec) => Some(CanSensors::register(spec, || ids.next(), writer)?),
        None => None,
    };
    Ok((outputs, track, can))
}

/// Ids neither a channel nor a schema of the input uses, highest first.
struct FreeIds<'a> {
    free: Box<dyn Iterator<Item = u16>>,
    output: &'a Path,
}

impl<'a> FreeIds<'a> {
    fn new(known: Option<&[Arc<ChannelInfo>]>, output: &'a Path) -> Self {
        let mut used: BTreeSet<u16> = known.into_iter().flatten().map(|c| c.id).collect();
        used.extend(
            known
                .into_iter()
                .flatten()
                .filter_map(|c| c.schema.as_ref().map(|s| s.id)),
        );
        Self {
            free: Box::new((1..=u16::MAX).rev().filter(move |id| !used.contains(id))),
            output,
        }
    }

    fn next(&mut self) -> Result<u16> {
        self.free
            .next()
            .ok_or_else(|| Error::Log(ids_exhausted(self.output)))
    }
}

/// The schema ids of the fused channels, shared by every pipeline.
struct Schemas {
    state: u16,
    diagnostics: u16,
    location: u16,
    safety: u16,
    imu_error_model: Option<u16>,
}

/// One pipeline's channels, registered (and told to the evaluator) in a fixed order.
fn pipeline_output(
    p: &PipelineSpec,
    schemas: &Schemas,
    ids: &mut FreeIds<'_>,
    writer: &mut LogWriter,
    eval: &mut Evaluator,
) -> Result<Output> {
    let state_topic = topics::fused_state(&p.name);
    let diag_topic = topics::fused_diagnostics(&p.name);
    let state =
        writer.add_channel_with_ids::<FusedState>(schemas.state, ids.next()?, &state_topic)?;
    let diagnostics = writer.add_channel_with_ids::<FusedDiagnostics>(
        schemas.diagnostics,
        ids.next()?,
        &diag_topic,
    )?;
    eval.channel(state.0, &state_topic, FusedState::SCHEMA_NAME);
    eval.channel(diagnostics.0, &diag_topic, FusedDiagnostics::SCHEMA_NAME);
    let smoothed = match p.estimator.smoother() {
        true => {
            let topic = topics::fused_smoothed(&p.name);
            let id =
                writer.add_channel_with_ids::<FusedState>(schemas.state, ids.next()?, &topic)?;
            eval.channel(id.0, &topic, FusedState::SCHEMA_NAME);
            Some(id)
        }
        false => None,
    };
    let imu_error_model = match (
        p.estimator.outputs().imu_error_model,
        schemas.imu_error_model,
    ) {
        (true, Some(schema)) => {
            let topic = topics::fused_imu_error_model(&p.name);
            Some(writer.add_channel_with_ids::<ImuErrorModel>(schema, ids.next()?, &topic)?)
        }
        _ => None,
    };
    let safety = match p.estimator.outputs().safety {
        true => {
            let topic = topics::fused_safety(&p.name);
            let id =
                writer.add_channel_with_ids::<SafetyStatus>(schemas.safety, ids.next()?, &topic)?;
            eval.channel(id.0, &topic, SafetyStatus::SCHEMA_NAME);
            Some(id)
        }
        _ => None,
    };
    let location = match railfuse_catalog::foxglove::twins_by_default() {
        true => Some(writer.add_twin_channel_with_ids(
            TwinKind::LocationFix,
            schemas.location,
            ids.next()?,
            &railfuse_catalog::foxglove::twin_topic(&state_topic),
        )?),
        false => None,
    };
    Ok(Output {
        state,
        location,
        last_location_ns: None,
        diagnostics,
        smoothed,
        safety,
        imu_error_model,
        train: None,
        last_train_ns: None,
        states: 0,
        smoothed_states: 0,
    })
}

/// Where the configuration's track is written in the output, and its Foxglove twin.
#[derive(Debug, Clone, Copy)]
pub(super) struct TrackOutput {
    map: ChannelId,
    twin: Option<ChannelId>,
}

impl TrackOutput {
    pub(super) fn ids(&self) -> impl Iterator<Item = u16> {
        [Some(self.map), self.twin]
            .into_iter()
            .flatten()
            .map(|c| c.0)
    }

    /// Writes `track` on its channels (its twin on the twin's own: the writer's automatic
    /// twin channel would take an id the input may use).
    pub(super) fn write(
        &self,
        writer: &mut LogWriter,
        log_time_ns: u64,
        track: &TrackMap,
    ) -> Result<()> {
        writer.write_message(self.map, log_time_ns, track)?;
        let twin = railfuse_catalog::foxglove::Twin::of(track);
        if let (Some(channel), Some(twin)) = (self.twin, twin) {
            writer.write_twin(channel, log_time_ns, &twin)?;
        }
        Ok(())
    }
}

pub(super) fn copy_channel(writer: &mut LogWriter, c: &ChannelInfo) -> Result<()> {
    let schema = c.schema.as_ref().map_or(0, |s| s.id);
    Ok(writer.copy_channel(c.id, schema, &c.topic, &c.message_encoding, &c.metadata)?)
}

pub(super) fn ids_exhausted(output: &Path) -> railfuse_catalog::Error {
    railfuse_catalog::Error::Write {
        path: output.to_owned(),
        cause: "no channel ids left for the fused channels".into(),
    }
}
