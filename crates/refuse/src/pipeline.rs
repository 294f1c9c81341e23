//! One configured pipeline: measurements are released to its estimator in sensor-time order
//! (within a bounded reorder window), checked, gated, and turned into fused states and
//! diagnostics. The pipeline is generic over the state dimension: the motion states (two for
//! the constant-velocity model, three for the others) followed by the sensor states it
//! estimates ([`AnyPipeline`] picks, up to [`MAX_STATES`]).
//!
//! A speed sensor with a scale-factor state measures `z = (1 + k) v`: its row is linearised at
//! the estimate of the moment (`H = [0, 1 + k̂, …, v̂]`, offset `−v̂ k̂`), an extended Kalman
//! filter step.

use nalgebra::{SMatrix, SVector};
use railfuse_catalog::messages::{FusedDiagnostics, FusedState, GateDecision, SensorStateEstimate};

use crate::error::{Error, Result};
use crate::filter::covariance_matching::CovarianceMatching;
use crate::filter::federated::Federated;
use crate::filter::rts::EpochRecorder;
use crate::filter::{
    Centralised, Estimator, KalmanFilter, Outcome, ParticleFilter, ScalarMeasurement,
    StateAndCovariance, MASTER,
};
use crate::kinds::MessagePipeline;
use crate::measurement::{Measurement, ObservationRow, Quantity, SensorContext};
use crate::model::SensorState;
use crate::noise::VarianceValue;
use crate::reorder::ReorderQueue;
use crate::spec::{EstimatorSpec, PipelineSpec, SensorBinding, SensorSpec, MAX_STATES};

pub use crate::fused::{measurement_record, Fused, PipelineCounts};

struct Field<const N: usize> {
    quantity: Quantity,
    row: ObservationRow<N>,
    variance: VarianceValue,
    /// Its variance from its innovations (config `adaptive_variance`).
    matching: Option<CovarianceMatching>,
}

impl<const N: usize> Field<N> {
    /// The variance of measurement `m`: the configured one, or the one it carries.
    fn variance_of(&self, m: &Measurement) -> Option<f64> {
        match self.variance {
            VarianceValue::Fixed(v) => Some(v),
            VarianceValue::FromMessage(_) => m.reported_variance,
        }
    }
}

