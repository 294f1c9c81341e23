//! The `refuse` run: stream the input log once, copy every record to the output unchanged,
//! feed each pipeline the measurements of its channels, write `/fused/<name>/state`,
//! `/fused/<name>/diagnostics` (and `/fused/<name>/smoothed` where asked), and store each
//! pipeline's configuration as metadata. Scoring the result is [`crate::eval`]'s job.
//!
//! Memory is bounded by the reorder windows, never by the length of the log (the smoother
//! spills to a temporary file).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use railfuse_catalog::log::{read_channels, ChannelId, LogReader, LogRecord, LogWriter};
use railfuse_catalog::messages::{
    ChannelMessage, Event, EventKind, FusedDiagnostics, FusedState, TrackMap,
};
use railfuse_catalog::topics;
use serde::Serialize;

use crate::config::PipelinesConfig;
use crate::error::{Error, Result};
use crate::measurement::{SensorContext, SensorModel};
use crate::pipeline::{AnyPipeline, Fused, PipelineCounts};

pub struct RefuseOptions<'a> {
    pub input: &'a Path,
    pub output: &'a Path,
    pub config: &'a PipelinesConfig,
    /// Where the configuration came from (a path, or "embedded default"), for the metadata.
    pub config_source: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct PipelineReport {
    pub name: String,
    pub counts: PipelineCounts,
    pub fused_states: u64,
    pub smoothed_states: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct RefuseReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_messages: u64,
    pub input_bytes: u64,
    pub fused_messages: u64,
    /// Messages whose log time is earlier than the one before them in the file.
    pub out_of_order_messages: u64,
    /// Sensor messages the pipelines read that did not decode: skipped (copied unchanged).
    pub undecodable_messages: u64,
    /// The first of them, with the reason.
    pub first_undecodable: Option<String>,
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
}

#[derive(Clone, Copy)]
enum ContextKind {
    TrackMap,
    Events,
}

struct Output {
    state: ChannelId,
    diagnostics: ChannelId,
    smoothed: Option<ChannelId>,
    states: u64,
    smoothed_states: u64,
}

