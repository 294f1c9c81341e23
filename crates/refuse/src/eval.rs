//! Evaluation of a log's fused channels against a reference: for every pipeline's states (and
//! its RTS-smoothed states), position and speed error RMSE, maximum and 95th percentile over
//! the whole run and over each marked window (injected faults, tunnels, correction outages,
//! reported device faults, from the `/events` channel); NEES of `[s, v]` and NIS of the
//! innovations as the share of epochs inside the 95 % χ² interval.
//!
//! The reference is the ground-truth channel or any channel the user names: another
//! pipeline's state, or a GNSS fix channel (an RTK receiver), matched on the track map.
//!
//! Streaming with bounded memory. Fused states lag the reference by at most a reorder window
//! and are scored in file order; smoothed states sit at the end of the file (they exist only
//! once the whole run is filtered), so they are scored in a second pass that walks the
//! reference with a second reader in step with them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{
    ChannelMessage, Event, EventKind, FusedDiagnostics, FusedState, GateDecision, GnssFix,
    GroundTruth, TrackMap,
};
use railfuse_catalog::topics;
use serde::Serialize;

use crate::accuracy::{
    AccuracyMeter, Consistency, ConsistencySummary, ErrorSummary, Span, CHI2_95_1DOF,
};
use crate::error::Result;
use crate::measurement::gnss_chainage;