/// What each state component is: the motion states, then one per sensor state.
#[derive(Debug, Clone)]
pub struct StateLayout {
    pub motion: usize,
    /// Topic and kind of each sensor state, in state order after the motion states.
    pub sensor: Vec<(String, &'static str)>,
}

/// A sensor's fields as rows of the observation matrix, once it is bound to its channel.
struct Sensor<const N: usize> {
    fields: Vec<Field<N>>,
    /// Gate rejections in a row of its chainage after which the estimate is reset to it (0:
    /// never), and the current run of them.
    reset_after: u32,
    rejected_in_row: u32,
}

/// The innovation check an ungated absolute fix must pass not to count towards a reset:
/// NIS 25, the 5σ of PX4's default position gate.
const FIX_CHECK_NIS: f64 = 25.0;

/// Whether the chainage fix `m` of a sensor (`spec`, `bound`) is the one to reset the position to, and why:
/// it fails the innovation check (the sensor's gate, or, ungated in a centralised
/// pipeline, NIS > 25: PX4's 5σ) for the `reset_after`-th time in a row. Judged on the
/// prediction, before any update, so that a reset starts from the same prior whether the
/// fix was gated or not. A federated pipeline's devices have their fault detector; its
/// master fixes (a balise) are checked.
fn fix_check<const N: usize>(
    spec: &SensorSpec,
    bound: &mut Sensor<N>,
    e: &dyn Estimator<N>,
    m: &ScalarMeasurement<N>,
) -> Option<String> {
    let centralised = spec.device_name.is_none();
    if m.quantity != Quantity::Chainage.index()
        || bound.reset_after == 0
        || !(centralised || spec.device == MASTER)
    {
        return None;
    }
    let check = spec.gate_nis.or(centralised.then_some(FIX_CHECK_NIS))?;
    if e.innovation(m).passes(Some(check)) {
        bound.rejected_in_row = 0;
        return None;
    }
    bound.rejected_in_row += 1;
    if bound.rejected_in_row < bound.reset_after {
        return None;
    }
    let n = std::mem::take(&mut bound.rejected_in_row);
    Some(format!(
        "failed the innovation check (NIS > {check}) {n} time(s) in a row: position reset \
         to this fix"
    ))
}

struct Pending {
    sensor: usize,
    field: usize,
    measurement: Measurement,
}

pub struct Pipeline<const N: usize> {
    pub spec: PipelineSpec,
    sensors: Vec<Sensor<N>>,
    /// Every sensor state with the index of its sensor, in state order.
    states: Vec<(usize, SensorState)>,
    layout: StateLayout,
    estimator: Option<Box<dyn Estimator<N>>>,
    smoother: Option<EpochRecorder<N>>,
    time_ns: u64,
    window_ns: u64,
    /// Measurements not yet released.
    order: ReorderQueue<Pending>,
    /// The latest valid speed measurement before the first position: the initial speed.
    speed_before_init: Option<(f64, f64)>,
    /// Per sensor: whether it may give chainage (until its channel is seen, it may).
    gives_chainage: Vec<bool>,
    output_period_ns: Option<u64>,
    next_output_ns: u64,
    pub counts: PipelineCounts,
}

impl<const N: usize> Pipeline<N> {
    fn new(spec: PipelineSpec) -> Result<Self> {
        debug_assert_eq!(spec.dimension(), N);
        let states = spec.sensor_states();
        let layout = StateLayout {
            motion: spec.motion.dimension(),
            sensor: states
                .iter()
                .map(|(i, s)| (spec.sensors[*i].topic.clone(), s.kind()))
                .collect(),
        };
        let smoother = if spec.estimator.smoother() {
            Some(EpochRecorder::new().map_err(|source| Error::Spill {
                pipeline: spec.name.clone(),
                source,
            })?)
        } else {
            None
        };
        Ok(Self {
            window_ns: spec.reorder_window_ns,
            output_period_ns: spec.output_period_ns,
            sensors: spec
                .sensors
                .iter()
                .map(|_| Sensor {
                    fields: Vec::new(),
                    reset_after: 0,
                    rejected_in_row: 0,
                })
                .collect(),
            gives_chainage: vec![true; spec.sensors.len()],
            spec,
            states,
            layout,
            estimator: None,
            smoother,
            time_ns: 0,
            order: ReorderQueue::default(),
            speed_before_init: None,
            next_output_ns: 0,
            counts: PipelineCounts::default(),
        })
    }

    /// Sensor `sensor` is bound to its channel: its fields become rows of the observation
    /// matrix, and it gives chainage only if one of them is chainage.
    pub fn bind(&mut self, sensor: usize, binding: &SensorBinding) {
        let motion = self.layout.motion;
        let window = self.spec.sensors[sensor].speed_window_s;
        let field = |q: Quantity, variance: VarianceValue| {
            let mut h = q.motion_row::<N>(window)?;
            let scaled = h;
            let mut scale_state = None;
            // The sensor's states on this quantity: a bias adds to the row, a scale factor
            // makes it non-linear (linearised at each update).
            for (p, (_, state)) in self
                .states
                .iter()
                .enumerate()
                .filter(|(_, (j, s))| *j == sensor && s.quantity() == q)
            {
                match state {
                    SensorState::ScaleFactor { .. } => scale_state = Some(motion + p),
                    SensorState::ChainageBias { .. } | SensorState::AccelerationBias { .. } => {
                        h[motion + p] = 1.0
                    }
                }
            }
            Some(Field {
                quantity: q,
                row: ObservationRow {
                    h,
                    scaled,
                    scale_state,
                },
                variance,
                matching: self.spec.sensors[sensor]
                    .adaptive_window
                    .map(CovarianceMatching::new),
            })
        };
        self.sensors[sensor].fields = binding
            .fields
            .iter()
            .filter_map(|&(q, v)| field(q, v))
            .collect();
        self.gives_chainage[sensor] = binding.fields.iter().any(|(q, _)| *q == Quantity::Chainage);
        self.sensors[sensor].reset_after = self.spec.sensors[sensor]
            .reset_after
            .unwrap_or(binding.model.default_reset_after());
    }