pub fn refuse(opts: &RefuseOptions<'_>) -> Result<RefuseReport> {
    let input = opts.input;
    let names: BTreeSet<&str> = opts
        .config
        .pipeline
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    let is_replaced =
        |topic: &str| topics::fused_pipeline_of(topic).is_some_and(|n| names.contains(n));
    let known = read_channels(input)?;
    if let Some(channels) = &known {
        for p in &opts.config.pipeline {
            for s in &p.sensor {
                match channels.iter().find(|c| c.topic == s.topic) {
                    None => {
                        let have: Vec<&str> = channels
                            .iter()
                            .map(|c| c.topic.as_str())
                            .filter(|t| !t.starts_with(topics::FUSED_PREFIX))
                            .collect();
                        return Err(channel_error(
                            input,
                            &p.name,
                            &s.topic,
                            format!("is not in the file (it has {})", have.join(", ")),
                        ));
                    }
                    Some(c) => check_sensor(input, p, s, c.schema_name())?,
                }
            }
        }
    }

    let mut writer = LogWriter::create(opts.output)?;
    // Output channels take the highest ids the input does not use, so copied records keep
    // theirs.
    let used: BTreeSet<u16> = known
        .iter()
        .flatten()
        .filter(|c| !is_replaced(&c.topic))
        .map(|c| c.id)
        .collect();
    let used_schemas: BTreeSet<u16> = known
        .iter()
        .flatten()
        .filter_map(|c| c.schema.as_ref().map(|s| s.id))
        .collect();
    let mut free = (1..=u16::MAX)
        .rev()
        .filter(|id| !used.contains(id) && !used_schemas.contains(id));
    let (state_schema, diag_schema) = (
        free.next().expect("ids to spare"),
        free.next().expect("ids to spare"),
    );
    let mut outputs = Vec::new();
    for p in &opts.config.pipeline {
        outputs.push(Output {
            state: writer.add_channel_with_ids::<FusedState>(
                state_schema,
                free.next().expect("ids"),
                &topics::fused_state(&p.name),
            )?,
            diagnostics: writer.add_channel_with_ids::<FusedDiagnostics>(
                diag_schema,
                free.next().expect("ids"),
                &topics::fused_diagnostics(&p.name),
            )?,
            smoothed: match p.smoother {
                true => Some(writer.add_channel_with_ids::<FusedState>(
                    state_schema,
                    free.next().expect("ids"),
                    &topics::fused_smoothed(&p.name),
                )?),
                false => None,
            },
            states: 0,
            smoothed_states: 0,
        });
    }

    let mut pipelines: Vec<AnyPipeline> = opts
        .config
        .pipeline
        .iter()
        .cloned()
        .map(AnyPipeline::new)
        .collect::<Result<_>>()?;
    let mut context = SensorContext::default();
    let mut measurements = Vec::new();
    let mut routes: HashMap<u16, Route> = HashMap::new();
    let mut seen_topics = BTreeSet::new();
    let mut fused_buf: Vec<Fused> = Vec::new();
    let mut report = RefuseReport {
        input: input.to_owned(),
        output: opts.output.to_owned(),
        input_messages: 0,
        input_bytes: 0,
        fused_messages: 0,
        out_of_order_messages: 0,
        undecodable_messages: 0,
        first_undecodable: None,
        pipelines: Vec::new(),
    };
    let mut last_log_time = 0u64;

    let mut reader = LogReader::open(input)?;
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Schema(s) => writer.copy_schema(s.id, &s.name, &s.encoding, &s.data)?,
            LogRecord::Channel(c) => {
                let mut route = Route::default();
                if is_replaced(&c.topic) {
                    route.replaced = true;
                } else {
                    writer.copy_channel(
                        c.id,
                        c.schema.as_ref().map_or(0, |s| s.id),
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )?;
                    seen_topics.insert(c.topic.clone());
                    route.context = match c.schema_name() {
                        n if n == TrackMap::SCHEMA_NAME => Some(ContextKind::TrackMap),
                        n if n == Event::SCHEMA_NAME => Some(ContextKind::Events),
                        _ => None,
                    };
                    for (pi, p) in pipelines.iter().enumerate() {
                        if let Some(si) = p.sensor_for(&c.topic) {
                            check_sensor(
                                input,
                                p.config(),
                                &p.config().sensor[si],
                                c.schema_name(),
                            )?;
                            route.sensors.push((pi, si));
                            route.model = SensorModel::for_schema(c.schema_name());
                        }
                    }
                }
                routes.insert(c.id, route);
            }
            LogRecord::Message(m) => {
                let route = &routes[&m.channel.id];
                if route.replaced {
                    continue;
                }
                report.input_messages += 1;
                if m.log_time_ns < last_log_time {
                    report.out_of_order_messages += 1;
                }
                last_log_time = last_log_time.max(m.log_time_ns);
                writer.write_raw(
                    m.channel.id,
                    m.sequence,
                    m.log_time_ns,
                    m.publish_time_ns,
                    m.data,
                )?;
                match route.context {
                    Some(ContextKind::TrackMap) => context.track = Some(m.decode(input)?),
                    Some(ContextKind::Events) => {
                        let e: Event = m.decode(input)?;
                        let failed = match e.kind {
                            EventKind::DeviceFault => Some(true),
                            EventKind::DeviceRecovered => Some(false),
                            _ => None,
                        };
                        if let Some(failed) = failed {
                            pipelines
                                .iter_mut()
                                .for_each(|p| p.device_event(&e.text, failed));
                        }
                    }
                    None => {}
                }
                if let Some(model) = route.model {
                    // A sensor message that does not decode (a null where a number belongs) is
                    // skipped and counted: one bad message must not cost the whole replay.
                    if let Err(e) = model.decode(&m, input, &context, &mut measurements) {
                        report.undecodable_messages += 1;
                        report
                            .first_undecodable
                            .get_or_insert_with(|| e.to_string());
                        continue;
                    }
                    for &(pi, si) in &route.sensors {
                        pipelines[pi].push(si, &measurements, m.log_time_ns, &mut fused_buf);
                        emit(
                            &mut writer,
                            &mut outputs[pi],
                            &mut fused_buf,
                            &mut report.fused_messages,
                        )?;
                    }
                }
            }
            LogRecord::Metadata { name, metadata } => {
                let replaced = name == topics::metadata::PIPELINE
                    && metadata
                        .get("pipeline")
                        .is_some_and(|p| names.contains(p.as_str()));
                if !replaced {
                    writer.write_metadata(&name, metadata)?;
                }
            }
            LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data,
            } => writer.attach(&name, &media_type, log_time_ns, create_time_ns, data)?,
        }
    }
    report.input_bytes = reader.bytes_read();

    for p in &opts.config.pipeline {
        for s in &p.sensor {
            if !seen_topics.contains(&s.topic) {
                return Err(channel_error(
                    input,
                    &p.name,
                    &s.topic,
                    "is not in the file".into(),
                ));
            }
        }
    }
    for (pi, p) in pipelines.iter_mut().enumerate() {
        p.finish(last_log_time, &mut fused_buf);
        emit(
            &mut writer,
            &mut outputs[pi],
            &mut fused_buf,
            &mut report.fused_messages,
        )?;
        if let (Some(channel), Some(smoothed)) = (outputs[pi].smoothed, p.smoothed()) {
            let spill = |source| Error::Spill {
                pipeline: p.name().to_owned(),
                source,
            };
            for state in smoothed.map_err(spill)? {
                let state = state.map_err(spill)?;
                writer.write(channel, state.stamp_ns, &state)?;
                report.fused_messages += 1;
                outputs[pi].smoothed_states += 1;
            }
        }
        let metadata = BTreeMap::from([
            ("pipeline".to_owned(), p.name().to_owned()),
            ("filter".to_owned(), p.config().filter.name().to_owned()),
            ("config_toml".to_owned(), p.config().to_toml()),
            ("config_source".to_owned(), opts.config_source.clone()),
            ("input".to_owned(), input.display().to_string()),
            (
                "tool_version".to_owned(),
                concat!("railfuse ", env!("CARGO_PKG_VERSION")).to_owned(),
            ),
            (
                "counts".to_owned(),
                serde_json::to_string(p.counts()).expect("counts serialise"),
            ),
        ]);
        writer.write_metadata(topics::metadata::PIPELINE, metadata)?;
    }
    writer.finish()?;

    for (p, out) in pipelines.iter().zip(&outputs) {
        report.pipelines.push(PipelineReport {
            name: p.name().to_owned(),
            counts: p.counts().clone(),
            fused_states: out.states,
            smoothed_states: out.smoothed_states,
        });
    }
    Ok(report)
}

