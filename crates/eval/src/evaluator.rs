use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use railfuse_catalog::foreign::ForeignChannels;
use railfuse_catalog::log::{ChannelInfo, LogMessage, LogRecord};
use railfuse_catalog::messages::{
    BalisePassage, ChannelMessage, Event, EventKind, FusedDiagnostics, FusedState, GateDecision,
    GnssFix, GroundTruth, SafetyStatus, SensorMount, TrackMap, TrainPosition, Vehicle,
};
use railfuse_catalog::run::{Run, RunReader};
use railfuse_catalog::topics::{self, FusedChannel};
use serde::Serialize;

use crate::accuracy::{
    AccuracyMeter, Consistency, ConsistencySummary, ErrorSummary, Interval, PlaneMeter,
    PlaneSample, PlaneSummary, Span, CHI2_95_1DOF,
};
use crate::fix_match::{FixMatchReport, FixMeter, FixQuality, FixSample, Reference, StateAt};
use crate::outages::{OutageEval, OutageWindow, Withheld};
use crate::safety::{SafetyEval, SafetyTally};
use railfuse_catalog::Result;

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
    /// The share of states whose position error exceeded 3σ of their own chainage variance
    /// (a silent divergence in one number; about 0.3 % for a consistent filter).
    pub beyond_3_sigma: Option<f64>,
    /// NIS of the measurements that reached the gate.
    pub nis: Option<ConsistencySummary>,
    pub gated: u64,
    /// Measurements used after a gate lockout (the filter's variance widened first).
    pub lockout_recoveries: u64,
    /// Absolute fixes the estimate was reset to (the gate had rejected their sensor too often
    /// in a row).
    pub resets_to_fix: u64,
    pub device_fault_rejections: u64,
    /// States outside the reference's time span.
    pub unmatched_states: u64,
    /// States inside a gap of the reference (its samples further apart than
    /// `MAX_GAP_PERIODS` of its periods): not scored.
    pub states_in_reference_gaps: u64,
    /// Against GNSS fixes: which fixes counted, how many were matched (the states interpolated
    /// to each fix's time) and the largest time to a state.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_fixes: Option<FixMatchReport>,
    /// Pipelines in the plane against GNSS fixes: the error across the track (state's offset
    /// from the centre line less the fix's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub across_track_error_m: Option<ErrorSummary>,
    /// The sensor withheld from it (the withholding protocol), and its errors in each outage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub withheld: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outages: Option<OutageEval>,
    pub windows: Vec<WindowEval>,
    /// Pipelines with safety checks: S7, availability, containment and caught faults.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyEval>,
    /// How often the train channel's safe front end interval held the reference's front
    /// end, beside the confidence it states.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safe_front: Option<SafeFrontEval>,
    /// 2-D pipelines against a ground-truth reference: east/north position and velocity
    /// errors in the plane.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane: Option<PlaneSummary>,
}

/// The safe front end interval against the reference: held `share` of the time, where a
/// filter honest about its error holds it at least `confidence` of the time.
#[derive(Debug, Clone, Serialize)]
pub struct SafeFrontEval {
    pub confidence: f64,
    pub checked: u64,
    pub contained: u64,
    pub share: f64,
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
pub enum ReferenceKind {
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
    Safety(usize),
    Train(usize),
    TrackMap,
    /// The log's `/vehicle`: where a GNSS reference's antenna sits.
    Vehicle,
    Events,
    Balise,
}

/// The window from the first balise passage to the end of the run.
pub const AFTER_FIRST_BALISE: &str = "after the first balise";

struct Scored {
    name: String,
    smoothed: bool,
    pipeline: String,
    meter: AccuracyMeter,
    states: u64,
    nis: Consistency,
    gated: u64,
    lockouts: u64,
    resets: u64,
    device_fault: u64,
    safety: Option<SafetyTally>,
    plane: PlaneMeter,
    /// Against GNSS fixes: the states interpolated to each fix.
    fixes: FixMeter,
    /// The confidence its train channel states for the safe front end interval.
    safe_front_confidence: Option<f64>,
}

impl Scored {
    fn new(name: String, pipeline: String, lag_s: f64, quality: FixQuality) -> Self {
        Self {
            smoothed: name.ends_with("/smoothed"),
            name,
            pipeline,
            meter: AccuracyMeter::new(lag_s),
            states: 0,
            nis: Consistency::default(),
            gated: 0,
            lockouts: 0,
            resets: 0,
            device_fault: 0,
            safety: None,
            safe_front_confidence: None,
            plane: PlaneMeter::new(lag_s),
            fixes: FixMeter::new(quality, lag_s),
        }
    }

