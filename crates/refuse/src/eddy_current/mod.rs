//! Source 004's `eddy_current` pipeline: speed and distance from two eddy-current sensors a
//! known distance `D` apart along the bogie, without touching the rail.
//!
//! | step | module | what |
//! |---|---|---|
//! | input | [`input_check`] | blocks bounded and checked: finite, same length, not clipped or dead, continuous; a gap or a change of rate or `D` starts the processing over |
//! | filters | [`butterworth`], [`front_end`] | the fixed 1 kHz low-pass, the speed-following band-pass, the rate pyramid |
//! | delay | [`correlation`], [`speed`] | open- or closed-loop correlator at the level that puts the delay near 64 samples; `v = D / τ` |
//! | warp | [`warping`] | the constant-acceleration warp factor `k` that maximises the correlation: the window's mean speed and acceleration |
//! | filter | here | a constant-acceleration Kalman filter (Joseph form) over speed and warp acceleration; the two accelerations cross-checked; zero speed at a standstill |
//! | distance | [`sleeper_count`] | sleepers counted on both sensors in the space domain against the map's atlas, outliers rejected, switches bridged |
//! | aiding | [`aiding`] | wheel odometers, if the pipeline has any besides the block channel, fused into the filter (railfuse's: the starts and stops the correlator cannot see) |
//!
//! Without the Kalman filter (`kalman = false`, the source's plain and warped correlators
//! on their own) the state is the latest measurement held until the next one.

pub mod aiding;
pub mod butterworth;
pub mod correlation;
pub mod departure;
mod filter;
pub mod front_end;
pub mod input_check;
pub mod kind;
pub mod landmark;
pub mod settings;
pub mod sleeper_count;
pub mod speed;
#[cfg(test)]
mod test_track;
pub mod warping;
mod windows;

use std::collections::VecDeque;
use std::path::Path;

use railfuse_catalog::log::LogMessage;
use railfuse_catalog::messages::{
    EddyCurrentBlock, EddyCurrentDiagnostics, FusedState, GateDecision, TrackMap,
};

use crate::base::PipelineBase;
use crate::error::Result;
use crate::filter::{Innovation, KalmanFilter};
use crate::fused::{measurement_record, Fused, PipelineCounts};
use crate::kinds::MessagePipeline;
use crate::measurement::SensorContext;
use crate::model::ConstantAcceleration;
use crate::noise::VarianceValue;
use aiding::Aiding;
use departure::Departure;
use front_end::{FrontEnd, WINDOW};
use input_check::Continuity;
pub use kind::Kind;
pub use settings::EddyCurrentSettings;
use sleeper_count::{Crossing, SleeperCounter};
use speed::{SpeedEstimator, SpeedMeasurement};

/// σ of the zero-speed and zero-acceleration updates at a standstill.
const STANDSTILL_SPEED_STD_MPS: f64 = 0.005;
const STANDSTILL_ACCELERATION_STD_MPS2: f64 = 0.02;
/// A speed innovation beyond this NIS is refused (a wrong peak); the filter is restarted
/// after this many refusals in a row (it is the filter that is wrong).
const SPEED_GATE_NIS: f64 = 25.0;
const GATE_RESTART: u32 = 5;
/// σ of a counted distance, m: a sleeper's laying error, the crossing's timing, the count
/// running a crossing behind. Counts further off than `COUNT_GATE_NIS` are not fused.
const COUNT_STD_M: f64 = 0.1;
const COUNT_GATE_NIS: f64 = 25.0;
/// Switches are bridged this far either side of the map's ends, m.
pub const SWITCH_MARGIN_M: f64 = 3.0;
/// The last measurement guides the next window for this long, ns.
const PRIOR_FOR_NS: u64 = 2_000_000_000;
/// The filter starts over after this long without a measurement, ns.
const FORGET_AFTER_NS: u64 = 5_000_000_000;
/// Crossings waiting for the filter, at most (several seconds of sleepers at line speed).
const MAX_CROSSINGS: usize = 1024;
/// Windows are at least this far apart, s.
const MIN_HOP_S: f64 = 0.1;
/// A start's fit hands over to the correlator once the start lies this far before the
/// window the correlator would use, s.
const HANDOVER_MARGIN_S: f64 = 0.3;

