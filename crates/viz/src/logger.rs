//! Turns railfuse messages into Rerun entities: one streaming pass over a file
//! ([`visualize`]), or message by message while recording or re-fusing ([`LiveViz`]).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use railfuse_catalog::foreign::{Role, Translated, Translator};
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::{ChannelInfo, LogMessage, LogReader, LogRecord, SchemaInfo};
use railfuse_catalog::messages::fused::CHI2_95_1DOF;
use railfuse_catalog::messages::*;
use railfuse_catalog::reference_track::{ReferenceSample, ReferenceTrack};
use railfuse_catalog::topics::{self, FusedChannel};
use rerun::components::{AggregationPolicy, InterpolationMode, MarkerShape, TextLogLevel};
use rerun::{Color, Points2D, Radius, RecordingStream, SeriesLines, SeriesPoints, TextLog};

use crate::blueprint::{Layout, PipelineLayout, NIS_AXIS_MAX};
use crate::series::{Columns, Decimation, OutlinesId, PointsId, SegmentsId, SeriesId, TIMELINE};
use crate::{entities as ent, map, palette, Error};

/// Where the recording goes.
#[derive(Debug, Clone)]
pub enum Sink {
    /// An `.rrd` file.
    Save(PathBuf),
    /// A running viewer, e.g. `rerun+http://127.0.0.1:9876/proxy`.
    Connect(String),
    /// Start a viewer (the `rerun` binary on PATH) and stream to it.
    Spawn,
}

impl Sink {
    /// A live view as `--viz` names one: `spawn`, or a viewer's URL.
    pub fn live(target: &str) -> Sink {
        match target {
            "spawn" => Sink::Spawn,
            url => Sink::Connect(url.to_owned()),
        }
    }
}

/// What to show, and how densely.
#[derive(Debug, Clone, Default)]
pub struct VizOptions {
    /// Seconds from the log's first message: nothing earlier is shown.
    pub from_s: Option<f64>,
    /// Seconds from the log's first message: nothing later is shown.
    pub to_s: Option<f64>,
    /// Raw topics to show (empty: all). The track map and the truth are always read: the
    /// errors are measured against them.
    pub topics: Vec<String>,
    /// Pipelines to show (empty: all).
    pub pipelines: Vec<String>,
    /// Keep every sample however long the run.
    pub full_rate: bool,
}

/// Runs longer than this are decimated unless `full_rate` is asked for: a screen shows a
/// half-hour run's 100 Hz series as a blur of ~180 000 samples per plot either way.
pub const DECIMATE_AFTER_S: f64 = 1800.0;

/// Bins a decimated run is cut into: a min/max pair per bin is at least one per pixel column
/// of a 4K-wide plot.
pub const SCREEN_BINS: u64 = 4096;

/// The true path on the map keeps a point a second: a trail, not a plot.
const TRAIL_EVERY_NS: u64 = 1_000_000_000;

/// How often live views send what they have buffered.
const LIVE_FLUSH: Duration = Duration::from_millis(250);

impl VizOptions {
    /// Full rate, or bins sized to the run (`span_ns`: first to last message).
    pub fn decimation(&self, span_ns: Option<u64>) -> Decimation {
        match span_ns {
            Some(span) if !self.full_rate && span as f64 / 1e9 > DECIMATE_AFTER_S => {
                Decimation::Bins {
                    bin_ns: span.div_ceil(SCREEN_BINS),
                }
            }
            _ => Decimation::Full,
        }
    }

    fn shows_topic(&self, topic: &str) -> bool {
        self.topics.is_empty() || self.topics.iter().any(|t| t == topic)
    }

    fn shows_pipeline(&self, pipeline: &str) -> bool {
        self.pipelines.is_empty() || self.pipelines.iter().any(|p| p == pipeline)
    }
}

#[derive(Debug, Clone, Default)]
pub struct VizReport {
    pub messages: u64,
    /// Rows logged to Rerun (a row can hold several values: an error and its bounds).
    pub logged: u64,
    pub entities: BTreeSet<String>,
    /// Plots were decimated to bins of this many seconds.
    pub bin_s: Option<f64>,
    /// Channels of another tool's encoding that could not be shown, by topic, with why.
    pub not_shown: BTreeMap<String, String>,
    /// Messages of foreign channels that did not decode, by topic and cause.
    pub undecodable: railfuse_catalog::rejections::Rejections,
}

/// How long to wait for a viewer to take the last of the data.
const VIEWER_TIMEOUT: Duration = Duration::from_secs(30);

/// Opens the Rerun recording stream for a sink (checking first that a viewer listens).
fn open_stream(sink: &Sink) -> Result<RecordingStream, Error> {
    if let Sink::Connect(url) = sink {
        probe_viewer(url)?;
    }
    let app = rerun::RecordingStreamBuilder::new(crate::APPLICATION_ID);
    let rec = match sink {
        Sink::Save(p) => app.save(p),
        Sink::Connect(url) => app.connect_grpc_opts(url.clone()),
        Sink::Spawn => app.spawn(),
    }
    .map_err(|e| {
        let first_line = e
            .to_string()
            .lines()
            .next()
            .unwrap_or_default()
            .trim()
            .to_owned();
        match sink {
            Sink::Spawn => Error::Rerun(format!(
                "{first_line} (the viewer comes with `pip install rerun-sdk==0.36.3`)"
            )),
            _ => Error::Rerun(first_line),
        }
    })?;
    // Our `log_time` timeline is the MCAP log time; the SDK's own wall-clock `log_time` would
    // overwrite it.
    rec.set_log_time_enabled(false);
    Ok(rec)
}

/// Logs the whole file to the sink, streaming. `progress` is told the bytes read so far.
pub fn visualize(
    path: &Path,
    sink: &Sink,
    options: &VizOptions,
    progress: &dyn Fn(u64),
) -> Result<VizReport, Error> {
    let Sink::Save(rrd) = sink else {
        return visualize_into(path, sink, options, progress);
    };
    // A recording is written beside its name and takes it only once complete: a failed run
    // (a damaged log) leaves no .rrd that opens as if it were whole.
    let mut partial = rrd.clone().into_os_string();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    if partial.exists() {
        return Err(Error::Output {
            path: partial,
            source: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "an unfinished earlier recording is in the way: move or remove it",
            ),
        });
    }
    let result = visualize_into(path, &Sink::Save(partial.clone()), options, progress);
    match &result {
        Ok(_) => std::fs::rename(&partial, rrd).map_err(|source| Error::Output {
            path: rrd.clone(),
            source,
        })?,
        Err(_) => {
            let _ = std::fs::remove_file(&partial);
        }
    }
    result
}