    fn set_outages(&mut self, windows: &[OutageWindow]) {
        self.meter.outages = crate::outages::OutageMeter::new(windows);
        self.fixes.set_outages(windows);
    }

    /// A state (fused or smoothed): to the meter of the reference's kind; `map` places a
    /// pipeline in the plane across the track.
    fn add_state(
        &mut self,
        state: &FusedState,
        (reference, map): (Option<ReferenceKind>, Option<&TrackMap>),
        spans: &[Span],
    ) {
        match reference {
            Some(ReferenceKind::Gnss) => {}
            _ => self.meter.add_estimate(state, spans),
        }
        // Kept a few seconds only: the reference kind may be known only once its channel
        // turns up, after the first states.
        let lateral_m = state
            .plane
            .as_ref()
            .zip(map)
            .and_then(|(p, m)| m.lateral_offset(p.east_m, p.north_m));
        let at = StateAt {
            stamp_ns: state.stamp_ns,
            chainage_m: state.chainage_m,
            speed_mps: state.speed_mps,
            variance_m2: state.covariance[0],
            lateral_m,
        };
        self.fixes.add_state(&at, spans);
        self.states += 1;
    }
}

/// A reference sample from a reference message, if it gives one (a GNSS fix moved from the
/// `antenna` to the front end, which the states are).
pub fn reference_sample(
    kind: ReferenceKind,
    m: &railfuse_catalog::log::LogMessage<'_>,
    path: &Path,
    (map, antenna): (Option<&TrackMap>, Option<&SensorMount>),
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
            let front = |(s, _, _)| front_chainage(map, antenna, s);
            match (
                map.and_then(|t| t.chainage_of_fix(&g)).map(front),
                g.speed_mps,
            ) {
                (Some(s), Some(v)) => Some((g.stamp_ns, s, v)),
                _ => None,
            }
        }
    })
}

/// The front end's chainage when the GNSS `antenna` (the log's `/vehicle` places it) is
/// matched on the map at `chainage_m`: a roof antenna 12.5 m behind the cab gives fixes
/// 12.5 m behind the front end the states are.
fn front_chainage(map: Option<&TrackMap>, antenna: Option<&SensorMount>, chainage_m: f64) -> f64 {
    match (map, antenna) {
        (Some(map), Some(a)) => a.front_chainage_of_point(map, chainage_m),
        _ => chainage_m,
    }
}