    /// Queues the measurements of one message of sensor `sensor`, received at `log_time_ns`,
    /// and releases every measurement the replay is now more than the reorder window past.
    pub fn push(
        &mut self,
        sensor: usize,
        measurements: &[Measurement],
        log_time_ns: u64,
        out: &mut Vec<Fused>,
    ) {
        // A sensor that stamps late is measured earlier than its stamp says: fused at the
        // time it measured, the reorder window holding the others back for it.
        let late_ns = self.spec.sensors[sensor].time_offset_ns;
        for m in measurements {
            let Some(field) = self.sensors[sensor]
                .fields
                .iter()
                .position(|f| f.quantity == m.quantity)
            else {
                continue;
            };
            let mut measurement = *m;
            measurement.stamp_ns = m.stamp_ns.saturating_add_signed(-late_ns);
            self.order.push(
                measurement.stamp_ns,
                Pending {
                    sensor,
                    field,
                    measurement,
                },
            );
        }
        self.release(log_time_ns.saturating_sub(self.window_ns), log_time_ns, out);
    }

    /// Releases everything still queued (end of the log, at replay time `log_time_ns`).
    pub fn finish(&mut self, log_time_ns: u64, out: &mut Vec<Fused>) {
        self.release(u64::MAX, log_time_ns, out);
        if let Some(e) = &mut self.estimator {
            self.smoother = e.take_smoother();
        }
    }

    /// A device's own fault report; `name` is its device name or one of its topics.
    pub fn device_event(&mut self, name: &str, failed: bool) {
        let device = self
            .spec
            .sensors
            .iter()
            .find(|s| s.topic == name)
            .map_or(name, |s| s.device_name.as_deref().unwrap_or(&s.topic));
        if let Some(e) = &mut self.estimator {
            e.device_event(device, failed);
        }
    }

    fn release(&mut self, up_to_ns: u64, log_time_ns: u64, out: &mut Vec<Fused>) {
        while let Some((_, p)) = self.order.pop_until(up_to_ns) {
            self.process(p, log_time_ns, out);
        }
    }

    /// Where the filter starts when that does not wait for a position measurement: the
    /// configured chainage, or distance 0 for a pipeline none of whose sensors gives chainage.
    fn known_start(&self) -> Option<(f64, f64)> {
        let init = &self.spec.initial;
        match init.chainage {
            Some(start) => Some(start),
            None if !self.gives_chainage.iter().any(|g| *g) => Some((0.0, init.distance_variance)),
            None => None,
        }
    }

    /// Builds the estimator at `init`, time `t0_ns`.
    fn start(&mut self, init: &StateAndCovariance<N>, t0_ns: u64) {
        let estimator = self.build(init, t0_ns);
        self.estimator = Some(estimator);
        self.time_ns = t0_ns;
        if let Some(period) = self.output_period_ns {
            // Ticks on whole multiples of the period, for comparable outputs.
            self.next_output_ns = t0_ns.div_ceil(period) * period;
        }
    }

    fn initial(&self, chainage: f64, r: f64) -> StateAndCovariance<N> {
        let init = &self.spec.initial;
        let (speed, speed_var) = self
            .speed_before_init
            .unwrap_or((init.speed_mps, init.speed_variance));
        let (motion, states) = (self.layout.motion, &self.states);
        // Motion states from the first fix; sensor states at zero with their prior spread.
        let mean = |i: usize| {
            if i < motion {
                [chainage, speed, init.acceleration_mps2][i]
            } else {
                0.0
            }
        };
        let var = |i: usize| {
            if i < motion {
                [r, speed_var, init.acceleration_variance][i]
            } else {
                states[i - motion].1.std().powi(2)
            }
        };
        StateAndCovariance {
            state: SVector::from_fn(|i, _| mean(i)),
            covariance: SMatrix::from_fn(|i, j| if i == j { var(i) } else { 0.0 }),
        }
    }

