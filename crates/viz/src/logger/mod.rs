//! Turns railfuse messages into Rerun entities: one streaming pass over a file
//! ([`visualize`]), or message by message while recording or re-fusing ([`LiveViz`]).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use railfuse_catalog::foreign::Translator;
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::{ChannelInfo, LogMessage, LogRecord};
use railfuse_catalog::messages::fused::CHI2_95_1DOF;
use railfuse_catalog::messages::*;
use railfuse_catalog::reference_track::ReferenceTrack;
use railfuse_catalog::run::Run;
use railfuse_catalog::topics::{self, FusedChannel};
use rerun::{Color, Points2D, Radius, RecordingStream, SeriesLines};

use crate::blueprint::{Layout, PipelineLayout};
use crate::series::{Columns, Decimation, OutlinesId, PointsId, SegmentsId, SeriesId};
use crate::{entities as ent, map, palette, Error};
mod fused;
mod live;
mod sensors;
mod tuning;

use live::probe_viewer;
pub use live::LiveViz;

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

/// Logs the whole run to the sink, streaming. `progress` is told the bytes read so far.
pub fn visualize(
    path: &Run,
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
    run: &Run,
    sink: &Sink,
    options: &VizOptions,
    progress: &dyn Fn(u64),
) -> Result<VizReport, Error> {
    let mut reader = run.reader()?;
    let summary = reader.summary().cloned();
    let path = run.name();
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
    /// The train along the track and its safe front end interval, registered when the first
    /// train comes, and the log time it was last drawn at.
    train: Option<(OutlinesId, SegmentsId)>,
    last_train_ns: Option<i64>,
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
    /// The train's drawing (the log's `/vehicle`): where its sensors are drawn.
    vehicle: Option<Vehicle>,
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
            vehicle: None,
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
            train: None,
            last_train_ns: None,
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

    /// One message to the entities of its kind.
    fn message(&mut self, m: &LogMessage<'_>) -> Result<(), Error> {
        let path = &*self.path.clone();
        let topic = m.channel.topic.as_str();
        let kind = m.channel.kind();
        // The references are read whatever the selection; the rest only when shown.
        let reference = matches!(
            kind,
            Some(MessageKind::TrackMap | MessageKind::GroundTruth | MessageKind::Vehicle)
        );
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
                FusedChannel::Train => self.train(p, &m.decode(path)?),
            };
        }
        if !reference && !self.options.shows_topic(topic) {
            return Ok(());
        }
        match kind {
            Some(MessageKind::TrackMap) => self.track_map(m.decode(path)?)?,
            Some(MessageKind::Vehicle) => self.vehicle = Some(m.decode(path)?),
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