/// A GNSS reference fix on the track map, moved from the `antenna` to the front end, with its
/// speed where it has one; `None` for a fix without a position, off the line's ends, or
/// before there is a map.
pub fn fix_sample(
    m: &railfuse_catalog::log::LogMessage<'_>,
    path: &Path,
    (map, antenna): (Option<&TrackMap>, Option<&SensorMount>),
) -> Result<Option<FixSample>> {
    let g: GnssFix = m.decode(path)?;
    Ok(map.and_then(|t| {
        let (s, variance_m2, _) = t.chainage_of_fix(&g)?;
        Some(FixSample {
            stamp_ns: g.stamp_ns,
            log_time_ns: m.log_time_ns,
            fix_type: g.fix_type,
            chainage_m: front_chainage(map, antenna, s),
            speed_mps: g.speed_mps,
            variance_m2,
            lateral_m: t.lateral_of_fix(&g),
        })
    }))
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

/// The evaluation of one log, fed record by record: by [`evaluate`] from a file, or by the
/// `refuse` replay as it goes (input records, and its fused outputs without a JSON round trip).
pub struct Evaluator {
    path: PathBuf,
    reference_topic: String,
    /// How far fused states may lag the reference in file order, s.
    lag_s: f64,
    scored: Vec<Scored>,
    roles: BTreeMap<u16, Role>,
    spans: Vec<Span>,
    filters: BTreeMap<String, String>,
    map: Option<TrackMap>,
    /// Where the reference's GNSS antenna sits on the train (the log's `/vehicle`).
    antenna: Option<SensorMount>,
    reference: Option<ReferenceKind>,
    smoothed_channels: bool,
    /// Smoothed channels whose states come straight from the replay, each with the reference
    /// walked beside them.
    smoothed_fed: BTreeMap<u16, ReferenceWalk>,
    first_ns: Option<u64>,
    /// Which fixes of a GNSS reference count.
    quality: FixQuality,
    /// Each pipeline's withheld sensor and outages.
    withheld: BTreeMap<String, Withheld>,
    /// Outages given for every pipeline (`eval --withhold --outages`), over the log's record.
    withheld_everywhere: Option<Withheld>,
}

impl Evaluator {
    /// `lag_s`: how far a fused state may trail its reference (the reorder window, plus a
    /// chunk's time span where fused chunks follow the input chunk they came from).
    pub fn new(path: &Path, reference: &Reference, lag_s: f64) -> Self {
        Self {
            path: path.to_owned(),
            reference_topic: reference.topic.clone(),
            lag_s,
            scored: Vec::new(),
            roles: BTreeMap::new(),
            spans: Vec::new(),
            filters: BTreeMap::new(),
            map: None,
            antenna: None,
            reference: None,
            smoothed_channels: false,
            smoothed_fed: BTreeMap::new(),
            first_ns: None,
            quality: reference.quality.clone(),
            withheld: BTreeMap::new(),
            withheld_everywhere: None,
        }
    }

    /// Scores every pipeline as if `w.topic` had been withheld from it in `w.windows` (a
    /// log fused elsewhere); the log's own `railfuse.withheld` records are then ignored.
    pub fn withheld_everywhere(&mut self, w: &Withheld) {
        for s in &mut self.scored {
            s.set_outages(&w.windows);
        }
        self.mark_outages(w);
        self.withheld_everywhere = Some(w.clone());
    }

    /// The outages as marked windows.
    fn mark_outages(&mut self, w: &Withheld) {
        let label = format!("withheld {}", w.topic);
        for window in &w.windows {
            let span = Span {
                label: label.clone(),
                start_ns: window.start_ns,
                end_ns: Some(window.end_ns),
            };
            if !self.spans.contains(&span) {
                self.spans.push(span);
            }
        }
    }

    /// What was withheld from `pipeline`.
    fn withheld_from(&self, pipeline: &str) -> Option<&Withheld> {
        self.withheld_everywhere
            .as_ref()
            .or_else(|| self.withheld.get(pipeline))
    }

    /// `pipeline` did not see `w.topic` inside `w.windows` (or at all): its errors there are
    /// reported outage by outage, and the outages are marked windows.
    pub fn withheld(&mut self, pipeline: &str, w: &Withheld) {
        if self.withheld_everywhere.is_some() {
            return;
        }
        for s in self.scored.iter_mut().filter(|s| s.pipeline == pipeline) {
            s.set_outages(&w.windows);
        }
        self.mark_outages(w);
        self.withheld.insert(pipeline.to_owned(), w.clone());
    }

    fn index_of(&mut self, name: String, pipeline: &str) -> usize {
        match self.scored.iter().position(|s| s.name == name) {
            Some(i) => i,
            None => {
                let quality = self.quality.clone();
                let mut s = Scored::new(name, pipeline.to_owned(), self.lag_s, quality);
                if let Some(w) = self.withheld_from(pipeline) {
                    s.set_outages(&w.windows);
                }
                self.scored.push(s);
                self.scored.len() - 1
            }
        }
    }

    /// Takes in a channel; says whether the evaluation reads its messages.
    pub fn channel(&mut self, id: u16, topic: &str, schema: &str) -> bool {
        let role = if topic == self.reference_topic {
            let kind = reference_kind(schema);
            self.reference = self.reference.or(kind);
            kind.map(Role::Reference)
        } else if let Some((p, channel)) = topics::parse_fused(topic) {
            match (channel, schema) {
                (FusedChannel::State, s) if s == FusedState::SCHEMA_NAME => {
                    Some(Role::State(self.index_of(p.to_owned(), p)))
                }
                (FusedChannel::Smoothed, s) if s == FusedState::SCHEMA_NAME => {
                    self.smoothed_channels = true;
                    Some(Role::Smoothed(self.index_of(format!("{p}/smoothed"), p)))
                }
                (FusedChannel::Diagnostics, s) if s == FusedDiagnostics::SCHEMA_NAME => {
                    Some(Role::Diagnostics(self.index_of(p.to_owned(), p)))
                }
                (FusedChannel::Safety, s) if s == SafetyStatus::SCHEMA_NAME => {
                    Some(Role::Safety(self.index_of(p.to_owned(), p)))
                }
                (FusedChannel::Train, s) if s == TrainPosition::SCHEMA_NAME => {
                    Some(Role::Train(self.index_of(p.to_owned(), p)))
                }
                _ => None,
            }
        } else if schema == TrackMap::SCHEMA_NAME {
            Some(Role::TrackMap)
        } else if schema == Vehicle::SCHEMA_NAME {
            Some(Role::Vehicle)
        } else if schema == Event::SCHEMA_NAME {
            Some(Role::Events)
        } else if schema == BalisePassage::SCHEMA_NAME {
            Some(Role::Balise)
        } else {
            None
        };
        if let Some(r) = role {
            self.roles.insert(id, r);
        }
        role.is_some_and(|r| !matches!(r, Role::Smoothed(_)))
    }

    /// The log time of any message of the file (the report's times count from the first).
    pub fn log_time(&mut self, t_ns: u64) {
        self.first_ns = Some(self.first_ns.map_or(t_ns, |f| f.min(t_ns)));
    }

    /// A message of a channel [`Evaluator::channel`] said it reads.
    pub fn message(&mut self, m: &LogMessage<'_>) -> Result<()> {
        let path = &self.path;
        match self.roles.get(&m.channel.id).copied() {
            Some(Role::Reference(ReferenceKind::Truth)) => {
                // The fields scored along the track and in the plane, in one parse (100 Hz).
                let g: GroundTruth = m.decode(path)?;
                self.reference_sample(g.stamp_ns, g.chainage_m, g.speed_mps);
                let (sin, cos) = g.heading_rad.sin_cos();
                let sample = PlaneSample {
                    stamp_ns: g.stamp_ns,
                    east_m: g.east_m,
                    north_m: g.north_m,
                    velocity_en_mps: (g.speed_mps * sin, g.speed_mps * cos),
                };
                for x in self.scored.iter_mut().filter(|x| !x.smoothed) {
                    x.plane.add_truth(sample);
                }
            }
            Some(Role::Reference(ReferenceKind::Gnss)) => {
                let place = (self.map.as_ref(), self.antenna.as_ref());
                if let Some(fix) = fix_sample(m, path, place)? {
                    for x in self.scored.iter_mut().filter(|x| !x.smoothed) {
                        x.fixes.add_fix(fix, &self.spans);
                    }
                }
            }
            Some(Role::Reference(kind)) => {
                let place = (self.map.as_ref(), self.antenna.as_ref());
                if let Some((t, s, v)) = reference_sample(kind, m, path, place)? {
                    self.reference_sample(t, s, v);
                }
            }
            Some(Role::State(_)) => self.fused_state(m.channel.id, &m.decode(path)?),
            Some(Role::Diagnostics(_)) => self.fused_diagnostics(m.channel.id, &m.decode(path)?),
            Some(Role::Safety(_)) => self.safety_status(m.channel.id, &m.decode(path)?),
            Some(Role::Train(_)) => self.train_position(m.channel.id, &m.decode(path)?),
            Some(Role::TrackMap) => self.map = Some(m.decode(path)?),
            Some(Role::Vehicle) => {
                let v: Vehicle = m.decode(path)?;
                self.antenna = v.mount(&self.reference_topic).cloned();
            }
            Some(Role::Events) => {
                let e: Event = m.decode(path)?;
                if let Some((label, opens)) = window_of(&e) {
                    if opens {
                        self.spans.push(Span {
                            label,
                            start_ns: e.stamp_ns,
                            end_ns: None,
                        });
                    } else if let Some(s) = self
                        .spans
                        .iter_mut()
                        .rev()
                        .find(|s| s.label == label && s.end_ns.is_none())
                    {
                        s.end_ns = Some(e.stamp_ns);
                    }
                }
            }
            Some(Role::Balise) => {
                if !self.spans.iter().any(|s| s.label == AFTER_FIRST_BALISE) {
                    let b: BalisePassage = m.decode(path)?;
                    self.spans.push(Span {
                        label: AFTER_FIRST_BALISE.to_owned(),
                        start_ns: b.stamp_ns,
                        end_ns: None,
                    });
                }
            }
            Some(Role::Smoothed(_)) | None => {}
        }
        Ok(())
    }

    fn reference_sample(&mut self, t: u64, s: f64, v: f64) {
        // Smoothed channels get the reference in their own later pass.
        for x in self.scored.iter_mut().filter(|x| !x.smoothed) {
            x.meter.add_reference(t, s, v, &self.spans);
        }
    }

    /// A fused state on channel `id` (a `/fused/<name>/state` channel).
    pub fn fused_state(&mut self, id: u16, state: &FusedState) {
        if let Some(Role::State(i)) = self.roles.get(&id).copied() {
            let against = (self.reference, self.map.as_ref());
            self.scored[i].add_state(state, against, &self.spans);
            self.scored[i].plane.add_state(state);
        }
    }

    /// A smoothed state on channel `id`, straight from the smoother; the reference is read
    /// from `reference_log` (the replay's input) in step with them.
    pub fn smoothed_state(
        &mut self,
        id: u16,
        state: &FusedState,
        reference_log: &Run,
    ) -> Result<()> {
        let Some(Role::Smoothed(i)) = self.roles.get(&id).copied() else {
            return Ok(());
        };
        if self.reference.is_none() {
            return Ok(());
        }
        let walk = match self.smoothed_fed.entry(id) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(ReferenceWalk::open(reference_log, &self.reference_topic)?)
            }
        };
        let s = &mut self.scored[i];
        walk.feed_until(s, state.stamp_ns, &self.spans)?;
        s.add_state(state, (self.reference, self.map.as_ref()), &self.spans);
        Ok(())
    }

    /// A fused diagnostics record on channel `id`.
    pub fn fused_diagnostics(&mut self, id: u16, d: &FusedDiagnostics) {
        let Some(Role::Diagnostics(i)) = self.roles.get(&id).copied() else {
            return;
        };
        let s = &mut self.scored[i];
        match d.decision {
            GateDecision::Accepted => {}
            GateDecision::RejectedGate => s.gated += 1,
            GateDecision::AcceptedAfterLockout => {
                s.lockouts += 1;
                return;
            }
            GateDecision::ResetToFix => {
                s.resets += 1;
                return;
            }
            GateDecision::RejectedDeviceFault => s.device_fault += 1,
            _ => return,
        }
        if let (Some(nis), GateDecision::Accepted | GateDecision::RejectedGate) =
            (d.nis, d.decision)
        {
            s.nis.add(nis, CHI2_95_1DOF);
        }
    }

    /// A safety status on channel `id` (a `/fused/<name>/safety` channel): tallied for S7,
    /// and its safe interval checked against the reference.
    pub fn safety_status(&mut self, id: u16, status: &SafetyStatus) {
        let Some(Role::Safety(i)) = self.roles.get(&id).copied() else {
            return;
        };
        let s = &mut self.scored[i];
        s.safety
            .get_or_insert_with(SafetyTally::default)
            .add(status, &self.spans);
        if let Some(u) = status.safe_interval.filter(|_| status.usable) {
            s.meter
                .add_interval(status.stamp_ns, u.low_m, u.high_m, Interval::SafetyCheck);
        }
    }

    /// A pipeline's train on channel `id`: does its safe front end interval hold the
    /// reference?
    pub fn train_position(&mut self, id: u16, train: &TrainPosition) {
        let Some(Role::Train(i)) = self.roles.get(&id).copied() else {
            return;
        };
        let s = &mut self.scored[i];
        s.safe_front_confidence = Some(train.confidence);
        let (low, high) = (train.min_safe_front_m, train.max_safe_front_m);
        s.meter
            .add_interval(train.stamp_ns, low, high, Interval::SafeFront);
    }

    /// A metadata record (pipeline records name each pipeline's filter; withheld records
    /// its outages).
    pub fn metadata(&mut self, name: &str, metadata: &BTreeMap<String, String>) {
        if name == topics::metadata::WITHHELD {
            if let (Some(p), Some(w)) =
                (metadata.get("pipeline"), Withheld::from_metadata(metadata))
            {
                self.withheld(&p.clone(), &w);
            }
        }
        if name == topics::metadata::PIPELINE {
            if let (Some(p), Some(f)) = (metadata.get("pipeline"), metadata.get("filter")) {
                self.filters.insert(p.clone(), f.clone());
            }
        }
    }

    /// The report. Smoothed states not fed directly are scored from `log` (a run holding
    /// them and the reference) in passes of their own; a part the run is missing is named
    /// among the windows.
    pub fn finish(mut self, log: &Run) -> Result<EvalReport> {
        if self.smoothed_channels && self.reference.is_some() {
            self.score_smoothed_from(log)?;
        }
        let t0 = self.first_ns.unwrap_or(0);
        for s in &mut self.scored {
            s.fixes.finish(&self.spans);
        }
        let withheld: Vec<Option<String>> = self
            .scored
            .iter()
            .map(|s| self.withheld_from(&s.pipeline).map(|w| w.topic.clone()))
            .collect();
        let filters = self.filters;
        let against = self.reference;
        let pipelines = self
            .scored
            .into_iter()
            .zip(withheld)
            // A pipeline that judged epochs without fusing any (S1 on a log of GNSS alone)
            // still has its S7 to report.
            .filter(|(s, _)| {
                s.states > 0 || s.gated > 0 || s.nis.summary().is_some() || s.safety.is_some()
            })
            .map(|(s, withheld)| {
                let mut e = pipeline_eval(s, &filters, t0, against);
                e.withheld = withheld;
                e
            })
            .collect();
        let secs = |t: u64| t.saturating_sub(t0) as f64 / 1e9;
        let missing = log.missing().iter().filter_map(|m| {
            let start = m.start_ns?;
            Some(SpanReport {
                label: format!("missing part {}", m.path.display()),
                start_s: secs(start),
                end_s: m.duration_ns.map(|d| secs(start + d)),
            })
        });
        let spans = self.spans.iter().map(|s| SpanReport {
            label: s.label.clone(),
            start_s: secs(s.start_ns),
            end_s: s.end_ns.map(secs),
        });
        Ok(EvalReport {
            input: self.path,
            reference: self.reference.map(|_| self.reference_topic),
            windows: spans.chain(missing).collect(),
            pipelines,
        })
    }

    /// Scores the smoothed channels the replay did not feed from `log`.
    fn score_smoothed_from(&mut self, log: &Run) -> Result<()> {
        let channels: Vec<(u16, usize)> = self
            .roles
            .iter()
            .filter(|(id, _)| !self.smoothed_fed.contains_key(id))
            .filter_map(|(&id, r)| match r {
                Role::Smoothed(i) => Some((id, *i)),
                _ => None,
            })
            .collect();
        score_smoothed(
            log,
            (&self.reference_topic, self.reference),
            &channels,
            &mut self.scored,
            &self.spans,
        )
    }
}