    fn build(&mut self, init: &StateAndCovariance<N>, t0: u64) -> Box<dyn Estimator<N>> {
        let states = self.states.iter().map(|(_, s)| *s).collect();
        let model = self.spec.motion.with_sensor_states::<N>(states);
        let devices = self.spec.devices.clone();
        match &self.spec.estimator {
            EstimatorSpec::Kalman { gate_lockout, .. } => Box::new(
                Centralised::new(
                    KalmanFilter::new(init.state, init.covariance),
                    model,
                    t0,
                    self.smoother.take(),
                )
                .with_gate_lockout(*gate_lockout),
            ),
            EstimatorSpec::Particle {
                particle,
                gate_lockout,
            } => Box::new(
                Centralised::new(ParticleFilter::new(*particle, init), model, t0, None)
                    .with_gate_lockout(*gate_lockout),
            ),
            EstimatorSpec::FederatedKalman { federated } => Box::new(Federated::new(
                federated.clone(),
                model,
                devices,
                init,
                t0,
                |_, s| KalmanFilter::new(s.state, s.covariance),
            )),
            // Each local particle filter has its own random stream.
            EstimatorSpec::FederatedParticle {
                federated,
                particle,
            } => Box::new(Federated::new(
                federated.clone(),
                model,
                devices,
                init,
                t0,
                |i, s| ParticleFilter::new(particle.stream(i as u64 + 1), s),
            )),
            EstimatorSpec::Messages(_) => {
                unreachable!("AnyPipeline::new makes a message pipeline of these specs")
            }
        }
    }

    /// Output ticks strictly before `t_ns`: the estimate predicted to each.
    fn ticks_before(&mut self, t_ns: u64, log_time_ns: u64, out: &mut Vec<Fused>) {
        let (Some(period), Some(e)) = (self.output_period_ns, &mut self.estimator) else {
            return;
        };
        while self.next_output_ns < t_ns {
            e.advance_to(self.next_output_ns);
            let state = fused_state(
                &self.layout,
                self.next_output_ns,
                &e.estimate(),
                "output_tick",
            );
            out.push(Fused {
                log_time_ns,
                state: Some(state),
                ..Default::default()
            });
            self.next_output_ns += period;
        }
    }

    /// One measurement through the filter: its variance, the start of the filter if this is
    /// where it starts, the update, and the diagnostics record of what was done with it.
    fn process(&mut self, p: Pending, log_time_ns: u64, out: &mut Vec<Fused>) {
        let m = p.measurement;
        let variance = self.sensors[p.sensor].fields[p.field].variance_of(&m);
        let mut diagnostics = self.diagnostics(p.sensor, &m, variance);
        if let Some(e) = &mut self.estimator {
            e.heard_from(self.spec.sensors[p.sensor].device, m.stamp_ns);
        }
        let usable =
            variance.filter(|r| r.is_finite() && *r > 0.0 && m.valid && m.value.is_finite());
        let (decision, state) = match usable {
            None => (GateDecision::RejectedInvalid, None),
            Some(r) if self.estimator.is_none() => {
                self.initialise(&p, r, log_time_ns, out, &mut diagnostics)
            }
            Some(r) => self.update(&p, r, log_time_ns, out, &mut diagnostics),
        };
        diagnostics.decision = decision;
        self.count(decision);
        out.push(Fused {
            log_time_ns,
            state,
            diagnostics: Some(diagnostics),
            ..Default::default()
        });
    }

    /// The diagnostics record of a measurement, before the filter has seen it.
    fn diagnostics(
        &self,
        sensor: usize,
        m: &Measurement,
        variance: Option<f64>,
    ) -> FusedDiagnostics {
        let sensor = &self.spec.sensors[sensor];
        FusedDiagnostics {
            stamp_ns: m.stamp_ns,
            source: sensor.topic.clone(),
            measurement: m.value.is_finite().then_some(m.value),
            measurement_variance: variance.filter(|v| v.is_finite()),
            innovation: None,
            innovation_variance: None,
            nis: None,
            decision: GateDecision::Accepted,
            device: sensor.device_name.clone(),
            axis: None,
            reason: None,
            effective_sample_size: None,
            resampled: None,
            sharing: None,
            eddy_current: None,
        }
    }