pub struct EddyCurrentPipeline {
    pub base: PipelineBase,
    settings: EddyCurrentSettings,
    pub counts: PipelineCounts,
    continuity: Continuity,
    front: Option<FrontEnd>,
    spacing_d: f64,
    estimator: SpeedEstimator,
    model: ConstantAcceleration,
    kf: Option<KalmanFilter<3>>,
    kf_ns: u64,
    gate_refusals: u32,
    /// The latest measurement (the state of the filterless variants).
    held: Option<SpeedMeasurement>,
    standing: bool,
    /// The last window judged a standstill.
    last_standstill_ns: Option<u64>,
    /// A start from a standstill being fitted (warped pipelines).
    departure: Option<Departure>,
    /// Sensor a's and b's sleeper counts; distance dead-reckoned along the way.
    counters: [SleeperCounter; 2],
    odometer_m: f64,
    /// Chainage = `count_origin + counter a's distance` once the first sleeper is seen.
    count_origin: Option<f64>,
    /// The sensor's place behind the front end (its lever arm's x, ≤ 0), from the vehicle at
    /// the first message. Every chainage inside is the sensor's own (switches and sleepers
    /// pass under it); the states written are the front end's, `x` further on.
    sensor_x_m: Option<f64>,
    /// Sleeper crossings not yet fused: when, and sensor a's counted distance then. The
    /// filter runs at its windows' middles, half a window behind the signal; a crossing
    /// waits until the filter reaches its time.
    crossings: VecDeque<(u64, f64)>,
    /// The level-0 sample of the next window.
    next_window: u64,
    /// The last state's stamp: states go out in time order (a window at a coarser level is
    /// centred earlier than the one before it).
    last_out_ns: u64,
    /// The last window that measured (a speed or a standstill).
    last_measured_ns: Option<u64>,
    switches: landmark::SwitchDetector,
    /// The pipeline's sensor that is the block channel.
    block_sensor: usize,
    /// Speed sensors beside it (odometers), and their samples waiting for the signal.
    aiding: Aiding,
    /// The last correlation speed the filter accepted.
    last_correlation_ns: Option<u64>,
    /// The filter's last state's stamp.
    last_state_ns: u64,
    /// The atlas as last looked up: at which sample, spacing, over a switch.
    atlas_here: Option<(u64, f64, bool)>,
}

impl EddyCurrentPipeline {
    pub fn new(
        base: PipelineBase,
        settings: EddyCurrentSettings,
        model: ConstantAcceleration,
        block_sensor: usize,
        aids: Vec<aiding::SpeedAid>,
    ) -> Result<Self> {
        let start_m = settings.initial_chainage_m;
        Ok(EddyCurrentPipeline {
            base,
            model,
            settings,
            counts: PipelineCounts::default(),
            continuity: Continuity::default(),
            front: None,
            spacing_d: 0.0,
            estimator: SpeedEstimator::default(),
            kf: None,
            kf_ns: 0,
            gate_refusals: 0,
            held: None,
            standing: false,
            last_standstill_ns: None,
            departure: None,
            counters: Default::default(),
            count_origin: None,
            sensor_x_m: None,
            crossings: VecDeque::new(),
            next_window: 0,
            last_out_ns: 0,
            last_measured_ns: None,
            switches: landmark::SwitchDetector::default(),
            atlas_here: None,
            odometer_m: start_m,
            block_sensor,
            aiding: Aiding::new(aids),
            last_correlation_ns: None,
            last_state_ns: 0,
        })
    }
}

impl MessagePipeline for EddyCurrentPipeline {
    fn counts(&self) -> &PipelineCounts {
        &self.counts
    }

    fn bind(&mut self, sensor: usize, variance: Option<VarianceValue>) {
        if let Some(j) = self.aiding.index(sensor) {
            self.aiding.tracks[j].variance = variance;
        }
    }

    fn push(
        &mut self,
        sensor: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
        out: &mut Vec<Fused>,
    ) -> Result<()> {
        if self.sensor_x_m.is_none() {
            // The run starts with the front end at `initial_chainage_m`: the sensor is behind.
            let topic = &self.base.topics[self.block_sensor];
            let x = context
                .vehicle
                .mount(topic)
                .map_or(0.0, |m| m.lever_arm_m[0]);
            self.odometer_m += x;
            self.sensor_x_m = Some(x);
        }
        let mut o = Vec::new();
        match self.aiding.index(sensor) {
            Some(j) => self.aid_message(j, msg, input, context, &mut o)?,
            None => {
                debug_assert_eq!(sensor, self.block_sensor);
                let block: EddyCurrentBlock = msg.decode(input)?;
                self.block(&block, context.track.as_ref(), &mut o);
            }
        }
        out.extend(o.into_iter().map(|mut f| {
            f.log_time_ns = msg.log_time_ns;
            f
        }));
        Ok(())
    }

    fn finish(&mut self, log_time_ns: u64, _context: &SensorContext, out: &mut Vec<Fused>) {
        let mut o = Vec::new();
        self.drain_aids(u64::MAX, &mut o);
        out.extend(o.into_iter().map(|mut f| {
            f.log_time_ns = log_time_ns;
            f
        }));
    }
}