fn visualize_into(
    path: &Path,
    sink: &Sink,
    options: &VizOptions,
    progress: &dyn Fn(u64),
) -> Result<VizReport, Error> {
    let mut reader = LogReader::open(path)?;
    let summary = railfuse_catalog::log::read_summary(path)?;
    // Fused states may trail the truth in file order by a chunk (railfuse writes the fused
    // chunk of an input chunk right after it): the truth is kept that much longer.
    let longest_chunk_ns = summary
        .as_ref()
        .and_then(|s| s.longest_chunk_ns)
        .unwrap_or(0);
    let span = summary.as_ref().and_then(|s| s.message_span_ns);
    let mut logger = Logger::new(
        open_stream(sink)?,
        path.to_owned(),
        options.clone(),
        options.decimation(span.map(|(a, b)| b.saturating_sub(a))),
        longest_chunk_ns,
    );
    logger.start_ns = span.map(|s| s.0);
    // Pipelines in a fixed order, so each keeps its colour from run to run: refuse gives a
    // config's first pipeline the highest channel ids, so descending ids is config order.
    for c in summary
        .iter()
        .flat_map(|s| s.channels.iter().flatten().rev())
    {
        if let Some((p, FusedChannel::State)) = topics::parse_fused(&c.topic) {
            logger.pipeline(p);
        }
    }
    let streaming = !matches!(sink, Sink::Save(_));
    if streaming {
        logger.send_blueprint()?;
    }
    // How each foreign channel is read (a ROS 2 bag's, a Foxglove log's): by channel id, None
    // where it is not.
    let mut foreign: HashMap<u16, Option<(Translator, Arc<ChannelInfo>)>> = HashMap::new();
    while let Some(record) = reader.next() {
        if let LogRecord::Message(m) = record? {
            logger.report.messages += 1;
            if is_foreign(m.channel) {
                let read = foreign
                    .entry(m.channel.id)
                    .or_insert_with(|| logger.foreign_channel(m.channel));
                if let Some((t, info)) = read {
                    logger.foreign_message(t, info, &m)?;
                }
            } else {
                logger.message(&m)?;
            }
            if logger.report.messages.is_multiple_of(4096) {
                progress(reader.bytes_read());
                if streaming {
                    logger.send_blueprint_if_changed()?;
                }
            }
        }
    }
    logger.finish()?;
    // A viewer that never takes the data must not hang the command; a file always does.
    let flushed = match sink {
        Sink::Save(_) => logger.rec.flush_blocking(),
        Sink::Connect(_) | Sink::Spawn => logger.rec.flush_with_timeout(VIEWER_TIMEOUT),
    };
    flushed.map_err(|e| {
        Error::Rerun(format!(
            "the Rerun viewer did not take the data within {} s: {e}",
            VIEWER_TIMEOUT.as_secs()
        ))
    })?;
    Ok(logger.report())
}

/// Streams messages to Rerun as they are recorded or re-fused (`record --viz`,
/// `refuse --viz`): the layout of `railfuse viz`, fed one message at a time.
///
/// Dropping it finishes it (what is buffered goes out, waiting for the viewer at most 30 s).
pub struct LiveViz {
    logger: Logger,
    channels: HashMap<(String, String), Arc<ChannelInfo>>,
    last_flush: Instant,
    finished: bool,
}

impl LiveViz {
    pub fn open(sink: &Sink, options: &VizOptions) -> Result<Self, Error> {
        let mut logger = Logger::new(
            open_stream(sink)?,
            PathBuf::from("<live>"),
            options.clone(),
            Decimation::Full,
            0,
        );
        logger.send_blueprint()?;
        Ok(Self {
            logger,
            channels: Default::default(),
            last_flush: Instant::now(),
            finished: false,
        })
    }

    /// Logs one message given as its topic, schema name, log time and JSON payload.
    pub fn message(
        &mut self,
        topic: &str,
        schema: &str,
        log_time_ns: u64,
        json: &[u8],
    ) -> Result<(), Error> {
        let n = self.channels.len() as u16;
        let channel = self
            .channels
            .entry((topic.to_owned(), schema.to_owned()))
            .or_insert_with(|| {
                Arc::new(ChannelInfo {
                    id: n,
                    topic: topic.to_owned(),
                    message_encoding: "json".into(),
                    metadata: Default::default(),
                    schema: Some(Arc::new(SchemaInfo {
                        id: n,
                        name: schema.to_owned(),
                        encoding: "jsonschema".into(),
                        data: Vec::new(),
                    })),
                })
            });
        let m = LogMessage {
            channel,
            sequence: 0,
            log_time_ns,
            publish_time_ns: log_time_ns,
            data: json,
        };
        self.logger.start_ns.get_or_insert(log_time_ns);
        self.logger.report.messages += 1;
        self.logger.message(&m)?;
        if self.last_flush.elapsed() >= LIVE_FLUSH {
            self.last_flush = Instant::now();
            self.logger.columns.flush(&self.logger.rec)?;
            self.logger.send_blueprint_if_changed()?;
        }
        Ok(())
    }

    /// Sends what is buffered and the final layout, and waits (bounded) for the viewer.
    pub fn finish(&mut self) -> Result<VizReport, Error> {
        if std::mem::replace(&mut self.finished, true) {
            return Ok(self.logger.report());
        }
        self.logger.finish()?;
        self.logger
            .rec
            .flush_with_timeout(VIEWER_TIMEOUT)
            .map_err(|e| Error::Rerun(e.to_string()))?;
        Ok(self.logger.report())
    }
}

impl Drop for LiveViz {
    fn drop(&mut self) {
        // Nowhere to report to: a viewer that went away was reported when it did.
        let _ = self.finish();
    }
}

/// Series of one fused channel (a pipeline's states, or its RTS-smoothed states).
struct FusedSeries {
    speed: SeriesId,
    chainage_error: SeriesId,
    speed_error: SeriesId,
}

/// What is logged for one pipeline.
struct PipelineState {
    name: String,
    index: usize,
    filtered: FusedSeries,
    smoothed: Option<FusedSeries>,
    position: PointsId,
    extent: SegmentsId,
    /// 2-D pipelines' covariance ellipse, registered when the first 2-D state comes.
    ellipse: Option<OutlinesId>,
    /// NIS per measurement topic.
    nis: HashMap<String, SeriesId>,
    /// Markers per gate decision other than plain acceptance.
    gates: HashMap<GateDecision, SeriesId>,
    bounds: SeriesId,
    /// Last time the χ² bound was drawn to, and the last diagnostics time.
    bounds_to_ns: Option<i64>,
    last_diagnostics_ns: Option<i64>,
    /// β per device, and how many devices.
    sharing: Option<(SeriesId, usize)>,
    /// β per device as last logged, and which devices were out.
    last_beta: Vec<f64>,
    out: BTreeSet<String>,
    effective_sample_size: Option<SeriesId>,
    /// Safety checks: U_safe's ends and the usable flag, and the last first failure shown.
    safety: Option<(SeriesId, SeriesId)>,
    last_failure: Option<Option<String>>,
    /// Values drawn with a band in the pipeline's tab, by entity.
    bands: HashMap<String, SeriesId>,
    /// Whether the learnt IMU error model was last applied (GNSS lost), to say when it
    /// changes.
    model_applied: Option<bool>,
}

struct Logger {
    rec: RecordingStream,
    /// The file the messages come from, for error messages (shared: cheap to lend).
    path: Arc<Path>,
    options: VizOptions,
    columns: Columns,
    map: Option<TrackMap>,
    /// Where east/north are measured from: the map's origin, else the first fix.
    origin: Option<GeodeticOrigin>,
    truth: ReferenceTrack,
    /// The truth's east/north velocity, for 2-D pipelines' velocity errors.
    truth_velocity: TruthWindow,
    /// The first message's log time, for --from/--to.
    start_ns: Option<u64>,
    /// Raw series by entity, registered as they first appear.
    raw: HashMap<String, SeriesId>,
    truth_train: Option<PointsId>,
    truth_path: Option<PointsId>,
    gnss: HashMap<FixType, PointsId>,
    pipelines: Vec<PipelineState>,
    layout: Layout,
    sent_layout: Option<Layout>,
    /// Legend entries drawn into the map when the layout last changed.
    legend: Vec<(String, Color)>,
    entities: BTreeSet<String>,
    report: VizReport,
}

