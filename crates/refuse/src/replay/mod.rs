//! The `refuse` run: stream the input log once, copy every record to the output unchanged,
//! feed each pipeline the measurements of its channels, write `/fused/<name>/state`,
//! `/fused/<name>/diagnostics` (and `/fused/<name>/smoothed` where asked), and store each
//! pipeline's configuration as metadata. Scoring the result is [`railfuse_eval`]'s job.
//!
//! Memory is bounded by the reorder windows, never by the length of the log (the smoother
//! spills to a temporary file).

use railfuse_catalog::protobuf::Encoding;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::op;
use railfuse_catalog::foreign::{ros2, Translated, Translator};
use railfuse_catalog::log::format::{self, Records};
use railfuse_catalog::log::scan::{Chunk, Item, ReadAhead, Scanner, READ_AHEAD_BYTES};
use railfuse_catalog::log::{
    read_summary, ChannelId, ChannelInfo, ChunkTally, IdMap, LogMessage, LogRecord, LogSummary,
    LogWriter, SchemaInfo,
};
use railfuse_catalog::messages::{ChannelMessage, Event, EventKind, TrackMap};
use railfuse_catalog::rejections::Rejections;
use railfuse_catalog::run::{MergeCounts, Run, Sequential};
use railfuse_catalog::topics;
use railfuse_eval::outages::Withhold;
use railfuse_eval::Reference;
use serde::Serialize;
use withholding::Withholding;

use crate::error::{Error, Result};
use crate::measurement::{Measurement, Quantity, SensorContext, SensorModel};
use crate::pipeline::{AnyPipeline, Fused, PipelineCounts};
use crate::spec::Pipelines;
use railfuse_eval::{self as eval, EvalReport, Evaluator};

mod can_sensors;
mod outputs;
mod provenance;
mod withholding;

use can_sensors::{CanRoute, CanSensors};
use outputs::{copy_channel, register_outputs, Output, TrackOutput};

pub struct RefuseOptions<'a> {
    /// The run to re-fuse: one file, or every file that holds it.
    pub run: &'a Run,
    pub output: &'a Path,
    pub config: &'a Pipelines,
    /// Where the configuration came from (a path, or "embedded default"), for the metadata.
    pub config_source: String,
    /// The reference of the accuracy evaluation made in the same pass.
    pub reference: &'a Reference,
    /// A sensor hidden from every pipeline that fuses it, in outages (the withholding
    /// protocol); over the pipelines' own `[pipeline.eval]`.
    pub withhold: Option<&'a Withhold>,
    /// Told the bytes of the input read so far, as the replay goes.
    pub progress: Option<&'a (dyn Fn(u64) + Sync)>,
    /// Told every message the replay reads (the pipelines' sensors, the reference, the map,
    /// the events) or writes (fused states, diagnostics, smoothed states), as it goes: a live
    /// view of the re-fusion.
    pub observer: Option<Observer<'a>>,
}

/// Called with a message's topic, schema name, log time (ns) and JSON payload.
pub type Observer<'a> = &'a (dyn Fn(&str, &str, u64, &[u8]) + Sync);

/// Tells the observer, if there is one, about a message this run writes.
fn observe<M: ChannelMessage>(
    observer: Option<Observer<'_>>,
    topic: &str,
    log_time_ns: u64,
    m: &M,
) {
    if let Some(observe) = observer {
        if let Ok(json) = serde_json::to_vec(m) {
            observe(topic, M::SCHEMA_NAME, log_time_ns, &json);
        }
    }
}

/// What the replay reads a message as.
enum Read {
    AsItIs,
    /// A foreign message translated to railfuse's JSON.
    As(Vec<u8>),
    /// Nothing to read (skipped, or not translatable: counted).
    Skip,
}

#[derive(Debug, Clone, Serialize)]
pub struct PipelineReport {
    pub name: String,
    pub counts: PipelineCounts,
    pub fused_states: u64,
    pub smoothed_states: u64,
    /// The kind's own line (`gnss_ins`: the GNSS quality gate's decisions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RefuseReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_messages: u64,
    pub input_bytes: u64,
    pub fused_messages: u64,
    /// What merging the run's files did (one file: nothing).
    pub merge: MergeCounts,
    /// Messages whose log time is earlier than the one before them in the file.
    pub out_of_order_messages: u64,
    /// Sensor messages the pipelines read that did not decode: skipped (copied unchanged),
    /// counted by topic and cause, the first of each said.
    pub undecodable: Rejections,
    /// Sensors left out because the log lacks their channel, each said as a warning.
    pub missing_sensors: BTreeSet<String>,
    /// Foreign messages read and not measurements (a NavSatFix of status NO_FIX), by reason.
    pub skipped: BTreeMap<String, u64>,
    /// Foreign topics whose messages carried no time of their own (a zero `header.stamp`):
    /// they took the log time.
    pub stamped_by_log_time: BTreeSet<String>,
    /// Messages of a withheld sensor each pipeline was not shown, by pipeline.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub withheld: BTreeMap<String, u64>,
    /// What the sensors made from the CAN bus made, and what of the bus they could not read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub can: Option<railfuse_catalog::foreign::can::BridgeCounts>,
    /// An IMU was fused on a track map without heights, which is then flat (said once).
    pub flat_track: bool,
    pub pipelines: Vec<PipelineReport>,
}