/// One pipeline's line of the report.
fn pipeline_eval(
    mut s: Scored,
    filters: &BTreeMap<String, String>,
    t0: u64,
    against: Option<ReferenceKind>,
) -> PipelineEval {
    s.meter.finish();
    let safety = s.safety.take().map(|t| t.finish(s.meter.containment, t0));
    let held = s.meter.safe_front;
    let safe_front = s
        .safe_front_confidence
        .filter(|_| held.checked > 0)
        .map(|confidence| SafeFrontEval {
            confidence,
            checked: held.checked,
            contained: held.contained,
            share: held.contained as f64 / held.checked as f64,
        });
    let windows = |w: &[crate::accuracy::WindowStats]| {
        w.iter()
            .map(|w| WindowEval {
                label: w.label.clone(),
                position_error_m: w.position.summary(),
                speed_error_mps: w.speed.summary(),
            })
            .collect()
    };
    let mut eval = PipelineEval {
        safety,
        safe_front,
        plane: s.plane.summary(),
        filter: filters.get(&s.pipeline).cloned(),
        name: s.name,
        pipeline: s.pipeline,
        states: s.states,
        position_error_m: s.meter.position.summary(),
        speed_error_mps: s.meter.speed.summary(),
        nees: s.meter.nees.summary(),
        beyond_3_sigma: s.meter.beyond_3_sigma.share(),
        nis: s.nis.summary(),
        gated: s.gated,
        lockout_recoveries: s.lockouts,
        resets_to_fix: s.resets,
        device_fault_rejections: s.device_fault,
        unmatched_states: s.meter.unmatched,
        states_in_reference_gaps: s.meter.in_reference_gaps,
        reference_fixes: None,
        across_track_error_m: None,
        withheld: None,
        outages: s.meter.outages.report(t0),
        windows: windows(&s.meter.windows),
    };
    if against == Some(ReferenceKind::Gnss) {
        // Scored at the fixes: the states' own counts against a reference do not apply, and
        // NEES needs a reference speed (and an error free of the sensor's own noise).
        let f = &s.fixes;
        eval.position_error_m = f.position();
        eval.speed_error_mps = f.speed();
        eval.beyond_3_sigma = f.beyond_3_sigma();
        eval.nees = None;
        eval.unmatched_states = 0;
        eval.states_in_reference_gaps = 0;
        eval.windows = windows(f.windows());
        eval.reference_fixes = Some(f.report());
        eval.across_track_error_m = f.across();
        eval.outages = f.outages(t0);
    }
    eval
}