    /// A usable measurement before the filter runs: it starts the filter where the pipeline
    /// is told to start (and is then used), or at a position measurement (which gives the
    /// start); a speed before that is kept as the initial speed.
    fn initialise(
        &mut self,
        p: &Pending,
        r: f64,
        log_time_ns: u64,
        out: &mut Vec<Fused>,
        diagnostics: &mut FusedDiagnostics,
    ) -> (GateDecision, Option<FusedState>) {
        let m = &p.measurement;
        if let Some((chainage, var)) = self.known_start() {
            let init = self.initial(chainage, var);
            self.start(&init, m.stamp_ns);
            return self.update(p, r, log_time_ns, out, diagnostics);
        }
        match m.quantity {
            Quantity::Chainage => {
                let init = self.initial(m.value, r);
                self.start(&init, m.stamp_ns);
                let source = &self.spec.sensors[p.sensor].topic;
                let state = self
                    .output_period_ns
                    .is_none()
                    .then(|| fused_state(&self.layout, m.stamp_ns, &init, source));
                (GateDecision::Accepted, state)
            }
            Quantity::Speed => {
                self.speed_before_init = Some((m.value, r));
                (GateDecision::BeforeInitialisation, None)
            }
            Quantity::Acceleration => (GateDecision::BeforeInitialisation, None),
        }
    }

    /// A usable measurement for the running filter: output ticks up to it, prediction to its
    /// time, the gated update (linearised where the row needs it).
    fn update(
        &mut self,
        p: &Pending,
        r: f64,
        log_time_ns: u64,
        out: &mut Vec<Fused>,
        diagnostics: &mut FusedDiagnostics,
    ) -> (GateDecision, Option<FusedState>) {
        let m = &p.measurement;
        if m.stamp_ns < self.time_ns {
            return (GateDecision::RejectedLate, None);
        }
        self.ticks_before(m.stamp_ns, log_time_ns, out);
        let sensor = &self.spec.sensors[p.sensor];
        let row = self.sensors[p.sensor].fields[p.field].row;
        let e = self.estimator.as_mut().expect("initialised");
        e.advance_to(m.stamp_ns);
        self.time_ns = m.stamp_ns;
        let x = row
            .is_linearised()
            .then(|| e.linearisation_point(sensor.device));
        let (h, offset) = row.at(x.as_ref());
        let mut scalar = ScalarMeasurement {
            device: sensor.device,
            quantity: m.quantity.index(),
            h,
            offset,
            r,
            z: m.value,
            gate_nis: sensor.gate_nis,
        };
        if let Some(m) = self.sensors[p.sensor].fields[p.field].matching.as_mut() {
            scalar.r = m.variance(r, &e.innovation(&scalar));
            if scalar.r > r {
                diagnostics.measurement_variance = Some(scalar.r);
                diagnostics.reason = Some(format!(
                    "variance {:.4} from its innovations (stated {r:.4})",
                    scalar.r
                ));
            }
        }
        let outcome = match fix_check(sensor, &mut self.sensors[p.sensor], e.as_ref(), &scalar) {
            Some(reason) => {
                diagnostics.reason = Some(reason);
                e.reset_to_fix(&scalar)
            }
            None => e.process(&scalar),
        };
        note_outcome(diagnostics, &outcome, e.diagnostics());
        let decision = gate_decision(&outcome);
        let used = matches!(
            decision,
            GateDecision::Accepted | GateDecision::AcceptedAfterLockout | GateDecision::ResetToFix
        );
        // With an output rate, states come from the ticks; otherwise one per update.
        let state = (used && self.output_period_ns.is_none())
            .then(|| fused_state(&self.layout, m.stamp_ns, &e.estimate(), &sensor.topic));
        (decision, state)
    }

    fn count(&mut self, decision: GateDecision) {
        let c = &mut self.counts;
        *match decision {
            GateDecision::Accepted => &mut c.accepted,
            GateDecision::AcceptedAfterLockout => &mut c.accepted_after_lockout,
            GateDecision::RejectedGate => &mut c.rejected_gate,
            GateDecision::RejectedInvalid => &mut c.rejected_invalid,
            GateDecision::RejectedLate => &mut c.rejected_late,
            GateDecision::RejectedDeviceFault => &mut c.rejected_device_fault,
            GateDecision::BeforeInitialisation => &mut c.before_initialisation,
            GateDecision::ResetToFix => &mut c.resets_to_fix,
        } += 1;
    }

