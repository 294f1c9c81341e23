use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::*;
use railfuse_catalog::reference_track::{ReferenceSample, ReferenceTrack};
use railfuse_catalog::topics::{self, FusedChannel};
use rerun::{
    Color, LineStrips2D, Points2D, Radius, RecordingStream, Scalars, SeriesLines, TextLog,
};

use crate::{entities as ent, Error};

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

#[derive(Debug, Clone, Default)]
pub struct VizReport {
    pub messages: u64,
    /// Records logged to Rerun (a message can give several: a value and its bounds, a map point).
    pub logged: u64,
    pub entities: BTreeSet<String>,
}

// Colours as RGB(A) tuples: rerun's Color constructors are not const.
const TRUTH_COLOR: (u8, u8, u8) = (235, 235, 235);
const BAND_COLOR: (u8, u8, u8, u8) = (200, 60, 60, 160);
/// Pipeline colours, by the order pipelines first appear.
const PIPELINE_COLORS: [(u8, u8, u8); 4] = [
    (30, 120, 230),
    (230, 120, 20),
    (40, 170, 80),
    (160, 60, 200),
];

fn rgb((r, g, b): (u8, u8, u8)) -> Color {
    Color::from_rgb(r, g, b)
}

fn pipeline_color(index: usize) -> Color {
    rgb(PIPELINE_COLORS[index % PIPELINE_COLORS.len()])
}

fn band_color() -> Color {
    let (r, g, b, a) = BAND_COLOR;
    Color::from_unmultiplied_rgba(r, g, b, a)
}

fn fix_color(fix: FixType) -> Color {
    match fix {
        FixType::None => Color::from_rgb(128, 128, 128),
        FixType::Single => Color::from_rgb(220, 50, 50),
        FixType::Dgps => Color::from_rgb(230, 150, 30),
        FixType::RtkFloat => Color::from_rgb(230, 210, 40),
        FixType::RtkFixed => Color::from_rgb(40, 170, 80),
    }
}

struct Logger {
    rec: RecordingStream,
    /// The file the messages come from, for error messages (shared: cheap to lend).
    path: std::sync::Arc<Path>,
    map: Option<TrackMap>,
    truth: ReferenceTrack,
    pipelines: Vec<String>,
    /// The last β per federated pipeline, to log the weights only when they change.
    shares: std::collections::HashMap<String, Vec<f64>>,
    /// Sensor-state entities whose series style is logged.
    sensor_states: std::collections::HashSet<String>,
    report: VizReport,
}