/// How far, in s, fused states may trail the reference in file order: the reorder window
/// (5 s covers any sane one) plus the longest chunk, since railfuse writes the fused chunk of
/// an input chunk right after it.
pub fn lag_allowance_s(longest_chunk_ns: Option<u64>) -> f64 {
    5.0 + longest_chunk_ns.unwrap_or(0) as f64 / 1e9
}

/// The accuracy table of a run's fused channels against `reference`; `outages`, when given,
/// are scored as withheld from every pipeline (over what the log records).
pub fn evaluate(
    run: &Run,
    reference: &Reference,
    outages: Option<&Withheld>,
) -> Result<EvalReport> {
    let reference_topic = reference.topic.as_str();
    let mut reader = run.reader()?;
    let longest = reader.summary().and_then(|s| s.longest_chunk_ns);
    let mut eval = Evaluator::new(run.name(), reference, lag_allowance_s(longest));
    if let Some(w) = outages {
        eval.withheld_everywhere(w);
    }
    let mut reads = std::collections::HashSet::new();
    let (mut foreign, mut translated) = (ForeignChannels::default(), Vec::new());
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                let c = reference_channel(&mut foreign, c, reference_topic);
                if eval.channel(c.id, &c.topic, c.schema_name()) {
                    reads.insert(c.id);
                }
            }
            LogRecord::Message(m) => {
                eval.log_time(m.log_time_ns);
                if reads.contains(&m.channel.id) {
                    // A foreign reference sample that does not read is a gap in it.
                    if let Ok(Some(m)) = foreign.message(m, &mut translated) {
                        eval.message(&m)?;
                    }
                }
            }
            LogRecord::Metadata { name, metadata } => eval.metadata(&name, &metadata),
            _ => {}
        }
    }
    eval.finish(run)
}