impl Logger {
    fn new(
        rec: RecordingStream,
        path: PathBuf,
        options: VizOptions,
        decimation: Decimation,
        longest_chunk_ns: u64,
    ) -> Self {
        let bin_s = match decimation {
            Decimation::Full => None,
            Decimation::Bins { bin_ns } => Some(bin_ns as f64 / 1e9),
        };
        Logger {
            rec,
            path: path.into(),
            options,
            columns: Columns::new(decimation),
            map: None,
            origin: None,
            truth: ReferenceTrack::new(10.0 + longest_chunk_ns as f64 / 1e9),
            truth_velocity: TruthWindow::new(10.0 + longest_chunk_ns as f64 / 1e9),
            start_ns: None,
            raw: HashMap::new(),
            truth_train: None,
            truth_path: None,
            gnss: HashMap::new(),
            pipelines: Vec::new(),
            layout: Layout::default(),
            sent_layout: None,
            legend: Vec::new(),
            entities: BTreeSet::new(),
            report: VizReport {
                bin_s,
                ..VizReport::default()
            },
        }
    }

    fn report(&self) -> VizReport {
        VizReport {
            logged: self.columns.rows_sent + self.report.logged,
            entities: self.entities.clone(),
            ..self.report.clone()
        }
    }

    fn static_(&mut self, entity: &str, data: &dyn rerun::AsComponents) -> Result<(), Error> {
        self.rec
            .log_static(entity, data)
            .map_err(|e| Error::Rerun(e.to_string()))?;
        self.entities.insert(entity.to_owned());
        Ok(())
    }

    /// A series drawn as lines: `names` and `colors` per component.
    fn line_series(
        &mut self,
        entity: &str,
        names: &[String],
        colors: &[Color],
        widths: &[f32],
    ) -> Result<SeriesId, Error> {
        self.static_(
            entity,
            &SeriesLines::new()
                .with_names(names.iter().cloned())
                .with_colors(colors.iter().copied())
                .with_widths(widths.iter().copied()),
        )?;
        Ok(self.columns.series(entity, names.len()))
    }

    /// A value with its ±3σ band: the value line in the pipeline's colour, the bounds lighter
    /// and thinner, so the band reads as a band.
    fn band_series(
        &mut self,
        entity: &str,
        name: &str,
        index: usize,
        smoothed: bool,
    ) -> Result<SeriesId, Error> {
        self.band_series_of(entity, name, index, smoothed, "3σ")
    }

    /// A value with a band `width` wide either side (`3σ`, `σ`): its rows are
    /// `[value, value + width, value − width]`.
    fn band_series_of(
        &mut self,
        entity: &str,
        name: &str,
        index: usize,
        smoothed: bool,
        width: &str,
    ) -> Result<SeriesId, Error> {
        let color = if smoothed {
            palette::smoothed(index)
        } else {
            palette::pipeline(index)
        };
        self.line_series(
            entity,
            &[
                name.to_owned(),
                format!("{name} +{width}"),
                format!("{name} −{width}"),
            ],
            &[color, palette::band(index), palette::band(index)],
            &[2.0, 0.75, 0.75],
        )
    }

    /// A raw sensor's series, registered on first use.
    fn raw_series(&mut self, entity: &str, names: &[&str]) -> Result<SeriesId, Error> {
        if let Some(&id) = self.raw.get(entity) {
            return Ok(id);
        }
        let truth = entity == ent::SPEED_TRUTH;
        let n = self.raw.len();
        let colors: Vec<Color> = (0..names.len())
            .map(|i| {
                if truth {
                    palette::truth()
                } else {
                    palette::raw_sensor(n + i)
                }
            })
            .collect();
        let widths = vec![if truth { 2.5 } else { 1.0 }; names.len()];
        let names: Vec<String> = names.iter().map(|s| (*s).to_owned()).collect();
        let id = self.line_series(entity, &names, &colors, &widths)?;
        if !truth {
            self.columns.break_on_silence(id);
        }
        self.raw.insert(entity.to_owned(), id);
        Ok(id)
    }

    fn raw_value(&mut self, entity: &str, name: &str, t: u64, value: f64) -> Result<(), Error> {
        let id = self.raw_series(entity, &[name])?;
        self.columns.push(&self.rec, id, t as i64, &[value])
    }

    /// The pipeline's index, registering it (and its series) on first sight.
    fn pipeline(&mut self, name: &str) -> Option<usize> {
        if let Some(i) = self.pipelines.iter().position(|p| p.name == name) {
            return Some(i);
        }
        if !self.options.shows_pipeline(name) {
            return None;
        }
        match self.register_pipeline(name) {
            Ok(p) => {
                self.pipelines.push(p);
                self.layout.pipelines.push(PipelineLayout::new(name));
                Some(self.pipelines.len() - 1)
            }
            // A style that cannot be logged: the pipeline's data could not be either.
            Err(_) => None,
        }
    }

    fn register_pipeline(&mut self, name: &str) -> Result<PipelineState, Error> {
        let index = self.pipelines.len();
        let filtered = self.fused_series(name, index, false)?;
        let position = ent::fused_position(name);
        self.static_(
            &position,
            &Points2D::update_fields()
                .with_colors([palette::pipeline(index)])
                .with_radii([Radius::new_ui_points(6.0)])
                .with_labels([name])
                .with_show_labels(false),
        )?;
        let extent = ent::fused_extent(name);
        self.static_(
            &extent,
            &rerun::LineStrips2D::update_fields()
                .with_colors([palette::band(index)])
                .with_radii([Radius::new_ui_points(3.0)]),
        )?;
        let bounds = self.line_series(
            &ent::nis_bounds(name),
            &["χ²₁ 2.5 %".into(), "χ²₁ 97.5 %".into()],
            &[palette::bound(), palette::bound()],
            &[1.0, 1.0],
        )?;
        Ok(PipelineState {
            name: name.to_owned(),
            index,
            filtered,
            smoothed: None,
            position: self.columns.points(&position, None),
            extent: self.columns.segments(&extent),
            ellipse: None,
            nis: HashMap::new(),
            gates: HashMap::new(),
            bounds,
            bounds_to_ns: None,
            last_diagnostics_ns: None,
            sharing: None,
            last_beta: Vec::new(),
            out: BTreeSet::new(),
            effective_sample_size: None,
            safety: None,
            last_failure: None,
            bands: HashMap::new(),
            model_applied: None,
        })
    }