fn emit(
    writer: &mut LogWriter,
    out: &mut Output,
    fused: &mut Vec<Fused>,
    count: &mut u64,
) -> Result<()> {
    for f in fused.drain(..) {
        if let Some(state) = &f.state {
            writer.write(out.state, f.log_time_ns, state)?;
            out.states += 1;
            *count += 1;
        }
        if let Some(d) = &f.diagnostics {
            writer.write(out.diagnostics, f.log_time_ns, d)?;
            *count += 1;
        }
    }
    Ok(())
}

/// The channel's schema has a sensor model, and that model gives the fields the sensor asks for.
fn check_sensor(
    input: &Path,
    p: &crate::config::PipelineConfig,
    s: &crate::config::SensorConfig,
    schema: &str,
) -> Result<()> {
    let Some(model) = SensorModel::for_schema(schema) else {
        let supported = SensorModel::SUPPORTED.join(", ");
        return Err(channel_error(
            input,
            &p.name,
            &s.topic,
            format!("has schema '{schema}', which no sensor model reads (supported: {supported})"),
        ));
    };
    let gives: Vec<&str> = model.quantities().iter().map(|q| q.name()).collect();
    let wanted = s
        .fields
        .clone()
        .unwrap_or_else(|| model.quantities().to_vec());
    for q in &wanted {
        if !model.quantities().contains(q) {
            return Err(channel_error(
                input,
                &p.name,
                &s.topic,
                format!("gives {} but not {}", gives.join(" and "), q.name()),
            ));
        }
        if q.index() >= p.motion.dimension() {
            return Err(channel_error(
                input,
                &p.name,
                &s.topic,
                format!(
                    "gives {}, which the {}-state motion model does not hold: set fields",
                    q.name(),
                    p.motion.dimension()
                ),
            ));
        }
        if s.variance.of(*q).is_none() {
            return Err(channel_error(
                input,
                &p.name,
                &s.topic,
                format!(
                    "gives {}, and the sensor's variance table has no entry for it",
                    q.name()
                ),
            ));
        }
    }
    for state in s.sensor_states() {
        let q = state.quantity();
        if !wanted.contains(&q) {
            return Err(channel_error(
                input,
                &p.name,
                &s.topic,
                format!(
                    "has a {} state but gives no {} to observe it",
                    state.kind(),
                    q.name()
                ),
            ));
        }
    }
    Ok(())
}

fn channel_error(input: &Path, pipeline: &str, topic: &str, problem: String) -> Error {
    Error::Channel {
        input: input.to_owned(),
        pipeline: pipeline.to_owned(),
        topic: topic.to_owned(),
        problem,
    }
}