/// `c` as the evaluation reads it: another tool's reference channel (a ROS bag's NavSatFix)
/// as the catalogue kind it translates to, every other channel as it is.
fn reference_channel(
    foreign: &mut ForeignChannels,
    c: Arc<ChannelInfo>,
    reference_topic: &str,
) -> Arc<ChannelInfo> {
    match c.topic == reference_topic && c.kind().is_none() {
        true => foreign.channel(c.clone(), None).unwrap_or(c),
        false => c,
    }
}

/// A log's reference channel read in step with states that come later in the file (smoothed
/// states exist only once the whole run is filtered): it feeds a meter the reference up to
/// each state's stamp.
struct ReferenceWalk {
    path: PathBuf,
    reader: RunReader,
    topic: String,
    roles: BTreeMap<u16, Role>,
    map: Option<TrackMap>,
    antenna: Option<SensorMount>,
    foreign: ForeignChannels,
    translated: Vec<u8>,
    done: bool,
    /// The newest reference stamp fed.
    newest_ns: Option<u64>,
}

impl ReferenceWalk {
    fn open(run: &Run, topic: &str) -> Result<Self> {
        Ok(Self {
            path: run.name().to_owned(),
            reader: run.reader()?,
            topic: topic.to_owned(),
            roles: BTreeMap::new(),
            map: None,
            antenna: None,
            foreign: ForeignChannels::default(),
            translated: Vec::new(),
            done: false,
            newest_ns: None,
        })
    }