/// What to do with the messages of one input channel.
#[derive(Default)]
struct Route {
    /// Dropped: an earlier run's output of a pipeline being re-run.
    replaced: bool,
    /// The track map (for GNSS map matching) or the events channel (device fault reports).
    context: Option<ContextKind>,
    /// (pipeline, sensor index) pairs fed by this channel, and how to read it.
    sensors: Vec<(usize, usize)>,
    model: Option<SensorModel>,
    /// A foreign channel (a ROS 2 bag's): read as the catalogue kind it translates to.
    translator: Option<Translator>,
    /// The evaluation reads it (reference, track map, events, kept fused channels).
    evaluated: bool,
    /// CAN frames, which the configuration's CAN sensors are made from.
    can_frames: bool,
}

#[derive(Clone, Copy)]
enum ContextKind {
    TrackMap,
    /// The log's installation drawing, unless the configuration has a `[vehicle]`.
    Vehicle,
    Events,
}

/// The shortest interval between two Foxglove positions of one pipeline.
const LOCATION_TWIN_EVERY_NS: u64 = 100_000_000;

/// Replays `opts.input` through the pipelines into `opts.output` and evaluates the result
/// against `opts.reference` in the same pass.
pub fn refuse(opts: &RefuseOptions<'_>) -> Result<(RefuseReport, EvalReport)> {
    let partial = railfuse_catalog::log::partial_path(opts.output);
    let ours = !partial.exists();
    let result = refuse_into(opts);
    // A failed run leaves no half output of its own (the input is untouched and the run can
    // be redone); a .partial that was there before is someone else's and stays.
    if result.is_err() && ours {
        let _ = std::fs::remove_file(&partial);
    }
    result
}

fn refuse_into(opts: &RefuseOptions<'_>) -> Result<(RefuseReport, EvalReport)> {
    let parts = opts.run.parts().iter().map(|p| p.path.clone()).collect();
    let digest = provenance::InputDigest::start(parts);
    let mut replay = match (opts.run.single_file(), opts.run.sequential_files()?) {
        (Some(file), _) => read_file(opts, file)?,
        (None, Some(run)) => read_files(opts, run)?,
        (None, None) => read_run(opts)?,
    };
    replay.input_sha256 = Some(digest.finish()?);
    replay.finish()
}

/// A run that is one file, read chunk by chunk: a chunk that holds no replaced channel is
/// copied to the output byte for byte.
fn read_file<'a>(opts: &'a RefuseOptions<'a>, file: &Path) -> Result<Replay<'a>> {
    let mut replay = Replay::new(opts, read_summary(file)?)?;
    let items = ReadAhead::new(Scanner::open(file)?, READ_AHEAD_BYTES);
    replay.report.input_bytes = replay.read_chunks(items, &[file])?;
    Ok(replay)
}

/// A split run whose parts follow one another with the same ids
/// ([`Run::sequential_files`]): the parts read chunk by chunk, one after the other, as one
/// file is.
fn read_files<'a>(opts: &'a RefuseOptions<'a>, run: Sequential<'_>) -> Result<Replay<'a>> {
    let mut replay = Replay::new(opts, Some(run.summary))?;
    let items = ReadAhead::files(&run.files, READ_AHEAD_BYTES)?;
    replay.report.input_bytes = replay.read_chunks(items, &run.files)?;
    replay.report.merge.parts_read = run.files.len();
    Ok(replay)
}

/// A run of several files (or one read on another clock or time basis), merged by time:
/// every record is written again under the run's ids.
fn read_run<'a>(opts: &'a RefuseOptions<'a>) -> Result<Replay<'a>> {
    let mut reader = opts.run.reader()?;
    let mut replay = Replay::new(opts, reader.summary().cloned())?;
    let mut count = 0u64;
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Schema(s) => replay.schema_info(s, true)?,
            LogRecord::Channel(c) => replay.channel_info(c, true).map(|_| ())?,
            LogRecord::Message(m) => {
                let view = format::MessageView {
                    header: mcap::records::MessageHeader {
                        channel_id: m.channel.id,
                        sequence: m.sequence,
                        log_time: m.log_time_ns,
                        publish_time: m.publish_time_ns,
                    },
                    data: m.data,
                };
                if replay.message(&view)? {
                    replay.writer.copy_message(&view)?;
                }
            }
            LogRecord::Metadata { name, metadata } => replay.metadata(name, metadata)?,
            LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data,
            } => replay
                .writer
                .attach(&name, &media_type, log_time_ns, create_time_ns, data)?,
        }
        count += 1;
        if let Some(progress) = opts.progress.filter(|_| count.is_multiple_of(4096)) {
            progress(reader.bytes_read());
        }
    }
    replay.report.input_bytes = reader.bytes_read();
    replay.report.merge = reader.counts().clone();
    Ok(replay)
}