    fn fused_series(
        &mut self,
        pipeline: &str,
        index: usize,
        smoothed: bool,
    ) -> Result<FusedSeries, Error> {
        let (key, label) = if smoothed {
            (
                format!("{pipeline}/smoothed"),
                format!("{pipeline} RTS-smoothed"),
            )
        } else {
            (pipeline.to_owned(), pipeline.to_owned())
        };
        let color = if smoothed {
            palette::smoothed(index)
        } else {
            palette::pipeline(index)
        };
        Ok(FusedSeries {
            speed: self.line_series(&ent::fused_speed(&key), &[label.clone()], &[color], &[1.5])?,
            chainage_error: self.band_series(
                &ent::chainage_error(&key),
                &label,
                index,
                smoothed,
            )?,
            speed_error: self.band_series(&ent::speed_error(&key), &label, index, smoothed)?,
        })
    }

    /// Whether a message at this log time is inside --from/--to.
    fn in_window(&self, t: u64) -> bool {
        let Some(start) = self.start_ns else {
            return true;
        };
        let s = t.saturating_sub(start) as f64 / 1e9;
        self.options.from_s.is_none_or(|f| s >= f) && self.options.to_s.is_none_or(|e| s <= e)
    }

    /// How a foreign channel is shown: as the catalogue kind it translates to. With no
    /// config to give a role, a twist is drawn as the speed of its topic. One that cannot be
    /// shown goes on the report with why.
    fn foreign_channel(&mut self, c: &ChannelInfo) -> Option<(Translator, Arc<ChannelInfo>)> {
        let (encoding, schema) = (c.message_encoding.as_str(), c.schema_name());
        let t = Translator::for_channel(c, None)
            .or_else(|_| Translator::for_channel(c, Some(Role::Odometer)));
        match t {
            Ok(Some(t)) => {
                let info = t.channel(c);
                Some((t, info))
            }
            _ => {
                let why = format!(
                    "{schema} ({encoding}) is not a type railfuse reads (it reads {})",
                    Translator::schemas().join(", ")
                );
                self.report.not_shown.insert(c.topic.clone(), why);
                None
            }
        }
    }

    /// A foreign message, drawn as the catalogue message it translates to; one that does not
    /// decode is counted.
    fn foreign_message(
        &mut self,
        t: &Translator,
        info: &Arc<ChannelInfo>,
        m: &LogMessage<'_>,
    ) -> Result<(), Error> {
        match t.translate(m.data, m.log_time_ns) {
            Ok(Translated::Message { message, .. }) => {
                let data = message.to_json();
                self.message(&LogMessage {
                    channel: info,
                    sequence: m.sequence,
                    log_time_ns: m.log_time_ns,
                    publish_time_ns: m.publish_time_ns,
                    data: &data,
                })
            }
            Ok(Translated::Skipped(_)) => Ok(()),
            Err(e) => {
                self.report.undecodable.add(&info.topic, e.kind(), || {
                    format!("{}: log time {} ns: {e}", info.topic, m.log_time_ns)
                });
                Ok(())
            }
        }
    }