    /// Feeds `scored` the reference until it has passed `stamp_ns`.
    fn feed_until(&mut self, scored: &mut Scored, stamp_ns: u64, spans: &[Span]) -> Result<()> {
        while !self.done && self.newest_ns.is_none_or(|n| n < stamp_ns) {
            let Some(record) = self.reader.next() else {
                self.done = true;
                break;
            };
            match record? {
                LogRecord::Channel(c) => {
                    let c = reference_channel(&mut self.foreign, c, &self.topic);
                    match reference_kind(c.schema_name()) {
                        Some(kind) if c.topic == self.topic => {
                            self.roles.insert(c.id, Role::Reference(kind));
                        }
                        _ if c.schema_name() == TrackMap::SCHEMA_NAME => {
                            self.roles.insert(c.id, Role::TrackMap);
                        }
                        _ if c.schema_name() == Vehicle::SCHEMA_NAME => {
                            self.roles.insert(c.id, Role::Vehicle);
                        }
                        _ => {}
                    }
                }
                LogRecord::Message(m) => match self.roles.get(&m.channel.id).copied() {
                    Some(Role::TrackMap) => self.map = Some(m.decode(&self.path)?),
                    Some(Role::Vehicle) => {
                        let v: Vehicle = m.decode(&self.path)?;
                        self.antenna = v.mount(&self.topic).cloned();
                    }
                    Some(Role::Reference(kind)) => {
                        let Ok(Some(m)) = self.foreign.message(m, &mut self.translated) else {
                            continue; // a foreign sample that does not read: a gap
                        };
                        let t = match kind {
                            ReferenceKind::Gnss => {
                                let place = (self.map.as_ref(), self.antenna.as_ref());
                                let fix = fix_sample(&m, &self.path, place)?;
                                fix.map(|f| {
                                    scored.fixes.add_fix(f, spans);
                                    f.stamp_ns
                                })
                            }
                            _ => {
                                let place = (self.map.as_ref(), self.antenna.as_ref());
                                let sample = reference_sample(kind, &m, &self.path, place)?;
                                sample.map(|(t, s, v)| {
                                    scored.meter.add_reference(t, s, v, spans);
                                    t
                                })
                            }
                        };
                        if let Some(t) = t {
                            self.newest_ns = Some(self.newest_ns.map_or(t, |n| n.max(t)));
                        }
                    }
                    _ => {}
                },
                _ => {}
            }
        }
        Ok(())
    }
}