    /// The smoothed states, once `finish` has run (Kalman pipelines with `smoother = true`).
    pub fn smoothed(
        &mut self,
    ) -> Option<std::io::Result<Box<dyn Iterator<Item = std::io::Result<FusedState>>>>> {
        let recorder = self.smoother.take()?;
        if recorder.epochs() == 0 {
            return None;
        }
        let layout = self.layout.clone();
        Some(recorder.smooth().map(
            move |epochs| -> Box<dyn Iterator<Item = std::io::Result<FusedState>>> {
                Box::new(epochs.map(move |e| {
                    e.map(|e| fused_state(&layout, e.stamp_ns, &e.estimate, "rts_smoother"))
                }))
            },
        ))
    }
}

/// A fused state from an `N`-state estimate (acceleration 0 with no variance for the
/// two-state constant-velocity model), with its sensor states.
pub fn fused_state<const N: usize>(
    layout: &StateLayout,
    stamp_ns: u64,
    e: &StateAndCovariance<N>,
    source: &str,
) -> FusedState {
    let motion = layout.motion;
    let x = |i: usize| if i < motion { e.state[i] } else { 0.0 };
    let mut covariance = [0.0; 9];
    for (k, c) in covariance.iter_mut().enumerate() {
        let (i, j) = (k / 3, k % 3);
        if i < motion && j < motion {
            *c = e.covariance[(i, j)];
        }
    }
    let sensor_states = layout
        .sensor
        .iter()
        .enumerate()
        .map(|(k, (topic, kind))| SensorStateEstimate {
            topic: topic.clone(),
            kind: (*kind).to_owned(),
            value: e.state[motion + k],
            std: e.covariance[(motion + k, motion + k)].max(0.0).sqrt(),
        })
        .collect();
    FusedState {
        stamp_ns,
        chainage_m: x(0),
        speed_mps: x(1),
        acceleration_mps2: x(2),
        covariance,
        source: source.to_owned(),
        sensor_states,
        plane: None,
    }
}

/// A pipeline of any state dimension up to [`MAX_STATES`], or one that reads whole messages.
pub enum AnyPipeline {
    /// Its spec, and the pipeline (built from the spec's [`base`](PipelineSpec::base)).
    Messages(Box<PipelineSpec>, Box<dyn MessagePipeline>),
    Two(Pipeline<2>),
    Three(Pipeline<3>),
    Four(Pipeline<4>),
    Five(Pipeline<5>),
    Six(Pipeline<6>),
    Seven(Pipeline<7>),
    Eight(Pipeline<8>),
    Nine(Pipeline<9>),
    Ten(Pipeline<10>),
}

/// `$e` on the pipeline of whatever dimension, or `$safety` on a safety pipeline.
macro_rules! each {
    ($self:expr, $p:ident => $e:expr, $s:ident => $safety:expr) => {
        match $self {
            AnyPipeline::Two($p) => $e,
            AnyPipeline::Three($p) => $e,
            AnyPipeline::Four($p) => $e,
            AnyPipeline::Five($p) => $e,
            AnyPipeline::Six($p) => $e,
            AnyPipeline::Seven($p) => $e,
            AnyPipeline::Eight($p) => $e,
            AnyPipeline::Nine($p) => $e,
            AnyPipeline::Ten($p) => $e,
            AnyPipeline::Messages(_, $s) => $safety,
        }
    };
}

impl AnyPipeline {
    pub fn new(spec: PipelineSpec) -> Result<Self> {
        const _: () = assert!(MAX_STATES == 10, "AnyPipeline has a variant per dimension");
        if let EstimatorSpec::Messages(kind) = &spec.estimator {
            let p = kind.build(spec.base())?;
            return Ok(AnyPipeline::Messages(Box::new(spec), p));
        }
        Ok(match spec.dimension() {
            2 => AnyPipeline::Two(Pipeline::new(spec)?),
            3 => AnyPipeline::Three(Pipeline::new(spec)?),
            4 => AnyPipeline::Four(Pipeline::new(spec)?),
            5 => AnyPipeline::Five(Pipeline::new(spec)?),
            6 => AnyPipeline::Six(Pipeline::new(spec)?),
            7 => AnyPipeline::Seven(Pipeline::new(spec)?),
            8 => AnyPipeline::Eight(Pipeline::new(spec)?),
            9 => AnyPipeline::Nine(Pipeline::new(spec)?),
            _ => AnyPipeline::Ten(Pipeline::new(spec)?),
        })
    }