    /// One message to the entities of its kind.
    fn message(&mut self, m: &LogMessage<'_>) -> Result<(), Error> {
        let path = &*self.path.clone();
        let topic = m.channel.topic.as_str();
        let kind = m.channel.kind();
        // The references are read whatever the selection; the rest only when shown.
        let reference = matches!(kind, Some(MessageKind::TrackMap | MessageKind::GroundTruth));
        if !reference && !self.in_window(m.log_time_ns) {
            return Ok(());
        }
        if let Some((pipeline, channel)) = topics::parse_fused(topic) {
            let Some(p) = self.pipeline(pipeline) else {
                return Ok(());
            };
            return match channel {
                FusedChannel::State => self.fused(p, false, &m.decode(path)?),
                FusedChannel::Smoothed => self.fused(p, true, &m.decode(path)?),
                FusedChannel::Diagnostics => self.diagnostics(p, &m.decode(path)?),
                FusedChannel::Safety => self.safety(p, &m.decode(path)?),
                FusedChannel::ImuErrorModel => self.imu_error_model(p, &m.decode(path)?),
            };
        }
        if !reference && !self.options.shows_topic(topic) {
            return Ok(());
        }
        match kind {
            Some(MessageKind::TrackMap) => self.track_map(m.decode(path)?)?,
            Some(MessageKind::GroundTruth) => self.truth(&m.decode(path)?)?,
            Some(MessageKind::GnssFix) => self.gnss(&m.decode(path)?)?,
            Some(MessageKind::RadarSpeed) => {
                let r: RadarSpeed = m.decode(path)?;
                if r.valid {
                    self.raw_value(ent::SPEED_RADAR, "radar", r.stamp_ns, r.speed_mps)?;
                }
            }
            Some(MessageKind::Odometer) => {
                let o: Odometer = m.decode(path)?;
                self.raw_value(&ent::speed_of(topic), topic, o.stamp_ns, o.speed_mps)?;
            }
            Some(MessageKind::LoopPosition) => {
                let l: LoopPosition = m.decode(path)?;
                self.position_sensor(ent::LOOP_CHAINAGE_ERROR, "loop", l.stamp_ns, l.chainage_m)?;
            }
            Some(MessageKind::BalisePassage) => {
                let b: BalisePassage = m.decode(path)?;
                self.position_sensor(
                    ent::BALISE_CHAINAGE_ERROR,
                    "balise",
                    b.stamp_ns,
                    b.chainage_m,
                )?;
            }
            Some(MessageKind::Imu) if self.imu_shown() => self.imu(&m.decode(path)?)?,
            Some(MessageKind::Event) => self.event(&m.decode(path)?)?,
            Some(MessageKind::TuneEvaluation) => {
                if let Some(pipeline) = topics::tune_trace_pipeline(topic) {
                    self.tune_evaluation(pipeline, &m.decode(path)?)?;
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// One evaluation of a tuning run: its objective and each value as points (a parallel
    /// search enters a batch of evaluations at once), the best so far as a line.
    fn tune_evaluation(&mut self, pipeline: &str, e: &TuneEvaluation) -> Result<(), Error> {
        let t = e.stamp_ns as i64;
        let objective = format!("{}/evaluations", ent::tune_objective(pipeline));
        let id = self.tune_points(&objective, "objective of each evaluation", 0)?;
        self.columns
            .push(&self.rec, id, t, &[e.objective.unwrap_or(f64::NAN)])?;
        let best = format!("{}/best", ent::tune_objective(pipeline));
        let id = match self.raw.get(&best) {
            Some(&id) => id,
            None => {
                // A step: the best holds until an evaluation beats it.
                self.static_(
                    &best,
                    &SeriesLines::new()
                        .with_names(["best so far"])
                        .with_colors([palette::truth()])
                        .with_widths([2.0])
                        .with_interpolation_mode(InterpolationMode::StepAfter)
                        // A batch's evaluations share a pixel: draw its lowest best.
                        .with_aggregation_policy(AggregationPolicy::Min),
                )?;
                let id = self.columns.series(&best, 1);
                self.raw.insert(best.clone(), id);
                id
            }
        };
        self.columns
            .push(&self.rec, id, t, &[e.best.unwrap_or(f64::NAN)])?;
        let k = match self.layout.tune.iter().position(|(p, _)| p == pipeline) {
            Some(k) => k,
            None => {
                self.layout.tune.push((pipeline.to_owned(), Vec::new()));
                self.layout.tune.len() - 1
            }
        };
        for (i, v) in e.values.iter().enumerate() {
            let entity = ent::tune_value(pipeline, i);
            if !self.layout.tune[k].1.iter().any(|(e, _)| *e == entity) {
                self.layout.tune[k].1.push((entity.clone(), v.name.clone()));
            }
            let id = self.tune_points(&entity, &v.name, i + 1)?;
            self.columns.push(&self.rec, id, t, &[v.value])?;
        }
        Ok(())
    }

    fn tune_points(&mut self, entity: &str, name: &str, colour: usize) -> Result<SeriesId, Error> {
        if let Some(&id) = self.raw.get(entity) {
            return Ok(id);
        }
        self.static_(
            entity,
            &SeriesPoints::new()
                .with_names([name])
                .with_colors([palette::raw_sensor(colour)])
                .with_marker_sizes([2.0]),
        )?;
        let id = self.columns.series(entity, 1);
        self.raw.insert(entity.to_owned(), id);
        Ok(id)
    }

    /// The IMU is drawn for raw logs, or when asked for by topic: in a fused run its 200 Hz
    /// would cost more than every other channel together and say little.
    fn imu_shown(&self) -> bool {
        self.pipelines.is_empty() || !self.options.topics.is_empty()
    }

    fn imu(&mut self, i: &Imu) -> Result<(), Error> {
        self.layout.imu = true;
        let t = i.stamp_ns as i64;
        let f = self.raw_series(ent::IMU_SPECIFIC_FORCE, &["forward", "left", "up"])?;
        self.columns.push(&self.rec, f, t, &i.specific_force_mps2)?;
        let w = self.raw_series(
            ent::IMU_ANGULAR_RATE,
            &["roll rate", "pitch rate", "yaw rate"],
        )?;
        self.columns.push(&self.rec, w, t, &i.angular_rate_radps)
    }

    fn position_sensor(
        &mut self,
        entity: &str,
        name: &str,
        t: u64,
        chainage_m: f64,
    ) -> Result<(), Error> {
        if let Some((s, _)) = self.truth.at(t) {
            self.layout.position_sensors = true;
            self.raw_value(entity, name, t, chainage_m - s)?;
        }
        Ok(())
    }

    fn track_map(&mut self, map: TrackMap) -> Result<(), Error> {
        for e in map::log_track_map(&self.rec, &map)? {
            self.entities.insert(e.to_owned());
        }
        self.origin = Some(map.origin.clone());
        self.map = Some(map);
        self.legend.clear();
        Ok(())
    }

    fn truth(&mut self, t: &GroundTruth) -> Result<(), Error> {
        self.truth.push(ReferenceSample {
            stamp_ns: t.stamp_ns,
            chainage_m: t.chainage_m,
            speed_mps: t.speed_mps,
        });
        let (sin, cos) = t.heading_rad.sin_cos();
        self.truth_velocity
            .push(t.stamp_ns, (t.speed_mps * sin, t.speed_mps * cos));
        if !self.in_window(t.stamp_ns) {
            return Ok(());
        }
        if !self.layout.truth {
            self.layout.truth = true;
            self.static_(
                ent::TRUTH_TRAIN,
                &Points2D::update_fields()
                    .with_colors([palette::truth()])
                    .with_radii([Radius::new_ui_points(8.0)])
                    .with_labels(["train (truth)"]),
            )?;
            self.static_(
                ent::TRUTH_PATH,
                &Points2D::update_fields()
                    .with_colors([palette::truth()])
                    .with_radii([Radius::new_ui_points(1.0)]),
            )?;
            self.truth_train = Some(self.columns.points(ent::TRUTH_TRAIN, None));
            self.truth_path = Some(self.columns.points(ent::TRUTH_PATH, Some(TRAIL_EVERY_NS)));
        }
        let (p, ts) = (map::plan(t.east_m, t.north_m), t.stamp_ns as i64);
        for id in [self.truth_train, self.truth_path].into_iter().flatten() {
            self.columns.point(&self.rec, id, ts, p)?;
        }
        self.raw_value(ent::SPEED_TRUTH, "truth", t.stamp_ns, t.speed_mps)
    }

    /// A GNSS fix on the map (by fix type) and its speed.
    fn gnss(&mut self, g: &GnssFix) -> Result<(), Error> {
        if let (Some(lat), Some(lon)) = (g.latitude_deg, g.longitude_deg) {
            let alt = g.altitude_m.unwrap_or(0.0);
            let origin = self.origin.get_or_insert_with(|| GeodeticOrigin {
                latitude_deg: lat,
                longitude_deg: lon,
                altitude_m: alt,
            });
            let (e, n, _) = origin.to_enu(lat, lon, g.altitude_m.unwrap_or(origin.altitude_m));
            let id = match self.gnss.get(&g.fix_type) {
                Some(&id) => id,
                None => {
                    let entity = ent::gnss_fixes(g.fix_type);
                    self.static_(
                        &entity,
                        &Points2D::update_fields()
                            .with_colors([palette::fix_type(g.fix_type)])
                            .with_radii([Radius::new_ui_points(2.5)]),
                    )?;
                    self.layout.gnss_fixes.push(entity.clone());
                    let id = self.columns.points(&entity, None);
                    self.gnss.insert(g.fix_type, id);
                    id
                }
            };
            self.columns
                .point(&self.rec, id, g.stamp_ns as i64, map::plan(e, n))?;
        }
        if let Some(v) = g.speed_mps {
            self.raw_value(ent::SPEED_GNSS, "GNSS", g.stamp_ns, v)?;
        }
        // Fix quality over time, fix or no fix: what a field engineer checks first.
        self.layout.gnss_quality = true;
        let id = self.raw_series(ent::GNSS_QUALITY, &["satellites", "HDOP"])?;
        let hdop = g.hdop.unwrap_or(f64::NAN);
        if hdop.is_finite() {
            self.columns.push(
                &self.rec,
                id,
                g.stamp_ns as i64,
                &[g.satellites as f64, hdop],
            )?;
        } else {
            let sats = self.raw_series(ent::GNSS_SATELLITES, &["satellites (no HDOP)"])?;
            self.columns
                .push(&self.rec, sats, g.stamp_ns as i64, &[g.satellites as f64])?;
        }
        Ok(())
    }

    fn text(&mut self, t_ns: u64, text: String, level: &str) -> Result<(), Error> {
        self.rec
            .set_timestamp_nanos_since_epoch(TIMELINE, t_ns as i64);
        self.rec
            .log(
                ent::EVENTS,
                &TextLog::new(text).with_level(TextLogLevel::from(level)),
            )
            .map_err(|e| Error::Rerun(e.to_string()))?;
        self.entities.insert(ent::EVENTS.to_owned());
        self.report.logged += 1;
        Ok(())
    }

    fn event(&mut self, e: &Event) -> Result<(), Error> {
        let level = match e.kind.describe().1 {
            Severity::Info => "INFO",
            Severity::Warning => "WARN",
            Severity::Error => "ERROR",
        };
        self.text(e.stamp_ns, e.line(), level)
    }

    fn fused(&mut self, p: usize, smoothed: bool, f: &FusedState) -> Result<(), Error> {
        let t = f.stamp_ns as i64;
        if smoothed && self.pipelines[p].smoothed.is_none() {
            let (name, index) = (self.pipelines[p].name.clone(), self.pipelines[p].index);
            self.pipelines[p].smoothed = Some(self.fused_series(&name, index, true)?);
        }
        let (s3, v3) = (3.0 * f.chainage_std_m(), 3.0 * f.speed_std_mps());
        let truth = self.truth.at(f.stamp_ns);
        let state = &self.pipelines[p];
        let series = if smoothed {
            state.smoothed.as_ref()
        } else {
            Some(&state.filtered)
        };
        let Some(series) = series else { return Ok(()) };
        let (speed, chainage_error, speed_error) =
            (series.speed, series.chainage_error, series.speed_error);
        let (position, extent) = (state.position, state.extent);
        self.columns.push(&self.rec, speed, t, &[f.speed_mps])?;
        if let Some((s, v)) = truth {
            let e = f.chainage_m - s;
            self.columns
                .push(&self.rec, chainage_error, t, &[e, e + s3, e - s3])?;
            let e = f.speed_mps - v;
            self.columns
                .push(&self.rec, speed_error, t, &[e, e + v3, e - v3])?;
        }
        if smoothed {
            return Ok(());
        }
        if let Some(plane) = &f.plane {
            // A 2-D pipeline: where it is in the plane, with its 3σ ellipse.
            let ellipse = match self.pipelines[p].ellipse {
                Some(id) => id,
                None => {
                    let entity = ent::fused_ellipse(&self.pipelines[p].name);
                    let index = self.pipelines[p].index;
                    self.static_(
                        &entity,
                        &rerun::LineStrips2D::update_fields()
                            .with_colors([palette::band(index)])
                            .with_radii([Radius::new_ui_points(1.5)]),
                    )?;
                    let id = self.columns.outlines(&entity);
                    self.pipelines[p].ellipse = Some(id);
                    id
                }
            };
            let outline: Vec<[f32; 2]> = plane
                .ellipse_3sigma(36)
                .into_iter()
                .map(|(e, n)| map::plan(e, n))
                .collect();
            self.columns.point(
                &self.rec,
                position,
                t,
                map::plan(plane.east_m, plane.north_m),
            )?;
            self.columns.outline(&self.rec, ellipse, t, outline)?;
        } else if let Some(m) = &self.map {
            if let (Some(here), Some(behind), Some(ahead)) = (
                map::at(m, f.chainage_m),
                map::at(m, f.chainage_m - s3),
                map::at(m, f.chainage_m + s3),
            ) {
                self.columns.point(&self.rec, position, t, here)?;
                self.columns
                    .segment(&self.rec, extent, t, [behind, ahead])?;
            }
        }
        let name = self.pipelines[p].name.clone();
        for st in &f.sensor_states {
            let entity = ent::sensor_state(&name, &st.topic, &st.kind);
            let title = format!("{} {}", st.topic, st.kind.replace('_', " "));
            self.band_value(p, &entity, &title, "3σ", t, st.value, 3.0 * st.std)?;
        }
        // A 2-D pipeline's velocity: east and north errors against the truth.
        let plane = f.plane.as_ref();
        if let (Some([ve, vn]), Some(c), Some((te, tn))) = (
            plane.and_then(|p| p.velocity_en_mps),
            plane.and_then(|p| p.velocity_covariance_en),
            self.truth_velocity.at(f.stamp_ns),
        ) {
            for (axis, e, var) in [("east", ve - te, c[0]), ("north", vn - tn, c[3])] {
                let entity = ent::velocity_error(&name, axis);
                let title = format!("{axis} velocity error (m/s)");
                self.band_value(p, &entity, &title, "3σ", t, e, 3.0 * var.max(0.0).sqrt())?;
            }
        }
        Ok(())
    }

    /// One row of a banded value in a pipeline's tab (`[v, v + b, v − b]`), its plot
    /// registered on first use under `title` with the band's `width` named.
    #[allow(clippy::too_many_arguments)]
    fn band_value(
        &mut self,
        p: usize,
        entity: &str,
        title: &str,
        width: &str,
        t: i64,
        value: f64,
        band: f64,
    ) -> Result<(), Error> {
        let id = match self.pipelines[p].bands.get(entity) {
            Some(&id) => id,
            None => {
                let index = self.pipelines[p].index;
                let id = self.band_series_of(entity, title, index, false, width)?;
                self.pipelines[p].bands.insert(entity.to_owned(), id);
                let title = format!("{title} ±{width}");
                self.layout.pipelines[p]
                    .bands
                    .push((entity.to_owned(), title));
                id
            }
        };
        self.columns
            .push(&self.rec, id, t, &[value, value + band, value - band])
    }

    /// A GNSS/INS pipeline's learnt IMU error model (once a second): the mean residual
    /// rates ψ with their spread σ; when it starts or stops being applied, a log line.
    fn imu_error_model(&mut self, p: usize, m: &ImuErrorModel) -> Result<(), Error> {
        let (t, name) = (m.stamp_ns as i64, self.pipelines[p].name.clone());
        let terms = [
            (
                "speed_residual",
                "learnt ψ speed (m/s²)",
                m.speed_residual_mps2,
                m.speed_residual_std_mps2,
            ),
            (
                "heading_residual",
                "learnt ψ heading (rad/s)",
                m.heading_residual_radps,
                m.heading_residual_std_radps,
            ),
        ];
        for (term, title, value, std) in terms {
            let entity = ent::imu_error_model(&name, term);
            self.band_value(p, &entity, title, "σ", t, value, std)?;
        }
        if self.pipelines[p].model_applied.replace(m.applied) != Some(m.applied) {
            let text = if m.applied {
                format!(
                    "{name}: GNSS lost: the learnt IMU model corrects the inertial solution \
                     (ψ speed {:+.2e} m/s², heading {:+.2e} rad/s, learnt over {:.0} s)",
                    m.speed_residual_mps2, m.heading_residual_radps, m.learnt_s
                )
            } else {
                format!("{name}: learning the IMU error model from GNSS")
            };
            self.text(m.stamp_ns, text, if m.applied { "WARN" } else { "INFO" })?;
        }
        Ok(())
    }

    /// One epoch's safety status: U_safe's ends relative to the reference and the usable
    /// flag as series; each change of the first failing check as a log line.
    fn safety(&mut self, p: usize, s: &SafetyStatus) -> Result<(), Error> {
        let t = s.stamp_ns as i64;
        let (interval, flag) = match self.pipelines[p].safety {
            Some(ids) => ids,
            None => {
                let (name, index) = (self.pipelines[p].name.clone(), self.pipelines[p].index);
                let interval = self.line_series(
                    &ent::safe_interval(&name),
                    &[format!("{name} U_safe high"), format!("{name} U_safe low")],
                    &[palette::smoothed(index), palette::smoothed(index)],
                    &[1.0, 1.0],
                )?;
                let flag = self.line_series(
                    &ent::safety(&name),
                    &["usable".into()],
                    &[palette::pipeline(index)],
                    &[1.5],
                )?;
                self.pipelines[p].safety = Some((interval, flag));
                self.layout.pipelines[p].safety = true;
                (interval, flag)
            }
        };
        let truth = self.truth.at(s.stamp_ns).map(|(c, _)| c);
        let (high, low) = match (s.safe_interval, truth) {
            (Some(u), Some(c)) => (u.high_m - c, u.low_m - c),
            _ => (f64::NAN, f64::NAN),
        };
        self.columns.push(&self.rec, interval, t, &[high, low])?;
        let usable = if s.usable { 1.0 } else { 0.0 };
        self.columns.push(&self.rec, flag, t, &[usable])?;
        if self.pipelines[p].last_failure.as_ref() != Some(&s.first_failure) {
            self.pipelines[p].last_failure = Some(s.first_failure.clone());
            let name = self.pipelines[p].name.clone();
            let (text, level) = match (&s.first_failure, &s.reason) {
                (Some(check), reason) => (
                    format!(
                        "{name}: not usable: {check}: {}",
                        reason.as_deref().unwrap_or("")
                    ),
                    "WARN",
                ),
                (None, _) => (format!("{name}: usable again, every check passes"), "INFO"),
            };
            self.text(s.stamp_ns, text, level)?;
        }
        Ok(())
    }

    fn diagnostics(&mut self, p: usize, d: &FusedDiagnostics) -> Result<(), Error> {
        let t = d.stamp_ns as i64;
        let name = self.pipelines[p].name.clone();
        // The χ² bounds as lines under the whole NIS plot: drawn on as time goes.
        let state = &mut self.pipelines[p];
        state.last_diagnostics_ns = Some(t);
        if state.bounds_to_ns.is_none_or(|b| t > b + 10_000_000_000) {
            state.bounds_to_ns = Some(t);
            let bounds = state.bounds;
            self.columns
                .push(&self.rec, bounds, t, &[CHI2_95_1DOF.0, CHI2_95_1DOF.1])?;
        }
        match d.decision {
            GateDecision::Accepted => {
                if let Some(nis) = d.nis {
                    let id = self.nis_series(p, &d.source)?;
                    self.columns.push(&self.rec, id, t, &[nis])?;
                }
            }
            // Not yet a filter to disagree with: nothing to mark.
            GateDecision::BeforeInitialisation => {}
            decision => {
                let id = self.gate_series(p, decision)?;
                let y = d.nis.map_or(NIS_AXIS_MAX, |n| n.min(NIS_AXIS_MAX)) * 0.97;
                self.columns.push(&self.rec, id, t, &[y])?;
                if decision == GateDecision::AcceptedAfterLockout {
                    self.text(
                        d.stamp_ns,
                        format!(
                            "{name}: {} accepted after a gate lockout (variance widened)",
                            d.source
                        ),
                        "WARN",
                    )?;
                }
            }
        }
        if let Some(ess) = d.effective_sample_size {
            let id = match self.pipelines[p].effective_sample_size {
                Some(id) => id,
                None => {
                    let index = self.pipelines[p].index;
                    let id = self.line_series(
                        &ent::effective_sample_size(&name),
                        &["effective sample size".into()],
                        &[palette::pipeline(index)],
                        &[1.5],
                    )?;
                    self.pipelines[p].effective_sample_size = Some(id);
                    self.layout.pipelines[p].effective_sample_size = true;
                    id
                }
            };
            self.columns.push(&self.rec, id, t, &[ess])?;
        }
        if let Some(sharing) = &d.sharing {
            self.sharing(p, d.stamp_ns, sharing)?;
        }
        if let Some(e) = &d.eddy_current {
            self.eddy_current(p, t, e)?;
        }
        Ok(())
    }

    /// An eddy-current window: its correlation with and without warping, the warp's
    /// acceleration beside the filter's, and the two sensors' sleeper counts' difference.
    fn eddy_current(&mut self, p: usize, t: i64, e: &EddyCurrentDiagnostics) -> Result<(), Error> {
        let name = self.pipelines[p].name.clone();
        let rows: [(&str, &str, [&str; 2], [f64; 2]); 3] = [
            (
                "correlation",
                "correlation peak ρ",
                ["ρ", "ρ unwarped"],
                [
                    e.rho.unwrap_or(f64::NAN),
                    e.unwarped_rho.unwrap_or(f64::NAN),
                ],
            ),
            (
                "acceleration",
                "acceleration (m/s²): warp and filter",
                ["warp", "filter"],
                [
                    e.warp_acceleration_mps2.unwrap_or(f64::NAN),
                    e.filter_acceleration_mps2.unwrap_or(f64::NAN),
                ],
            ),
            (
                "sleepers",
                "sleepers counted: a, b",
                ["sensor a", "sensor b"],
                [e.sleepers_a as f64, e.sleepers_b as f64],
            ),
        ];
        for (what, title, names, values) in rows {
            let plot = ent::eddy_current(&name, what);
            for (k, (component, value)) in names.iter().zip(values).enumerate() {
                if !value.is_finite() {
                    continue;
                }
                let entity = format!("{plot}/{}", component.replace(' ', "_"));
                let id = match self.raw.get(&entity) {
                    Some(&id) => id,
                    None => {
                        let index = self.pipelines[p].index;
                        let color = [palette::pipeline(index), palette::smoothed(index)][k];
                        let id = self.line_series(
                            &entity,
                            &[(*component).to_owned()],
                            &[color],
                            &[[1.5, 1.0][k]],
                        )?;
                        // ρ and the accelerations exist only in moving windows: the line
                        // breaks over a stop instead of joining its two ends.
                        if what != "sleepers" {
                            self.columns.break_on_silence(id);
                        }
                        self.raw.insert(entity.clone(), id);
                        let lines = &mut self.layout.pipelines[p].lines;
                        if !lines.iter().any(|(e, _)| *e == plot) {
                            lines.push((plot.clone(), title.to_owned()));
                        }
                        id
                    }
                };
                self.columns.push(&self.rec, id, t, &[value])?;
            }
        }
        Ok(())
    }

    fn nis_series(&mut self, p: usize, source: &str) -> Result<SeriesId, Error> {
        if let Some(&id) = self.pipelines[p].nis.get(source) {
            return Ok(id);
        }
        let entity = ent::nis(&self.pipelines[p].name, source);
        let color = palette::raw_sensor(self.pipelines[p].nis.len());
        self.static_(
            &entity,
            &SeriesPoints::new()
                .with_names([source])
                .with_colors([color])
                .with_marker_sizes([1.0]),
        )?;
        let id = self.columns.series(&entity, 1);
        self.pipelines[p].nis.insert(source.to_owned(), id);
        Ok(id)
    }

    fn gate_series(&mut self, p: usize, decision: GateDecision) -> Result<SeriesId, Error> {
        if let Some(&id) = self.pipelines[p].gates.get(&decision) {
            return Ok(id);
        }
        let entity = ent::gate_decisions(&self.pipelines[p].name, decision);
        let (marker, color) = match decision {
            GateDecision::AcceptedAfterLockout => (MarkerShape::Diamond, palette::after_lockout()),
            GateDecision::RejectedGate => (MarkerShape::Cross, palette::rejected()),
            _ => (MarkerShape::Asterisk, palette::bound()),
        };
        self.static_(
            &entity,
            &SeriesPoints::new()
                .with_names([ent::gate_decision_name(decision).replace('_', " ")])
                .with_colors([color])
                .with_markers([marker])
                .with_marker_sizes([4.0]),
        )?;
        let id = self.columns.series(&entity, 1);
        self.pipelines[p].gates.insert(decision, id);
        Ok(id)
    }

    /// A federated pipeline's β per device, logged when it changes, and devices going out
    /// or coming back as events.
    fn sharing(&mut self, p: usize, t_ns: u64, sharing: &[DeviceShare]) -> Result<(), Error> {
        let beta: Vec<f64> = sharing.iter().map(|s| s.beta).collect();
        let name = self.pipelines[p].name.clone();
        let id = match self.pipelines[p].sharing {
            // β's of another set of devices cannot share the series.
            Some((_, width)) if width != beta.len() => return Ok(()),
            Some((id, _)) => id,
            None => {
                let names: Vec<String> =
                    sharing.iter().map(|s| format!("β {}", s.device)).collect();
                let colors: Vec<Color> = (0..names.len()).map(palette::pipeline).collect();
                let entity = ent::sharing(&name);
                // β holds between fusions: steps, not slopes.
                self.static_(
                    &entity,
                    &SeriesLines::new()
                        .with_names(names.iter().cloned())
                        .with_colors(colors)
                        .with_widths(vec![1.5; names.len()])
                        .with_interpolation_mode(InterpolationMode::StepAfter),
                )?;
                let id = self.columns.series(&entity, names.len());
                self.pipelines[p].sharing = Some((id, beta.len()));
                self.layout.pipelines[p].sharing = true;
                id
            }
        };
        if self.pipelines[p].last_beta != beta {
            self.columns.push(&self.rec, id, t_ns as i64, &beta)?;
            self.pipelines[p].last_beta = beta;
        }
        for s in sharing {
            let was_out = self.pipelines[p].out.contains(&s.device);
            match (&s.fault, was_out) {
                (Some(why), false) => {
                    self.pipelines[p].out.insert(s.device.clone());
                    self.text(
                        t_ns,
                        format!("{name}: {} out of the fusion ({why})", s.device),
                        "WARN",
                    )?;
                }
                (None, true) => {
                    self.pipelines[p].out.remove(&s.device);
                    self.text(
                        t_ns,
                        format!("{name}: {} back in the fusion", s.device),
                        "INFO",
                    )?;
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The legend entries for what the map shows now.
    fn legend_entries(&self) -> Vec<(String, Color)> {
        let mut entries = Vec::new();
        if self.layout.truth {
            entries.push(("truth".to_owned(), palette::truth()));
        }
        for p in &self.pipelines {
            entries.push((p.name.clone(), palette::pipeline(p.index)));
        }
        let mut fixes: Vec<FixType> = self.gnss.keys().copied().collect();
        fixes.sort_by_key(|f| std::cmp::Reverse(*f as u8));
        for f in fixes {
            entries.push((
                format!("GNSS {}", f.name().replace('_', " ")),
                palette::fix_type(f),
            ));
        }
        if self.map.as_ref().is_some_and(|m| !m.balises.is_empty()) {
            entries.push(("balise".to_owned(), palette::balise()));
        }
        entries
    }

    /// Redraws the legend when what it lists changed.
    fn update_legend(&mut self) -> Result<(), Error> {
        let entries = self.legend_entries();
        if entries == self.legend {
            return Ok(());
        }
        if let Some(bounds) = self.map.as_ref().and_then(map::bounds) {
            map::log_legend(&self.rec, bounds, &entries)?;
            self.entities.insert(ent::LEGEND.to_owned());
        }
        self.legend = entries;
        Ok(())
    }

    fn send_blueprint(&mut self) -> Result<(), Error> {
        self.update_legend()?;
        self.layout.send(&self.rec, self.columns.span())?;
        self.sent_layout = Some(self.layout.clone());
        Ok(())
    }

    fn send_blueprint_if_changed(&mut self) -> Result<(), Error> {
        if self.sent_layout.as_ref() != Some(&self.layout) {
            self.send_blueprint()?;
        }
        Ok(())
    }

    /// Closes the plots (bounds drawn to the end), sends what is buffered and the layout.
    fn finish(&mut self) -> Result<(), Error> {
        for i in 0..self.pipelines.len() {
            let (bounds, last) = (
                self.pipelines[i].bounds,
                self.pipelines[i].last_diagnostics_ns,
            );
            if let Some(t) = last.filter(|&t| Some(t) != self.pipelines[i].bounds_to_ns) {
                self.columns
                    .push(&self.rec, bounds, t, &[CHI2_95_1DOF.0, CHI2_95_1DOF.1])?;
            }
        }
        self.columns.flush(&self.rec)?;
        self.send_blueprint()
    }
}

/// Checks that something listens at the viewer URL's host and port before streaming: the SDK
/// would otherwise queue data and retry for ever against an address where no viewer runs.
fn probe_viewer(url: &str) -> Result<(), Error> {
    use std::net::{TcpStream, ToSocketAddrs};
    let authority = url
        .split("://")
        .nth(1)
        .and_then(|rest| rest.split('/').next())
        .filter(|a| a.contains(':'));
    let Some(authority) = authority else {
        return Err(Error::Rerun(format!(
            "{url}: expected a viewer URL like rerun+http://127.0.0.1:9876/proxy"
        )));
    };
    let addrs = authority
        .to_socket_addrs()
        .map_err(|e| Error::Rerun(format!("{url}: {e}")))?;
    for addr in addrs {
        if TcpStream::connect_timeout(&addr, Duration::from_secs(3)).is_ok() {
            return Ok(());
        }
    }
    Err(Error::Rerun(format!(
        "{url}: no Rerun viewer is listening there (start one with `rerun`)"
    )))
}

/// A short window of the truth's east/north velocity, interpolated linearly at a stamp: bounded,
/// samples older than the retention span behind the newest are dropped.
struct TruthWindow {
    samples: std::collections::VecDeque<(u64, (f64, f64))>,
    retain_ns: u64,
}

impl TruthWindow {
    fn new(retain_s: f64) -> Self {
        TruthWindow {
            samples: std::collections::VecDeque::new(),
            retain_ns: (retain_s * 1e9) as u64,
        }
    }

    fn push(&mut self, t: u64, value: (f64, f64)) {
        if self.samples.back().is_some_and(|&(last, _)| t <= last) {
            return;
        }
        self.samples.push_back((t, value));
        while self
            .samples
            .get(1)
            .is_some_and(|&(s, _)| s + self.retain_ns < t)
        {
            self.samples.pop_front();
        }
    }

    fn at(&self, t: u64) -> Option<(f64, f64)> {
        let i = self.samples.partition_point(|&(s, _)| s < t);
        let &(tb, b) = self.samples.get(i)?;
        if tb == t {
            return Some(b);
        }
        let &(ta, a) = self.samples.get(i.checked_sub(1)?)?;
        let w = (t - ta) as f64 / (tb - ta) as f64;
        Some((a.0 + w * (b.0 - a.0), a.1 + w * (b.1 - a.1)))
    }
}

/// A channel of another tool's schema, shown as the catalogue kind it translates to. The
/// ROS and Foxglove twins railfuse writes of its own fused states (under `/fused/` and
/// `/foxglove/`) are not: the fused states themselves are shown.
fn is_foreign(c: &ChannelInfo) -> bool {
    c.kind().is_none()
        && !c.topic.starts_with(topics::FUSED_PREFIX)
        && !c
            .topic
            .starts_with(railfuse_catalog::foxglove::TOPIC_PREFIX)
}