impl RefuseReport {
    /// The report of a run from `input` to `output` before anything is read.
    fn new(input: &Path, output: &Path) -> Self {
        RefuseReport {
            input: input.to_owned(),
            output: output.to_owned(),
            input_messages: 0,
            input_bytes: 0,
            fused_messages: 0,
            merge: MergeCounts::default(),
            out_of_order_messages: 0,
            undecodable: Rejections::default(),
            missing_sensors: BTreeSet::new(),
            skipped: BTreeMap::new(),
            stamped_by_log_time: BTreeSet::new(),
            withheld: BTreeMap::new(),
            can: None,
            flat_track: false,
            pipelines: Vec::new(),
        }
    }
}

/// One `refuse` run in progress.
struct Replay<'a> {
    opts: &'a RefuseOptions<'a>,
    /// The input file's SHA-256 (hex), known once the input is read.
    input_sha256: Option<String>,
    /// The pipelines being run, whose earlier outputs the input may hold.
    names: BTreeSet<String>,
    writer: LogWriter,
    pipelines: Vec<AnyPipeline>,
    outputs: Vec<Output>,
    context: SensorContext,
    schemas: IdMap<Arc<SchemaInfo>>,
    channels: IdMap<Arc<ChannelInfo>>,
    /// Each channel as the input has it (a foreign channel's encoding and schema), which the
    /// output copies: `channels` holds what it is read as.
    originals: IdMap<Arc<ChannelInfo>>,
    routes: IdMap<Route>,
    /// For a ROS 2 input, each pipeline's state also as NavSatFix and Odometry in CDR
    /// (registered when the first CDR channel is met).
    ros_outputs: Vec<(ChannelId, ChannelId)>,
    /// The configuration's track, written once as `/track/map` before the first message of
    /// an input that has none, so that the output shows (and re-fuses on) the track it was
    /// fused on.
    track_output: Option<TrackOutput>,
    track_written: bool,
    /// The sensors were checked against the summary's channels.
    bound_checked: bool,
    seen_topics: BTreeSet<String>,
    eval: Evaluator,
    measurements: Vec<Measurement>,
    fused: Vec<Fused>,
    report: RefuseReport,
    last_log_time: u64,
    /// The file being read chunk by chunk (a part of a split run), for messages about it.
    reading: Option<PathBuf>,
    withholding: Withholding,
    /// The sensors the configuration makes from the CAN bus.
    can: Option<CanSensors>,
}

impl<'a> Replay<'a> {
    /// Checks the pipelines against the file's channels (when it has a summary), opens the
    /// output and registers the fused channels.
    fn new(opts: &'a RefuseOptions<'a>, summary: Option<LogSummary>) -> Result<Self> {
        let input = opts.run.name();
        let names: BTreeSet<String> = opts.config.names().map(str::to_owned).collect();
        let known = summary.as_ref().and_then(|s| s.channels.as_ref());
        let mut writer = LogWriter::create(opts.output)?;
        // Fused states of kept pipelines may trail the reference by a chunk in file order.
        let lag = eval::lag_allowance_s(summary.as_ref().and_then(|s| s.longest_chunk_ns));
        let mut eval = Evaluator::new(opts.output, opts.reference, lag);
        let (outputs, track_output, can) =
            register_outputs(opts, known.map(Vec::as_slice), &mut writer, &mut eval)?;
        let withholding = Withholding::resolve(
            input,
            &opts.config.pipeline,
            opts.withhold,
            summary.as_ref().and_then(|s| s.message_span_ns),
            known.map(Vec::as_slice),
        )?;
        withholding.record(&opts.config.pipeline, &mut writer, &mut eval)?;
        let pipelines = opts
            .config
            .pipeline
            .iter()
            .cloned()
            .map(AnyPipeline::new)
            .collect::<Result<_>>()?;
        let mut replay = Self {
            input_sha256: None,
            opts,
            names,
            writer,
            pipelines,
            outputs,
            // The configuration's track until the log brings its own.
            context: SensorContext {
                track: opts.config.track.clone(),
                vehicle: opts
                    .config
                    .vehicle
                    .clone()
                    .unwrap_or_else(railfuse_catalog::messages::Vehicle::point),
                whereabouts: None,
            },
            schemas: IdMap::default(),
            channels: IdMap::default(),
            originals: IdMap::default(),
            routes: IdMap::default(),
            ros_outputs: Vec::new(),
            track_output,
            track_written: false,
            bound_checked: false,
            seen_topics: BTreeSet::new(),
            eval,
            measurements: Vec::new(),
            fused: Vec::new(),
            report: RefuseReport::new(input, opts.output),
            last_log_time: 0,
            reading: None,
            withholding,
            can,
        };
        // With a summary, every sensor is bound to its channel before anything is read.
        if let Some(channels) = known {
            for c in channels {
                replay.route(c.clone())?;
            }
            replay.check_every_sensor_bound(channels)?;
            replay.bound_checked = true;
        }
        Ok(replay)
    }