#[derive(Debug, Clone, Serialize)]
pub struct WindowEval {
    pub label: String,
    pub position_error_m: Option<ErrorSummary>,
    pub speed_error_mps: Option<ErrorSummary>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PipelineEval {
    /// `<pipeline>` for its states, `<pipeline>/smoothed` for its smoothed states.
    pub name: String,
    pub pipeline: String,
    pub filter: Option<String>,
    pub states: u64,
    pub position_error_m: Option<ErrorSummary>,
    pub speed_error_mps: Option<ErrorSummary>,
    /// NEES of `[s, v]` against the state's own covariance.
    pub nees: Option<ConsistencySummary>,
    /// NIS of the measurements that reached the gate.
    pub nis: Option<ConsistencySummary>,
    pub gated: u64,
    /// Measurements used after a gate lockout (the filter's variance widened first).
    pub lockout_recoveries: u64,
    pub device_fault_rejections: u64,
    /// States outside the reference's time span.
    pub unmatched_states: u64,
    pub windows: Vec<WindowEval>,
}

#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    pub input: PathBuf,
    /// The reference topic, when the file has it with a usable schema.
    pub reference: Option<String>,
    pub windows: Vec<SpanReport>,
    pub pipelines: Vec<PipelineEval>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SpanReport {
    pub label: String,
    pub start_s: f64,
    pub end_s: Option<f64>,
}

#[derive(Clone, Copy, PartialEq)]
enum ReferenceKind {
    Truth,
    Fused,
    Gnss,
}

#[derive(Clone, Copy)]
enum Role {
    Reference(ReferenceKind),
    State(usize),
    Smoothed(usize),
    Diagnostics(usize),
    TrackMap,
    Events,
}

struct Scored {
    name: String,
    smoothed: bool,
    pipeline: String,
    meter: AccuracyMeter,
    states: u64,
    nis: Consistency,
    gated: u64,
    lockouts: u64,
    device_fault: u64,
}

impl Scored {
    fn new(name: String, pipeline: String) -> Self {
        // Fused states are released up to a reorder window (default 0.5 s) behind the
        // replay; 5 s covers any sane window.
        Self {
            smoothed: name.ends_with("/smoothed"),
            name,
            pipeline,
            meter: AccuracyMeter::new(5.0),
            states: 0,
            nis: Consistency::default(),
            gated: 0,
            lockouts: 0,
            device_fault: 0,
        }
    }
}

/// A reference sample from a reference message, if it gives one.
fn reference_sample(
    kind: ReferenceKind,
    m: &railfuse_catalog::log::LogMessage<'_>,
    path: &Path,
    map: Option<&TrackMap>,
) -> Result<Option<(u64, f64, f64)>> {
    Ok(match kind {
        ReferenceKind::Truth => {
            let t: GroundTruth = m.decode(path)?;
            Some((t.stamp_ns, t.chainage_m, t.speed_mps))
        }
        ReferenceKind::Fused => {
            let t: FusedState = m.decode(path)?;
            Some((t.stamp_ns, t.chainage_m, t.speed_mps))
        }
        ReferenceKind::Gnss => {
            let g: GnssFix = m.decode(path)?;
            match (gnss_chainage(&g, map), g.speed_mps) {
                (Some((s, _, _)), Some(v)) => Some((g.stamp_ns, s, v)),
                _ => None,
            }
        }
    })
}

/// A marked window from an event: (label, opens).
fn window_of(e: &Event) -> Option<(String, bool)> {
    let trimmed = |suffix: &str| e.text.strip_suffix(suffix).unwrap_or(&e.text).to_owned();
    Some(match e.kind {
        EventKind::FaultInjected => (format!("fault {}", trimmed(" starts")), true),
        EventKind::FaultCleared => (format!("fault {}", trimmed(" ends")), false),
        EventKind::TunnelEntry => ("tunnel".into(), true),
        EventKind::TunnelExit => ("tunnel".into(), false),
        EventKind::CorrectionLinkDown => ("no RTK corrections".into(), true),
        EventKind::CorrectionLinkUp => ("no RTK corrections".into(), false),
        EventKind::DeviceFault => (format!("reported fault {}", e.text), true),
        EventKind::DeviceRecovered => (format!("reported fault {}", e.text), false),
        _ => return None,
    })
}

pub fn evaluate(input: &Path, reference_topic: &str) -> Result<EvalReport> {
    let mut scored: Vec<Scored> = Vec::new();
    let mut roles: BTreeMap<u16, Role> = BTreeMap::new();
    let mut spans: Vec<Span> = Vec::new();
    let mut filters: BTreeMap<String, String> = BTreeMap::new();
    let mut map: Option<TrackMap> = None;
    let mut reference: Option<ReferenceKind> = None;
    let mut smoothed_channels = false;
    let mut first_ns: Option<u64> = None;
    let index_of = |scored: &mut Vec<Scored>, name: String, pipeline: &str| match scored
        .iter()
        .position(|s| s.name == name)
    {
        Some(i) => i,
        None => {
            scored.push(Scored::new(name, pipeline.to_owned()));
            scored.len() - 1
        }
    };

    let mut reader = LogReader::open(input)?;
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                let schema = c.schema_name();
                let role = if c.topic == reference_topic {
                    let kind = match schema {
                        s if s == GroundTruth::SCHEMA_NAME => Some(ReferenceKind::Truth),
                        s if s == FusedState::SCHEMA_NAME => Some(ReferenceKind::Fused),
                        s if s == GnssFix::SCHEMA_NAME => Some(ReferenceKind::Gnss),
                        _ => None,
                    };
                    reference = reference.or(kind);
                    kind.map(Role::Reference)
                } else if let Some(p) = topics::fused_pipeline_of(&c.topic) {
                    match c.topic.rsplit('/').next() {
                        Some("state") if schema == FusedState::SCHEMA_NAME => {
                            Some(Role::State(index_of(&mut scored, p.to_owned(), p)))
                        }
                        Some("smoothed") if schema == FusedState::SCHEMA_NAME => {
                            smoothed_channels = true;
                            Some(Role::Smoothed(index_of(
                                &mut scored,
                                format!("{p}/smoothed"),
                                p,
                            )))
                        }
                        Some("diagnostics") if schema == FusedDiagnostics::SCHEMA_NAME => {
                            Some(Role::Diagnostics(index_of(&mut scored, p.to_owned(), p)))
                        }
                        _ => None,
                    }
                } else if schema == TrackMap::SCHEMA_NAME {
                    Some(Role::TrackMap)
                } else if schema == Event::SCHEMA_NAME {
                    Some(Role::Events)
                } else {
                    None
                };
                if let Some(r) = role {
                    roles.insert(c.id, r);
                }
            }
            LogRecord::Message(m) => {
                first_ns = Some(first_ns.map_or(m.log_time_ns, |f: u64| f.min(m.log_time_ns)));
                match roles.get(&m.channel.id).copied() {
                    Some(Role::Reference(kind)) => {
                        if let Some((t, s, v)) = reference_sample(kind, &m, input, map.as_ref())? {
                            // Smoothed channels get the reference in their own later pass.
                            for x in scored.iter_mut().filter(|x| !x.smoothed) {
                                x.meter.add_reference(t, s, v, &spans);
                            }
                        }
                    }
                    Some(Role::State(i)) => {
                        let st: FusedState = m.decode(input)?;
                        scored[i].meter.add_estimate(&st, &spans);
                        scored[i].states += 1;
                    }
                    Some(Role::Diagnostics(i)) => {
                        let d: FusedDiagnostics = m.decode(input)?;
                        match d.decision {
                            GateDecision::Accepted => {}
                            GateDecision::RejectedGate => scored[i].gated += 1,
                            GateDecision::AcceptedAfterLockout => {
                                scored[i].lockouts += 1;
                                continue;
                            }
                            GateDecision::RejectedDeviceFault => scored[i].device_fault += 1,
                            _ => continue,
                        }
                        if let (Some(nis), GateDecision::Accepted | GateDecision::RejectedGate) =
                            (d.nis, d.decision)
                        {
                            scored[i].nis.add(nis, CHI2_95_1DOF);
                        }
                    }
                    Some(Role::TrackMap) => map = Some(m.decode(input)?),
                    Some(Role::Events) => {
                        let e: Event = m.decode(input)?;
                        if let Some((label, opens)) = window_of(&e) {
                            if opens {
                                spans.push(Span {
                                    label,
                                    start_ns: e.stamp_ns,
                                    end_ns: None,
                                });
                            } else if let Some(s) = spans
                                .iter_mut()
                                .rev()
                                .find(|s| s.label == label && s.end_ns.is_none())
                            {
                                s.end_ns = Some(e.stamp_ns);
                            }
                        }
                    }
                    Some(Role::Smoothed(_)) | None => {}
                }
            }
            LogRecord::Metadata { name, metadata } if name == topics::metadata::PIPELINE => {
                if let (Some(p), Some(f)) = (metadata.get("pipeline"), metadata.get("filter")) {
                    filters.insert(p.clone(), f.clone());
                }
            }
            _ => {}
        }
    }
    if smoothed_channels && reference.is_some() {
        score_smoothed(input, &roles, &mut scored, &spans)?;
    }

    let t0 = first_ns.unwrap_or(0);
    let pipelines = scored
        .into_iter()
        .filter(|s| s.states > 0 || s.gated > 0 || s.nis.summary().is_some())
        .map(|mut s| {
            s.meter.finish();
            PipelineEval {
                filter: filters.get(&s.pipeline).cloned(),
                name: s.name,
                pipeline: s.pipeline,
                states: s.states,
                position_error_m: s.meter.position.summary(),
                speed_error_mps: s.meter.speed.summary(),
                nees: s.meter.nees.summary(),
                nis: s.nis.summary(),
                gated: s.gated,
                lockout_recoveries: s.lockouts,
                device_fault_rejections: s.device_fault,
                unmatched_states: s.meter.unmatched,
                windows: s
                    .meter
                    .windows
                    .iter()
                    .map(|w| WindowEval {
                        label: w.label.clone(),
                        position_error_m: w.position.summary(),
                        speed_error_mps: w.speed.summary(),
                    })
                    .collect(),
            }
        })
        .collect();
    let secs = |t: u64| t.saturating_sub(t0) as f64 / 1e9;
    Ok(EvalReport {
        input: input.to_owned(),
        reference: reference.map(|_| reference_topic.to_owned()),
        windows: spans
            .iter()
            .map(|s| SpanReport {
                label: s.label.clone(),
                start_s: secs(s.start_ns),
                end_s: s.end_ns.map(secs),
            })
            .collect(),
        pipelines,
    })
}