    pub fn spec(&self) -> &PipelineSpec {
        match self {
            AnyPipeline::Messages(spec, _) => spec,
            _ => each!(self, p => &p.spec, _s => unreachable!("matched above")),
        }
    }

    pub fn name(&self) -> &str {
        &self.spec().name
    }

    pub fn counts(&self) -> &PipelineCounts {
        each!(self, p => &p.counts, s => s.counts())
    }

    /// The kind's line for the run's report (a GNSS gate's decisions), if any.
    pub fn report(&self) -> Option<String> {
        each!(self, _p => None, s => s.report())
    }

    /// A pipeline fed whole messages ([`MessagePipeline::push`]) instead of
    /// [`push`](Self::push)'s scalar measurements.
    pub fn as_message_pipeline(&mut self) -> Option<&mut dyn MessagePipeline> {
        match self {
            AnyPipeline::Messages(_, s) => Some(s.as_mut()),
            _ => None,
        }
    }

    /// Scalar measurements of sensor `sensor` (pipelines along the track; a message pipeline
    /// takes whole messages through [`as_message_pipeline`](Self::as_message_pipeline) and
    /// ignores these).
    pub fn push(
        &mut self,
        sensor: usize,
        measurements: &[Measurement],
        log_time_ns: u64,
        out: &mut Vec<Fused>,
    ) {
        each!(self, p => p.push(sensor, measurements, log_time_ns, out), _s => ())
    }

    /// The end of the log; `context` is the replay's (a safety pipeline's map).
    pub fn finish(&mut self, log_time_ns: u64, context: &SensorContext, out: &mut Vec<Fused>) {
        each!(self, p => p.finish(log_time_ns, out), s => s.finish(log_time_ns, context, out))
    }

    /// A device's own fault report (federated pipelines act on it; a safety pipeline
    /// diagnoses its sensors from their messages).
    pub fn device_event(&mut self, device: &str, failed: bool) {
        each!(self, p => p.device_event(device, failed), _s => ())
    }

    pub fn bind(&mut self, sensor: usize, binding: &SensorBinding) {
        each!(
            self,
            p => p.bind(sensor, binding),
            s => s.bind(sensor, binding.fields.first().map(|f| f.1))
        )
    }