    /// The reference is a channel this run writes (another pipeline's state).
    fn reference_is_ours(&self) -> bool {
        self.is_replaced(&self.opts.reference.topic)
    }

    /// An earlier run's output of a pipeline this run re-runs: its fused channels and their
    /// Foxglove twins.
    fn is_replaced(&self, topic: &str) -> bool {
        let own = topic
            .strip_prefix(railfuse_catalog::foxglove::TOPIC_PREFIX)
            .unwrap_or(topic);
        topics::fused_pipeline_of(own).is_some_and(|n| self.names.contains(n))
    }

    /// Reads `files` chunk by chunk into the replay, as `items` hands them over; the bytes
    /// read.
    fn read_chunks(&mut self, mut items: ReadAhead, files: &[&Path]) -> Result<u64> {
        while let Some(item) = items.next() {
            if self.reading.as_deref() != files.get(items.file()).copied() {
                self.reading = files.get(items.file()).map(|p| p.to_path_buf());
            }
            if let Some(progress) = self.opts.progress {
                progress(items.position());
            }
            match item? {
                Item::Chunk(chunk) => items.recycle(self.chunk(chunk)?),
                Item::Record { opcode, body, .. } => self.top_level(opcode, &body)?,
                Item::Damage(_) => unreachable!("a strict scanner reports damage as an error"),
            }
        }
        Ok(items.position())
    }

    /// An input chunk: its messages go to the pipelines and the evaluation; the chunk itself
    /// is copied byte for byte unless it holds a replaced channel, and the fused records it
    /// gave rise to follow it in a chunk of their own. Returns its records buffer, to reuse.
    fn chunk(&mut self, chunk: Chunk) -> Result<Vec<u8>> {
        let mut rewrite = false;
        let mut tally = ChunkTally::default();
        for record in Records::new(&chunk.records) {
            let record = record.map_err(|e| self.damaged(chunk.offset, e))?;
            match record.opcode {
                op::SCHEMA => self.schema(record.body, false)?,
                op::CHANNEL => rewrite |= !self.channel(record.body, false)?,
                op::MESSAGE => {
                    let m = format::parse_message(record.body).ok_or_else(|| {
                        self.damaged(chunk.offset, "a message record is cut short".into())
                    })?;
                    rewrite |= !self.message(&m)?;
                    tally.message(record.offset, &m.header);
                    continue;
                }
                _ => {}
            }
            tally.record(&record);
        }
        let records = if rewrite {
            self.rewrite(&chunk)?;
            chunk.records
        } else {
            self.writer.copy_tallied_chunk(chunk, tally)?
        };
        self.writer.close_chunk()?;
        Ok(records)
    }

    /// Writes a chunk's records but those of replaced channels.
    fn rewrite(&mut self, chunk: &Chunk) -> Result<()> {
        let routes = &self.routes;
        self.writer.copy_records_where(&chunk.records, |id| {
            routes.get(&id).is_some_and(|r| !r.replaced)
        })?;
        Ok(())
    }

    /// A record outside chunks.
    fn top_level(&mut self, opcode: u8, body: &[u8]) -> Result<()> {
        match opcode {
            op::SCHEMA => self.schema(body, true),
            op::CHANNEL => self.channel(body, true).map(|_| ()),
            op::MESSAGE => {
                let m = format::parse_message(body)
                    .ok_or_else(|| self.damaged(0, "a message record is cut short".into()))?;
                if self.message(&m)? {
                    self.writer.copy_message(&m)?;
                }
                Ok(())
            }
            op::METADATA | op::ATTACHMENT => match mcap::parse_record(opcode, body) {
                Ok(mcap::records::Record::Metadata(m)) => self.metadata(m.name, m.metadata),
                Ok(mcap::records::Record::Attachment {
                    header: h, data, ..
                }) => Ok(self.writer.attach(
                    &h.name,
                    &h.media_type,
                    h.log_time,
                    h.create_time,
                    &data,
                )?),
                Ok(_) => Ok(()),
                Err(e) => Err(self.damaged(0, e.to_string())),
            },
            _ => Ok(()),
        }
    }