/// Later passes for smoothed states, one per smoothed channel: one reader walks its states,
/// another the reference, in step.
fn score_smoothed(
    input: &Path,
    roles: &BTreeMap<u16, Role>,
    scored: &mut [Scored],
    spans: &[Span],
) -> Result<()> {
    let channels: Vec<(u16, usize)> = roles
        .iter()
        .filter_map(|(&id, r)| {
            if let Role::Smoothed(i) = r {
                Some((id, *i))
            } else {
                None
            }
        })
        .collect();
    for (channel, i) in channels {
        let mut estimates = LogReader::open(input)?;
        let mut refs = LogReader::open(input)?;
        let mut map: Option<TrackMap> = None;
        let mut refs_done = false;
        while let Some(record) = estimates.next() {
            let LogRecord::Message(m) = record? else {
                continue;
            };
            if m.channel.id != channel {
                continue;
            }
            let st: FusedState = m.decode(input)?;
            // Feed the reference until it has passed this state's stamp.
            while !refs_done
                && scored[i]
                    .meter
                    .reference_newest_ns()
                    .is_none_or(|n| n < st.stamp_ns)
            {
                let Some(r) = refs.next() else {
                    refs_done = true;
                    break;
                };
                let LogRecord::Message(rm) = r? else { continue };
                match roles.get(&rm.channel.id).copied() {
                    Some(Role::TrackMap) => map = Some(rm.decode(input)?),
                    Some(Role::Reference(kind)) => {
                        if let Some((t, s, v)) = reference_sample(kind, &rm, input, map.as_ref())? {
                            scored[i].meter.add_reference(t, s, v, spans);
                        }
                    }
                    _ => {}
                }
            }
            scored[i].meter.add_estimate(&st, spans);
            scored[i].states += 1;
        }
    }
    Ok(())
}