/// The reference kind a schema gives.
pub fn reference_kind(schema: &str) -> Option<ReferenceKind> {
    match schema {
        s if s == GroundTruth::SCHEMA_NAME => Some(ReferenceKind::Truth),
        s if s == FusedState::SCHEMA_NAME => Some(ReferenceKind::Fused),
        s if s == GnssFix::SCHEMA_NAME => Some(ReferenceKind::Gnss),
        _ => None,
    }
}

/// Later passes for the smoothed channels of `log` not fed to the evaluator directly, one
/// per channel: one reader walks its states, another the reference, in step.
fn score_smoothed(
    log: &Run,
    (reference_topic, reference): (&str, Option<ReferenceKind>),
    channels: &[(u16, usize)],
    scored: &mut [Scored],
    spans: &[Span],
) -> Result<()> {
    for &(channel, i) in channels {
        let mut estimates = log.reader()?;
        let mut walk = ReferenceWalk::open(log, reference_topic)?;
        while let Some(record) = estimates.next() {
            let LogRecord::Message(m) = record? else {
                continue;
            };
            if m.channel.id != channel {
                continue;
            }
            let st: FusedState = m.decode(log.name())?;
            walk.feed_until(&mut scored[i], st.stamp_ns, spans)?;
            scored[i].add_state(&st, (reference, walk.map.as_ref()), spans);
        }
    }
    Ok(())
}