impl EddyCurrentPipeline {
    fn topic(&self) -> String {
        self.settings.topic.clone()
    }

    fn note(&self, stamp_ns: u64, decision: GateDecision, reason: &str, o: &mut Vec<Fused>) {
        o.push(Fused {
            diagnostics: Some(measurement_record(
                stamp_ns,
                &self.topic(),
                None,
                (None, None),
                None,
                decision,
                Some(reason),
            )),
            ..Default::default()
        });
    }

    /// Starts the signal processing over (a refused block, a gap, a new rate or D): the
    /// distance over what was missed is dead-reckoned by the counters.
    fn restart(&mut self) {
        self.front = None;
        self.atlas_here = None;
        self.departure = None;
        self.estimator.forget();
        for c in &mut self.counters {
            c.restart();
        }
    }

    fn block(&mut self, b: &EddyCurrentBlock, map: Option<&TrackMap>, o: &mut Vec<Fused>) {
        match self.continuity.judge(b) {
            Err(why) => {
                self.counts.rejected_invalid += 1;
                self.note(
                    b.stamp_ns,
                    GateDecision::RejectedInvalid,
                    &why.to_string(),
                    o,
                );
                self.restart();
                return;
            }
            Ok(Some(brk)) => {
                self.note(b.stamp_ns, GateDecision::Accepted, &brk.to_string(), o);
                // Across a gap the train went on: dead-reckon it.
                if let input_check::Break::Gap { missing_s } = &brk {
                    let v = self.speed_now(b.stamp_ns);
                    self.odometer_m += v * missing_s;
                }
                self.restart();
            }
            Ok(None) => {}
        }
        self.counts.accepted += 1;
        if self.front.is_none() {
            match FrontEnd::new(
                b.sample_rate_hz,
                b.stamp_ns,
                self.settings.lowpass_hz,
                self.settings.band_floor_hz,
            ) {
                Ok(f) => {
                    self.next_window = f.samples + WINDOW as u64;
                    self.front = Some(f);
                    self.spacing_d = b.spacing_m;
                }
                Err(why) => {
                    self.counts.rejected_invalid += 1;
                    self.note(b.stamp_ns, GateDecision::RejectedInvalid, &why, o);
                    return;
                }
            }
        }
        let fs = b.sample_rate_hz;
        for (&a, &bb) in b.sensor_a.iter().zip(&b.sensor_b) {
            let front = self.front.as_mut().expect("started above");
            let f = front.push(a as f64, bb as f64);
            let t = front.now_ns();
            let samples = front.samples;
            self.drain_aids(t.saturating_sub(aiding::AID_WAIT_NS), o);
            let ds = self.speed_now(t) / fs;
            self.odometer_m += ds;
            if self.settings.count_sleepers {
                self.count(t, f.band.0, f.band.1, map);
            }
            if self.settings.landmark_search_m > 0.0 {
                let s = self.chainage_now(t);
                let search = self.settings.landmark_search_m;
                if let Some(fix) =
                    self.switches
                        .sample(f.low.0, ds, self.odometer_m, s, map, search)
                {
                    self.landmark(t, &fix, o);
                }
            }
            if samples >= self.next_window {
                self.window(t, map, o);
            }
        }
    }

    /// A switch found in the map: the chainage moved by the correction, count and filter.
    fn landmark(&mut self, t: u64, fix: &landmark::Fix, o: &mut Vec<Fused>) {
        let c = fix.correction_m;
        match &mut self.count_origin {
            Some(origin) => *origin += c,
            None => self.odometer_m += c,
        }
        if let Some(kf) = self.kf.as_mut() {
            kf.estimate.state[0] += c;
        }
        let why = format!(
            "landmark: switch {} (its middle at {:.1} m): chainage corrected by {c:+.2} m",
            fix.name, fix.chainage_m
        );
        self.note(t, GateDecision::Accepted, &why, o);
    }

    /// The speed now: the filter's prediction, or the latest measurement.
    fn speed_now(&self, t_ns: u64) -> f64 {
        if self.standing {
            return 0.0;
        }
        match (&self.kf, &self.held) {
            (Some(kf), _) => {
                let dt = t_ns.saturating_sub(self.kf_ns) as f64 / 1e9;
                let x = kf.estimate.state;
                (x[1] + x[2] * dt).max(0.0)
            }
            (None, Some(m)) => m.speed_mps,
            _ => 0.0,
        }
    }