    pub fn smoothed(
        &mut self,
    ) -> Option<std::io::Result<Box<dyn Iterator<Item = std::io::Result<FusedState>>>>> {
        each!(self, p => p.smoothed(), _s => None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Pipelines;
    use railfuse_catalog::messages::MessageKind;

    fn pipeline(gate: &str) -> AnyPipeline {
        let text = format!(
            "[[pipeline]]\nname = \"p\"\nfilter = \"kalman\"\nmotion = {{ model = \"constant_acceleration\", jerk_psd = 0.1 }}\nreorder_window_s = 0.2\n\
             [[pipeline.sensor]]\ntopic = \"/pos\"\nvariance = 0.01\n{gate}\n[[pipeline.sensor]]\ntopic = \"/spd\"\nvariance = \"message\"\n"
        );
        let c = Pipelines::parse(&text, std::path::Path::new("t.toml")).unwrap();
        let mut p = AnyPipeline::new(c.pipeline[0].clone()).unwrap();
        let input = std::path::Path::new("t.mcap");
        let kinds = [MessageKind::LoopPosition, MessageKind::RadarSpeed];
        for (i, kind) in kinds.iter().enumerate() {
            p.bind(
                i,
                &c.pipeline[0].bind(input, i, kind.schema_name()).unwrap(),
            );
        }
        p
    }

    fn m(stamp_ns: u64, quantity: Quantity, value: f64, var: Option<f64>) -> [Measurement; 1] {
        [Measurement {
            stamp_ns,
            quantity,
            value,
            reported_variance: var,
            valid: true,
        }]
    }

    #[test]
    fn measurements_are_fused_in_sensor_time_order_within_the_window() {
        let mut p = pipeline("");
        let mut out = Vec::new();
        let s = 1_000_000_000u64;
        p.push(0, &m(s, Quantity::Chainage, 0.0, None), s, &mut out);
        // A speed measured at 1.10 s arrives after a position measured at 1.15 s.
        p.push(
            0,
            &m(s + 150_000_000, Quantity::Chainage, 1.5, None),
            s + 160_000_000,
            &mut out,
        );
        p.push(
            1,
            &m(s + 100_000_000, Quantity::Speed, 10.0, Some(0.01)),
            s + 170_000_000,
            &mut out,
        );
        p.finish(s + 200_000_000, &SensorContext::default(), &mut out);
        let diags: Vec<FusedDiagnostics> =
            out.iter().filter_map(|f| f.diagnostics.clone()).collect();
        let stamps: Vec<u64> = diags.iter().map(|d| d.stamp_ns).collect();
        assert_eq!(stamps, vec![s, s + 100_000_000, s + 150_000_000]);
        assert!(diags.iter().all(|d| d.decision == GateDecision::Accepted));
        assert_eq!(p.counts().rejected_late, 0);
    }

    #[test]
    fn nan_and_missing_variances_are_rejected_and_never_reach_the_state() {
        let mut p = pipeline("gate_nis = 9.0");
        let mut out = Vec::new();
        p.push(0, &m(0, Quantity::Chainage, 0.0, None), 0, &mut out);
        p.push(0, &m(10, Quantity::Chainage, f64::NAN, None), 10, &mut out);
        p.push(
            0,
            &m(20, Quantity::Chainage, f64::INFINITY, None),
            20,
            &mut out,
        );
        p.push(1, &m(30, Quantity::Speed, 3.0, None), 30, &mut out); // "message" variance, none given
        p.push(
            1,
            &m(40, Quantity::Speed, 0.0, Some(f64::NAN)),
            40,
            &mut out,
        );
        p.push(0, &m(50, Quantity::Chainage, 1e6, None), 50, &mut out); // far outside the gate
        p.finish(60, &SensorContext::default(), &mut out);
        assert_eq!(p.counts().accepted, 1);
        assert_eq!(p.counts().rejected_invalid, 4);
        assert_eq!(p.counts().rejected_gate, 1);
        for f in &out {
            if let Some(s) = &f.state {
                assert!(s.chainage_m.is_finite() && s.covariance.iter().all(|c| c.is_finite()));
            }
            // Every output survives JSON (which has no NaN) both ways.
            let d = f.diagnostics.as_ref().unwrap();
            let back: FusedDiagnostics =
                serde_json::from_str(&serde_json::to_string(d).unwrap()).unwrap();
            assert_eq!(back.decision, d.decision);
        }
    }
}

/// An update's innovation and the estimator's own diagnostics (particles, shares) into the
/// state's diagnostics.
fn note_outcome(
    diagnostics: &mut FusedDiagnostics,
    outcome: &Outcome,
    extra: crate::filter::EstimatorDiagnostics,
) {
    if let Some(i) = outcome.innovation() {
        diagnostics.innovation = Some(i.residual);
        diagnostics.innovation_variance = Some(i.variance);
        diagnostics.nis = Some(i.nis);
    }
    diagnostics.effective_sample_size = extra.effective_sample_size;
    diagnostics.resampled = extra.resampled;
    diagnostics.sharing = extra.sharing.map(|shares| {
        shares
            .into_iter()
            .map(|s| railfuse_catalog::messages::DeviceShare {
                device: s.device,
                beta: s.beta,
                fault: s.fault,
            })
            .collect()
    });
}

/// What the filter did with a measurement, as the diagnostics count it.
fn gate_decision(outcome: &Outcome) -> GateDecision {
    match outcome {
        Outcome::Accepted(_) => GateDecision::Accepted,
        Outcome::AcceptedAfterLockout(_) => GateDecision::AcceptedAfterLockout,
        Outcome::RejectedGate(_) => GateDecision::RejectedGate,
        Outcome::RejectedNumerics(_) => GateDecision::RejectedInvalid,
        Outcome::RejectedDeviceFault(_) => GateDecision::RejectedDeviceFault,
        Outcome::Reset(_) => GateDecision::ResetToFix,
    }
}