    /// A metadata record: copied, unless it is the configuration of a pipeline this run
    /// re-runs (which writes its own).
    fn metadata(&mut self, name: String, metadata: BTreeMap<String, String>) -> Result<()> {
        let replaced = name == topics::metadata::PIPELINE
            && metadata
                .get("pipeline")
                .is_some_and(|p| self.names.contains(p));
        if !replaced {
            self.eval.metadata(&name, &metadata);
            self.writer.write_metadata(&name, metadata)?;
        }
        Ok(())
    }

    /// The run's name, for messages.
    fn input(&self) -> &'a Path {
        self.opts.run.name()
    }

    fn damaged(&self, offset: u64, cause: String) -> Error {
        Error::Log(railfuse_catalog::Error::Damaged {
            path: self.reading.as_deref().unwrap_or(self.input()).to_owned(),
            offset,
            cause,
        })
    }

    fn schema(&mut self, body: &[u8], top_level: bool) -> Result<()> {
        let Ok(mcap::records::Record::Schema { header, data }) =
            mcap::parse_record(op::SCHEMA, body)
        else {
            return Err(self.damaged(0, "a schema record does not parse".into()));
        };
        if self.schemas.contains_key(&header.id) {
            return Ok(());
        }
        let info = SchemaInfo {
            id: header.id,
            name: header.name,
            encoding: header.encoding,
            data: data.into_owned(),
        };
        self.schema_info(Arc::new(info), top_level)
    }

    /// Takes in a schema (written to the output when outside a copied chunk).
    fn schema_info(&mut self, info: Arc<SchemaInfo>, top_level: bool) -> Result<()> {
        if self.schemas.contains_key(&info.id) {
            return Ok(());
        }
        if top_level {
            self.writer
                .copy_schema(info.id, &info.name, &info.encoding, &info.data)?;
        }
        self.schemas.insert(info.id, info);
        Ok(())
    }

    /// Routes a channel; false when it is replaced (its records are left out).
    fn channel(&mut self, body: &[u8], top_level: bool) -> Result<bool> {
        let Ok(mcap::records::Record::Channel(c)) = mcap::parse_record(op::CHANNEL, body) else {
            return Err(self.damaged(0, "a channel record does not parse".into()));
        };
        // Routed already when the summary listed it.
        let info = match self.channels.get(&c.id) {
            Some(info) => info.clone(),
            None => {
                let schema = match c.schema_id {
                    0 => None,
                    id => Some(self.schemas.get(&id).cloned().ok_or_else(|| {
                        self.damaged(0, format!("channel {} names unknown schema {id}", c.topic))
                    })?),
                };
                Arc::new(ChannelInfo {
                    id: c.id,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                    metadata: c.metadata,
                    schema,
                })
            }
        };
        self.channel_info(info, top_level)
    }

    /// Routes a channel met in the input (written to the output when outside a copied chunk);
    /// false when it is replaced.
    fn channel_info(&mut self, info: Arc<ChannelInfo>, top_level: bool) -> Result<bool> {
        // Routed already when the summary listed it: that one carries its schema.
        let info = self.channels.get(&info.id).cloned().unwrap_or(info);
        let kept = self.route(info.clone())?;
        if kept && top_level {
            let original = self.originals.get(&info.id).cloned().unwrap_or(info);
            copy_channel(&mut self.writer, &original)?;
        }
        Ok(kept)
    }

    /// Decides what to do with a channel's messages, binding the pipelines' sensors that read
    /// it; false when it is replaced. Each channel is routed once.
    fn route(&mut self, info: Arc<ChannelInfo>) -> Result<bool> {
        if let Some(route) = self.routes.get(&info.id) {
            return Ok(!route.replaced);
        }
        self.originals.insert(info.id, info.clone());
        if info.message_encoding == ros2::ENCODING && self.ros_outputs.is_empty() {
            self.register_ros_outputs()?;
        }
        let mut route = Route {
            replaced: self.is_replaced(&info.topic),
            ..Route::default()
        };
        if !route.replaced && !self.is_made(&info) {
            match self.route_can(&info)? {
                CanRoute::MadeBefore => route.replaced = true,
                CanRoute::Frames => route.can_frames = true,
                CanRoute::Other => {}
            }
        }
        if !route.replaced {
            let info = match self.translator(&info)? {
                Some(t) => {
                    let read_as = t.channel(&info);
                    route.translator = Some(t);
                    read_as
                }
                None => info.clone(),
            };
            self.seen_topics.insert(info.topic.clone());
            let schema = info.schema_name();
            route.context = match schema {
                n if n == TrackMap::SCHEMA_NAME => Some(ContextKind::TrackMap),
                n if n == railfuse_catalog::messages::Vehicle::SCHEMA_NAME => {
                    Some(ContextKind::Vehicle)
                }
                n if n == Event::SCHEMA_NAME => Some(ContextKind::Events),
                _ => None,
            };
            route.evaluated = self.eval.channel(info.id, &info.topic, schema);
            let input = self.input();
            for (pi, p) in self.pipelines.iter_mut().enumerate() {
                if let Some(si) = p.spec().sensor_for(&info.topic) {
                    let binding = p.spec().bind(input, si, schema)?;
                    p.bind(si, &binding);
                    route.sensors.push((pi, si));
                    route.model = Some(binding.model);
                }
            }
            self.channels.insert(info.id, info);
        }
        let kept = !route.replaced;
        self.routes.insert(info.id, route);
        self.channels.entry(info.id).or_insert(info);
        Ok(kept)
    }

    /// How the pipelines' sensors on a foreign channel read it (`None`: a channel of
    /// railfuse's own, or one nothing reads). The sensors on one topic must agree on its role.
    fn translator(&self, info: &ChannelInfo) -> Result<Option<Translator>> {
        let sensors: Vec<(&AnyPipeline, usize)> = self
            .pipelines
            .iter()
            .filter_map(|p| Some((p, p.spec().sensor_for(&info.topic)?)))
            .collect();
        // Only what a pipeline reads, or the accuracy table's reference, is translated
        // (railfuse's own Foxglove twins pass as they are).
        let Some(&(first, first_si)) = sensors.first() else {
            let reference = info.topic == self.opts.reference.topic && info.kind().is_none();
            return Ok(reference
                .then(|| Translator::for_channel(info, None).ok().flatten())
                .flatten());
        };
        let role = first.spec().sensors[first_si].role;
        for (p, si) in &sensors {
            if p.spec().sensors[*si].role != role {
                let problem =
                    format!("is read with another role by an earlier pipeline ({role:?})");
                return Err(p.spec().channel_error(self.input(), *si, problem));
            }
        }
        Translator::for_channel(info, role)
            .map_err(|why| first.spec().channel_error(self.input(), first_si, why))
    }

    /// Every sensor of every pipeline has met its channel, or is said missing (an error for
    /// a required one, or for a pipeline left with none); `channels` are the log's, named in
    /// the message.
    fn check_every_sensor_bound(&mut self, channels: &[Arc<ChannelInfo>]) -> Result<()> {
        let have: Vec<&str> = channels
            .iter()
            .map(|c| c.topic.as_str())
            .filter(|t| !t.starts_with(topics::FUSED_PREFIX))
            .collect();
        for p in &self.opts.config.pipeline {
            let missing: Vec<usize> = (0..p.sensors.len())
                .filter(|&si| !self.seen_topics.contains(&p.sensors[si].topic))
                .collect();
            for &si in &missing {
                let warning = p.missing_channel(self.input(), si, &have)?;
                self.report.missing_sensors.insert(warning);
            }
            if !p.sensors.is_empty() && missing.len() == p.sensors.len() {
                return Err(p.channel_error(
                    self.input(),
                    0,
                    "is not in the file, nor is any other channel of the pipeline".into(),
                ));
            }
        }
        Ok(())
    }

    /// A pipeline that takes chainage from GNSS fixes had a track to match them on: from the
    /// log or from the configuration.
    fn check_track_for_chainage(&self) -> Result<()> {
        if self.context.track.is_some() {
            return Ok(());
        }
        for route in self.routes.values() {
            if route.model != Some(SensorModel::GnssFix) {
                continue;
            }
            for &(pi, si) in &route.sensors {
                let p = &self.pipelines[pi];
                let fields = &p.spec().sensors[si].fields;
                let chainage = fields
                    .as_ref()
                    .is_none_or(|f| f.contains(&Quantity::Chainage));
                if !matches!(p, AnyPipeline::Messages(..)) && chainage {
                    return Err(p.spec().channel_error(
                        self.input(),
                        si,
                        "gives chainage only on a track map, and neither the log (no /track/map) \
                         nor the configuration has one: name a GeoJSON line at its top with \
                         track = \"line.geojson\""
                            .into(),
                    ));
                }
            }
        }
        Ok(())
    }

    /// One input message: context, evaluation, pipelines. False when it is left out
    /// (a replaced channel's).
    fn message(&mut self, m: &format::MessageView<'_>) -> Result<bool> {
        let h = m.header;
        let Some(route) = self.routes.get(&h.channel_id) else {
            return Err(self.damaged(
                0,
                format!(
                    "message at log time {} on unknown channel {}",
                    h.log_time, h.channel_id
                ),
            ));
        };
        if route.replaced {
            return Ok(false);
        }
        let (context, model, evaluated) = (route.context, route.model, route.evaluated);
        let can_frames = route.can_frames;
        self.arrived(h.log_time)?;
        if context.is_none() && model.is_none() && !evaluated && !can_frames {
            return Ok(true); // passes through untouched
        }
        let channel = self.channels[&h.channel_id].clone();
        let translated = match self.translate(&channel, h.channel_id, m) {
            Read::AsItIs => None,
            Read::As(data) => Some(data),
            Read::Skip => return Ok(true),
        };
        let msg = LogMessage {
            channel: &channel,
            sequence: h.sequence,
            log_time_ns: h.log_time,
            publish_time_ns: h.publish_time,
            data: translated.as_deref().unwrap_or(m.data),
        };
        if let Some(observe) = self.opts.observer {
            // The observer takes JSON: a protobuf message of a railfuse type is given as its
            // JSON form.
            let json = match channel.message_encoding == Encoding::Protobuf.message_encoding() {
                true => msg.decode_any(self.input())?.map(|any| any.to_json()),
                false => None,
            };
            let data = json.as_deref().unwrap_or(m.data);
            observe(&channel.topic, channel.schema_name(), h.log_time, data);
        }
        if evaluated {
            self.eval.message(&msg)?;
        }
        self.context_message(context, &msg)?;
        if can_frames {
            self.can_frame(&msg)?;
        }
        self.sensor_message(h.channel_id, &msg).map(|()| true)
    }

    /// A message of a channel the pipelines read: its measurements decoded and fed to each
    /// pipeline sensor on it. One that does not decode (a null where a number belongs) is
    /// skipped and counted: one bad message must not cost the whole replay.
    fn sensor_message(&mut self, id: u16, msg: &LogMessage<'_>) -> Result<()> {
        let Some(model) = self.routes.get(&id).and_then(|r| r.model) else {
            return Ok(());
        };
        let input = self.input();
        if model == SensorModel::ImuAcceleration {
            self.say_if_flat();
        }
        if let Err(e) = model.decode(msg, input, &self.context, &mut self.measurements) {
            self.report
                .undecodable
                .add(&msg.channel.topic, "decode", || e.to_string());
            return Ok(());
        }
        self.feed(id, msg)
    }

    /// Says once that the track map an IMU is fused on has no heights: the line is taken as
    /// flat, and no gradient's gravity is taken out of the IMU's acceleration.
    fn say_if_flat(&mut self) {
        let Some(map) = self.context.track.as_ref() else {
            return;
        };
        if self.report.flat_track || map.has_heights() {
            return;
        }
        self.report.flat_track = true;
        eprintln!(
            "{}: the track map '{}' has no heights: the line is taken as flat (no gradient's \
             gravity is taken out of the IMU)",
            self.input().display(),
            map.name
        );
    }

    /// Counts a message read, and writes the configuration's track before the first.
    fn arrived(&mut self, log_time: u64) -> Result<()> {
        if let (Some(out), Some(track), false) = (
            self.track_output,
            &self.opts.config.track,
            self.track_written,
        ) {
            out.write(&mut self.writer, log_time, track)?;
            self.track_written = true;
        }
        self.report.input_messages += 1;
        if log_time < self.last_log_time {
            self.report.out_of_order_messages += 1;
        }
        self.last_log_time = self.last_log_time.max(log_time);
        self.eval.log_time(log_time);
        Ok(())
    }

    /// A foreign message read as its catalogue kind's railfuse message; one that does not
    /// translate is counted, not fatal.
    fn translate(&mut self, channel: &ChannelInfo, id: u16, m: &format::MessageView<'_>) -> Read {
        let Some(t) = &self.routes[&id].translator else {
            return Read::AsItIs;
        };
        let log_time = m.header.log_time;
        match t.translate(m.data, log_time) {
            Ok(Translated::Message {
                message,
                took_log_time,
            }) => {
                if took_log_time
                    && self
                        .report
                        .stamped_by_log_time
                        .insert(channel.topic.clone())
                {
                    eprintln!(
                        "{}: {}: messages carry no header.stamp: their log time is used",
                        self.input().display(),
                        channel.topic
                    );
                }
                Read::As(message.to_json())
            }
            Ok(Translated::Skipped(reason)) => {
                *self.report.skipped.entry(reason.to_owned()).or_insert(0) += 1;
                Read::Skip
            }
            Err(e) => {
                self.report.undecodable.add(&channel.topic, e.kind(), || {
                    format!("{}: log time {} ns: {e}", channel.topic, log_time)
                });
                Read::Skip
            }
        }
    }

    /// The track map, or a device's own fault report, which the pipelines act on.
    fn context_message(&mut self, kind: Option<ContextKind>, msg: &LogMessage<'_>) -> Result<()> {
        let input = self.input();
        match kind {
            Some(ContextKind::TrackMap) => self.context.track = Some(msg.decode(input)?),
            Some(ContextKind::Vehicle) if self.opts.config.vehicle.is_none() => {
                let v: railfuse_catalog::messages::Vehicle = msg.decode(input)?;
                v.check()
                    .map_err(|e| Error::Map(format!("{}: /vehicle: {e}", input.display())))?;
                self.context.vehicle = v;
            }
            Some(ContextKind::Vehicle) => {}
            Some(ContextKind::Events) => {
                let e: Event = msg.decode(input)?;
                let failed = match e.kind {
                    EventKind::DeviceFault => Some(true),
                    EventKind::DeviceRecovered => Some(false),
                    _ => None,
                };
                if let Some(failed) = failed {
                    self.pipelines
                        .iter_mut()
                        .for_each(|p| p.device_event(&e.text, failed));
                }
            }
            None => {}
        }
        Ok(())
    }

    /// A sensor message (its measurements decoded) to every pipeline sensor it feeds.
    fn feed(&mut self, id: u16, msg: &LogMessage<'_>) -> Result<()> {
        let input = self.input();
        let sensors = std::mem::take(&mut self.routes.get_mut(&id).expect("routed").sensors);
        let result = (|| {
            for &(pi, si) in &sensors {
                if self
                    .withholding
                    .hides(pi, &msg.channel.topic, msg.log_time_ns)
                {
                    continue;
                }
                match self.pipelines[pi].as_message_pipeline() {
                    // A pipeline in the plane reads the whole message.
                    Some(p) => {
                        if let Err(e) = p.push(si, msg, input, &self.context, &mut self.fused) {
                            self.report
                                .undecodable
                                .add(&msg.channel.topic, "decode", || e.to_string());
                        }
                    }
                    None => {
                        let log_time = msg.log_time_ns;
                        self.pipelines[pi].push(si, &self.measurements, log_time, &mut self.fused)
                    }
                }
                self.emit(pi)?;
            }
            Ok(())
        })();
        self.routes.get_mut(&id).expect("routed").sensors = sensors;
        result
    }

    /// Flushes the pipelines, writes smoothed states and each pipeline's metadata, closes the
    /// output and finishes the evaluation.
    fn finish(mut self) -> Result<(RefuseReport, EvalReport)> {
        // Without a summary, the channels are known only now.
        if !self.bound_checked {
            self.check_every_sensor_bound(&[])?;
        }
        self.check_track_for_chainage()?;
        self.report.can = self.can.as_ref().map(|c| c.counts().clone());
        for pi in 0..self.pipelines.len() {
            self.pipelines[pi].finish(self.last_log_time, &self.context, &mut self.fused);
            self.emit(pi)?;
            self.write_smoothed(pi)?;
            let p = &self.pipelines[pi];
            let metadata = BTreeMap::from([
                ("pipeline".to_owned(), p.name().to_owned()),
                ("filter".to_owned(), p.spec().estimator.name().to_owned()),
                ("config_toml".to_owned(), p.spec().to_toml()),
                (
                    "config_source".to_owned(),
                    provenance::file_name(&self.opts.config_source),
                ),
                ("input".to_owned(), provenance::run_name(self.opts.run)),
                (
                    "input_sha256".to_owned(),
                    self.input_sha256.clone().unwrap_or_default(),
                ),
                (
                    "tool_version".to_owned(),
                    concat!("railfuse ", env!("CARGO_PKG_VERSION")).to_owned(),
                ),
                (
                    "counts".to_owned(),
                    serde_json::to_string(p.counts()).expect("counts serialise"),
                ),
            ]);
            self.eval.metadata(topics::metadata::PIPELINE, &metadata);
            self.writer
                .write_metadata(topics::metadata::PIPELINE, metadata)?;
        }
        // Smoothed states not scored on the way are in the input beside its reference, unless
        // the reference is this run's own output.
        let output = Run::file(self.opts.output);
        let log = match self.reference_is_ours() {
            true => &output,
            false => self.opts.run,
        };
        self.writer.finish()?;
        for (pi, (p, out)) in self.pipelines.iter().zip(&self.outputs).enumerate() {
            if self.withholding.of(pi).is_some() {
                let hidden = self.withholding.hidden[pi];
                self.report.withheld.insert(p.name().to_owned(), hidden);
            }
            self.report.pipelines.push(PipelineReport {
                name: p.name().to_owned(),
                counts: p.counts().clone(),
                fused_states: out.states,
                smoothed_states: out.smoothed_states,
                report: p.report(),
            });
        }
        let eval = self.eval.finish(log)?;
        Ok((self.report, eval))
    }
}