    /// The acceleration now: the filter's, or the latest measurement's (0 without either).
    fn acceleration_now(&self) -> f64 {
        match (&self.kf, &self.held) {
            _ if self.standing => 0.0,
            (Some(kf), _) => kf.estimate.state[2],
            (None, Some(m)) => m.acceleration.map_or(0.0, |a| a.0),
            _ => 0.0,
        }
    }

    /// The chainage estimate at `t_ns` (for the atlas): the filter's, else the count's.
    fn chainage_now(&self, t_ns: u64) -> f64 {
        match &self.kf {
            Some(kf) => {
                let dt = t_ns.saturating_sub(self.kf_ns) as f64 / 1e9;
                let x = kf.estimate.state;
                x[0] + x[1] * dt + 0.5 * x[2] * dt * dt
            }
            None => self.count_chainage().unwrap_or(self.odometer_m),
        }
    }

    /// The chainage by the count now (dead-reckoned since the last sleeper).
    fn count_chainage(&self) -> Option<f64> {
        self.count_origin
            .map(|o| o + self.counters[0].distance_at(self.odometer_m))
    }

    /// The atlas where the sensors are: the sleeper spacing, and whether they are over a
    /// switch (with its margin).
    fn atlas_at(&self, s: f64, map: Option<&TrackMap>) -> (f64, bool) {
        match map {
            Some(m) if !m.sleeper_sections.is_empty() => (
                m.sleeper_spacing_at(s),
                m.switches.iter().any(|w| {
                    s > w.start_chainage_m - SWITCH_MARGIN_M
                        && s - self.spacing_d < w.end_chainage_m + SWITCH_MARGIN_M
                }),
            ),
            Some(m) => (m.sleeper_spacing_m, false),
            None => (self.settings.sleeper_spacing_m, false),
        }
    }

    fn count(&mut self, t: u64, ya: f64, yb: f64, map: Option<&TrackMap>) {
        let s = self.chainage_now(t);
        // Looked up every 32 samples (13 cm at 40 m/s): a lookup per sample was a tenth of
        // the pipeline's time.
        let sample = self.front.as_ref().map_or(0, |f| f.samples);
        let (spacing, irregular) = match self.atlas_here {
            Some((at, spacing, irregular)) if sample < at + 32 => (spacing, irregular),
            _ => {
                let (spacing, irregular) = self.atlas_at(s, map);
                self.atlas_here = Some((sample, spacing, irregular));
                (spacing, irregular)
            }
        };
        let crossed = self.counters[0].sample(ya, self.odometer_m, spacing, irregular);
        self.counters[1].sample(yb, self.odometer_m, spacing, irregular);
        if let Some(c) = crossed {
            // Not while the pipeline believes the train stands (the first metre of a start,
            // before its speed is observable): the dead-reckoned distance has not moved.
            if self.count_origin.is_none() && !self.standing && matches!(c, Crossing::Counted(_)) {
                self.count_origin = Some(s - self.counters[0].distance_m);
            }
            if self.crossings.len() == MAX_CROSSINGS {
                self.crossings.pop_front();
            }
            self.crossings.push_back((t, self.counters[0].distance_m));
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn record(
        &mut self,
        stamp_ns: u64,
        z: Option<f64>,
        r: Option<f64>,
        i: Option<Innovation>,
        decision: GateDecision,
        reason: Option<&str>,
        diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let topic = self.topic();
        self.record_as(&topic, stamp_ns, z, r, i, decision, reason, diag, o);
    }

    /// A diagnostics record of sensor `topic`'s measurement.
    #[allow(clippy::too_many_arguments)]
    fn record_as(
        &self,
        topic: &str,
        stamp_ns: u64,
        z: Option<f64>,
        r: Option<f64>,
        i: Option<Innovation>,
        decision: GateDecision,
        reason: Option<&str>,
        diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let mut d = measurement_record(stamp_ns, topic, None, (z, r), i, decision, reason);
        d.eddy_current = Some(diag);
        o.push(Fused {
            diagnostics: Some(d),
            ..Default::default()
        });
    }
}

impl EddyCurrentPipeline {
    /// The front end's chainage with the sensor at `sensor_chainage_m`.
    fn front_chainage(&self, sensor_chainage_m: f64) -> f64 {
        sensor_chainage_m - self.sensor_x_m.unwrap_or(0.0)
    }
}

/// A state, if every number in it is finite: NaN never reaches a fused channel.
fn push_state(state: FusedState, o: &mut Vec<Fused>) {
    let finite = [state.chainage_m, state.speed_mps, state.acceleration_mps2]
        .iter()
        .chain(&state.covariance)
        .all(|v| v.is_finite());
    if finite {
        o.push(Fused {
            state: Some(state),
            ..Default::default()
        });
    }
}