/// How long to wait for a viewer to take the last of the data.
const VIEWER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// Opens the Rerun recording stream for a sink (checking first that a viewer listens).
fn open_stream(sink: &Sink) -> Result<RecordingStream, Error> {
    if let Sink::Connect(url) = sink {
        probe_viewer(url)?;
    }
    let app = rerun::RecordingStreamBuilder::new("railfuse");
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

/// Streams messages to Rerun as they are recorded (`railfuse record --viz`): the same entity
/// layout as `railfuse viz`, fed one message at a time.
pub struct LiveViz {
    logger: Logger,
    channels: std::collections::HashMap<
        (String, String),
        std::sync::Arc<railfuse_catalog::log::ChannelInfo>,
    >,
}

impl LiveViz {
    pub fn open(sink: &Sink) -> Result<Self, Error> {
        Ok(Self {
            logger: Logger::new(open_stream(sink)?, PathBuf::from("<live>"), 0),
            channels: Default::default(),
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
                std::sync::Arc::new(railfuse_catalog::log::ChannelInfo {
                    id: n,
                    topic: topic.to_owned(),
                    message_encoding: "json".into(),
                    metadata: Default::default(),
                    schema: Some(std::sync::Arc::new(railfuse_catalog::log::SchemaInfo {
                        id: n,
                        name: schema.to_owned(),
                        encoding: "jsonschema".into(),
                        data: Vec::new(),
                    })),
                })
            });
        let m = railfuse_catalog::log::LogMessage {
            channel,
            sequence: 0,
            log_time_ns,
            publish_time_ns: log_time_ns,
            data: json,
        };
        self.logger
            .rec
            .set_timestamp_nanos_since_epoch("log_time", log_time_ns as i64);
        self.logger.message(&m)
    }
}

/// Logs the whole file to the sink, streaming.
/// `progress` is told the bytes of the file read so far.
pub fn visualize(path: &Path, sink: &Sink, progress: &dyn Fn(u64)) -> Result<VizReport, Error> {
    let mut reader = LogReader::open(path)?;
    // Fused states may trail the truth in file order by a chunk (railfuse writes the fused
    // chunk of an input chunk right after it): the truth is kept that much longer.
    let longest_chunk_ns = railfuse_catalog::log::read_summary(path)?
        .and_then(|s| s.longest_chunk_ns)
        .unwrap_or(0);
    let mut logger = Logger::new(open_stream(sink)?, path.to_owned(), longest_chunk_ns);
    while let Some(record) = reader.next() {
        if let LogRecord::Message(m) = record? {
            logger.report.messages += 1;
            logger
                .rec
                .set_timestamp_nanos_since_epoch("log_time", m.log_time_ns as i64);
            logger.message(&m)?;
            if logger.report.messages.is_multiple_of(4096) {
                progress(reader.bytes_read());
            }
        }
    }
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
    Ok(logger.report)
}

impl Logger {
    fn new(rec: RecordingStream, path: PathBuf, longest_chunk_ns: u64) -> Self {
        Logger {
            rec,
            path: path.into(),
            map: None,
            truth: ReferenceTrack::new(10.0 + longest_chunk_ns as f64 / 1e9),
            pipelines: Vec::new(),
            shares: Default::default(),
            sensor_states: Default::default(),
            report: VizReport::default(),
        }
    }

    fn log<AS: ?Sized + rerun::AsComponents>(
        &mut self,
        entity: &str,
        data: &AS,
    ) -> Result<(), Error> {
        self.rec
            .log(entity, data)
            .map_err(|e| Error::Rerun(e.to_string()))?;
        self.report.logged += 1;
        if !self.report.entities.contains(entity) {
            self.report.entities.insert(entity.to_owned());
        }
        Ok(())
    }

    fn log_static<AS: ?Sized + rerun::AsComponents>(
        &mut self,
        entity: &str,
        data: &AS,
    ) -> Result<(), Error> {
        self.rec
            .log_static(entity, data)
            .map_err(|e| Error::Rerun(e.to_string()))?;
        self.report.entities.insert(entity.to_owned());
        Ok(())
    }

    /// Plan-view point: Rerun's 2-D view grows y downwards, so north is negated to show it up.
    fn plan(east: f64, north: f64) -> [f32; 2] {
        [east as f32, -north as f32]
    }

    fn series_style(
        &mut self,
        entity: &str,
        name: &str,
        color: Color,
        width: f32,
    ) -> Result<(), Error> {
        self.log_static(
            entity,
            &SeriesLines::new()
                .with_names([name])
                .with_colors([color])
                .with_widths([width]),
        )
    }

    /// One message to the entities of its kind.
    fn message(&mut self, m: &railfuse_catalog::log::LogMessage<'_>) -> Result<(), Error> {
        let path = &*self.path.clone();
        let topic = m.channel.topic.as_str();
        match m.channel.kind() {
            Some(MessageKind::TrackMap) => self.track_map(m.decode(path)?)?,
            Some(MessageKind::GroundTruth) => {
                let t: GroundTruth = m.decode(path)?;
                self.truth.push(ReferenceSample {
                    stamp_ns: t.stamp_ns,
                    chainage_m: t.chainage_m,
                    speed_mps: t.speed_mps,
                });
                self.log(
                    ent::TRUTH_POSITION,
                    &Points2D::new([Self::plan(t.east_m, t.north_m)])
                        .with_colors([rgb(TRUTH_COLOR)])
                        .with_radii([Radius::new_ui_points(7.0)]),
                )?;
                self.log(ent::SPEED_TRUTH, &Scalars::single(t.speed_mps))?;
            }
            Some(MessageKind::GnssFix) => self.gnss(&m.decode(path)?)?,
            Some(MessageKind::RadarSpeed) => {
                let r: RadarSpeed = m.decode(path)?;
                if r.valid {
                    self.log(ent::SPEED_RADAR, &Scalars::single(r.speed_mps))?;
                }
            }
            Some(MessageKind::Odometer) => {
                let o: Odometer = m.decode(path)?;
                self.log(&ent::speed_of(topic), &Scalars::single(o.speed_mps))?;
            }
            Some(MessageKind::LoopPosition) => {
                let l: LoopPosition = m.decode(path)?;
                if let Some((s, _)) = self.truth.at(l.stamp_ns) {
                    self.log(ent::LOOP_CHAINAGE_ERROR, &Scalars::single(l.chainage_m - s))?;
                }
            }
            Some(MessageKind::BalisePassage) => {
                let b: BalisePassage = m.decode(path)?;
                if let Some((s, _)) = self.truth.at(b.stamp_ns) {
                    self.log(
                        ent::BALISE_CHAINAGE_ERROR,
                        &Scalars::single(b.chainage_m - s),
                    )?;
                }
            }
            Some(MessageKind::Event) => {
                let e: Event = m.decode(path)?;
                self.log(
                    ent::EVENTS,
                    &TextLog::new(format!("{:?}: {}", e.kind, e.text)),
                )?;
            }
            Some(MessageKind::FusedState) => {
                // A pipeline's RTS-smoothed states are a series of their own.
                let series = match topics::parse_fused(topic) {
                    Some((pipeline, FusedChannel::State)) => pipeline.to_owned(),
                    Some((pipeline, FusedChannel::Smoothed)) => format!("{pipeline}/smoothed"),
                    _ => return Ok(()),
                };
                let f: FusedState = m.decode(path)?;
                // Fused states are released after the reorder window: plot them at the
                // instant they describe, so they line up with the truth.
                self.rec
                    .set_timestamp_nanos_since_epoch("log_time", f.stamp_ns as i64);
                self.fused(&series, &f)?;
            }
            Some(MessageKind::FusedDiagnostics) => {
                if let Some((pipeline, FusedChannel::Diagnostics)) = topics::parse_fused(topic) {
                    self.sharing(pipeline, m.decode(path)?)?;
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// The track, balises and stations on the plan view (static).
    fn track_map(&mut self, map: TrackMap) -> Result<(), Error> {
        let strip: Vec<[f32; 2]> = map
            .vertices
            .iter()
            .map(|v| Self::plan(v.east_m, v.north_m))
            .collect();
        self.log_static(
            ent::TRACK,
            &LineStrips2D::new([strip])
                .with_colors([Color::from_rgb(170, 170, 170)])
                .with_radii([Radius::new_ui_points(1.5)]),
        )?;
        let at = |c: f64| map.locate(c).map(|(e, n, _)| Self::plan(e, n));
        let balises: Vec<_> = map
            .balises
            .iter()
            .filter_map(|b| at(b.chainage_m))
            .collect();
        // Balise ids would crowd the plan view: they show on hover as instance data.
        self.log_static(
            ent::BALISES,
            &Points2D::new(balises)
                .with_colors([Color::from_rgb(250, 200, 0)])
                .with_radii([Radius::new_ui_points(4.0)]),
        )?;
        let stations: Vec<_> = map
            .stations
            .iter()
            .filter_map(|s| at(s.chainage_m))
            .collect();
        let names: Vec<_> = map.stations.iter().map(|s| s.name.clone()).collect();
        self.log_static(
            ent::STATIONS,
            &Points2D::new(stations)
                .with_labels(names)
                .with_colors([Color::from_rgb(255, 255, 255)])
                .with_radii([Radius::new_ui_points(6.0)]),
        )?;
        self.series_style(ent::SPEED_TRUTH, "truth", rgb(TRUTH_COLOR), 2.0)?;
        self.map = Some(map);
        Ok(())
    }

    /// A GNSS fix on the plan view (coloured by fix type) and its speed.
    fn gnss(&mut self, g: &GnssFix) -> Result<(), Error> {
        if let (Some(map), Some(lat), Some(lon)) = (&self.map, g.latitude_deg, g.longitude_deg) {
            let (e, n, _) =
                map.origin
                    .to_enu(lat, lon, g.altitude_m.unwrap_or(map.origin.altitude_m));
            let label = format!("{:?}", g.fix_type);
            self.log(
                ent::GNSS_POSITION,
                &Points2D::new([Self::plan(e, n)])
                    .with_colors([fix_color(g.fix_type)])
                    .with_radii([Radius::new_ui_points(4.0)])
                    .with_labels([label]),
            )?;
        }
        if let Some(v) = g.speed_mps {
            self.log(ent::SPEED_GNSS, &Scalars::single(v))?;
        }
        Ok(())
    }

    /// A federated pipeline's β per device, logged when it changes, and devices going out.
    fn sharing(&mut self, pipeline: &str, d: FusedDiagnostics) -> Result<(), Error> {
        let Some(sharing) = d.sharing else {
            return Ok(());
        };
        let beta: Vec<f64> = sharing.iter().map(|s| s.beta).collect();
        if self.shares.get(pipeline) == Some(&beta) {
            return Ok(());
        }
        let entity = ent::sharing(pipeline);
        if !self.shares.contains_key(pipeline) {
            let names: Vec<String> = sharing.iter().map(|s| format!("β {}", s.device)).collect();
            let colors: Vec<Color> = (0..names.len()).map(pipeline_color).collect();
            self.log_static(
                &entity,
                &SeriesLines::new().with_names(names).with_colors(colors),
            )?;
        }
        self.rec
            .set_timestamp_nanos_since_epoch("log_time", d.stamp_ns as i64);
        self.log(&entity, &Scalars::new(beta.clone()))?;
        for s in sharing.iter().filter(|s| s.fault.is_some()) {
            self.log(
                ent::EVENTS,
                &TextLog::new(format!(
                    "{pipeline}: {} out ({})",
                    s.device,
                    s.fault.as_deref().unwrap_or_default()
                )),
            )?;
        }
        self.shares.insert(pipeline.to_owned(), beta);
        Ok(())
    }

    fn fused(&mut self, pipeline: &str, f: &FusedState) -> Result<(), Error> {
        let index = match self.pipelines.iter().position(|p| p == pipeline) {
            Some(i) => i,
            None => {
                self.pipelines.push(pipeline.to_owned());
                let color = pipeline_color(self.pipelines.len() - 1);
                for base in [
                    ent::fused_speed(pipeline),
                    ent::chainage_error(pipeline),
                    ent::speed_error(pipeline),
                ] {
                    let style = SeriesLines::new()
                        .with_names([
                            pipeline.to_owned(),
                            format!("{pipeline} +3σ"),
                            format!("{pipeline} −3σ"),
                        ])
                        .with_colors([color, band_color(), band_color()])
                        .with_widths([1.5, 1.0, 1.0]);
                    self.log_static(&base, &style)?;
                }
                self.pipelines.len() - 1
            }
        };
        let color = pipeline_color(index);
        let (s3, v3) = (3.0 * f.chainage_std_m(), 3.0 * f.speed_std_mps());
        if let Some((e, n, _)) = self.map.as_ref().and_then(|m| m.locate(f.chainage_m)) {
            self.log(
                &ent::fused_position(pipeline),
                &Points2D::new([Self::plan(e, n)])
                    .with_colors([color])
                    .with_radii([Radius::new_ui_points(5.0)]),
            )?;
        }
        self.band(&ent::fused_speed(pipeline), f.speed_mps, v3)?;
        if let Some((s, v)) = self.truth.at(f.stamp_ns) {
            self.band(&ent::chainage_error(pipeline), f.chainage_m - s, s3)?;
            self.band(&ent::speed_error(pipeline), f.speed_mps - v, v3)?;
        }
        for st in &f.sensor_states {
            let entity = ent::sensor_state(pipeline, &st.topic, &st.kind);
            if self.sensor_states.insert(entity.clone()) {
                let name = format!("{} {}", st.topic, st.kind);
                let style = SeriesLines::new()
                    .with_names([name.clone(), format!("{name} +3σ"), format!("{name} −3σ")])
                    .with_colors([color, band_color(), band_color()]);
                self.log_static(&entity, &style)?;
            }
            self.band(&entity, st.value, 3.0 * st.std)?;
        }
        Ok(())
    }

    /// A value with its ±3σ band: three series of one entity, so they share one plot.
    fn band(&mut self, entity: &str, value: f64, three_sigma: f64) -> Result<(), Error> {
        self.log(
            entity,
            &Scalars::new([value, value + three_sigma, value - three_sigma]),
        )
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
        if TcpStream::connect_timeout(&addr, std::time::Duration::from_secs(3)).is_ok() {
            return Ok(());
        }
    }
    Err(Error::Rerun(format!(
        "{url}: no Rerun viewer is listening there (start one with `rerun`)"
    )))
}
