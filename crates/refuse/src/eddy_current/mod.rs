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
//!
//! Without the Kalman filter (`kalman = false`, the source's plain and warped correlators
//! on their own) the state is the latest measurement held until the next one.

pub mod butterworth;
pub mod correlation;
pub mod departure;
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

use std::collections::VecDeque;
use std::path::Path;

use nalgebra::{RowVector3, Vector3};
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
use departure::{Departure, Fit, Moved};
use front_end::{FrontEnd, WINDOW};
use input_check::Continuity;
pub use kind::Kind;
pub use settings::EddyCurrentSettings;
use sleeper_count::{Crossing, SleeperCounter};
use speed::{Outcome, Request, SpeedEstimator, SpeedMeasurement};

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
    /// The atlas as last looked up: at which sample, spacing, over a switch.
    atlas_here: Option<(u64, f64, bool)>,
}

impl EddyCurrentPipeline {
    pub fn new(
        base: PipelineBase,
        settings: EddyCurrentSettings,
        model: ConstantAcceleration,
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
            crossings: VecDeque::new(),
            next_window: 0,
            last_out_ns: 0,
            last_measured_ns: None,
            switches: landmark::SwitchDetector::default(),
            atlas_here: None,
            odometer_m: start_m,
        })
    }
}

impl MessagePipeline for EddyCurrentPipeline {
    fn counts(&self) -> &PipelineCounts {
        &self.counts
    }

    fn bind(&mut self, _sensor: usize, _variance: Option<VarianceValue>) {}

    fn push(
        &mut self,
        _sensor: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
        out: &mut Vec<Fused>,
    ) -> Result<()> {
        let block: EddyCurrentBlock = msg.decode(input)?;
        let mut o = Vec::new();
        self.block(&block, context.track.as_ref(), &mut o);
        out.extend(o.into_iter().map(|mut f| {
            f.log_time_ns = msg.log_time_ns;
            f
        }));
        Ok(())
    }

    fn finish(&mut self, _log_time_ns: u64, _context: &SensorContext, _out: &mut Vec<Fused>) {}
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

    /// One correlation window ending at `t`: a measurement, the filter, a state.
    fn window(&mut self, t: u64, map: Option<&TrackMap>, o: &mut Vec<Fused>) {
        let (q, prior) = self.request(t);
        let (outcome, start) = match self.departing(t, &q) {
            Some(o) => o,
            None => {
                let front = self.front.as_ref().expect("running");
                (self.estimator.measure(front, &q), None)
            }
        };
        self.schedule(t, map, &outcome, start.is_some(), prior);
        let diag = EddyCurrentDiagnostics {
            sleepers_a: self.counters[0].sleepers,
            sleepers_b: self.counters[1].sleepers,
            ..Default::default()
        };
        match outcome {
            Outcome::Moving(m) => self.moving(t, m, start, diag, o),
            Outcome::Standstill { stamp_ns } => self.standstill(t, stamp_ns, diag, o),
            Outcome::NoLock { stamp_ns, best_rho } => self.no_lock(t, stamp_ns, best_rho, diag, o),
        }
    }

    /// What the correlator is asked, with the speed the last measurement says now (nothing
    /// when it is too old to go by).
    fn request(&self, t: u64) -> (Request, Option<f64>) {
        let fresh = self
            .last_measured_ns
            .is_some_and(|m| t.saturating_sub(m) < PRIOR_FOR_NS);
        let prior = match (&self.kf, &self.held) {
            (Some(_), _) if fresh => Some(self.speed_now(t)),
            (None, Some(m)) if fresh => Some(m.speed_mps),
            _ => None,
        }
        .filter(|v| *v > 0.05);
        let q = Request {
            spacing_m: self.spacing_d,
            prior_mps: prior,
            prior_acceleration_mps2: self.acceleration_now(),
            correlator: self.settings.correlator,
            warp: self.settings.warp,
            max_acceleration_mps2: self.settings.max_acceleration_mps2,
            min_rho: self.settings.min_rho,
            standstill_factor: self.settings.standstill_factor,
        };
        (q, prior)
    }

    /// The next window: a quarter of this one's span later, at least 0.1 s (a start's fits
    /// every 0.1 s); and the band-pass tuned to the speed and the sleeper spacing here.
    fn schedule(
        &mut self,
        t: u64,
        map: Option<&TrackMap>,
        outcome: &Outcome,
        starting: bool,
        prior: Option<f64>,
    ) {
        let front = self.front.as_ref().expect("running");
        let level = match outcome {
            _ if self.departure.is_some() || starting => 0,
            Outcome::Moving(m) => m.level,
            _ => prior.map_or(0, |v| SpeedEstimator::level_for(front, self.spacing_d, v)),
        };
        let span = (WINDOW << level) as f64;
        let hop = (span / 4.0).max(MIN_HOP_S * front.fs_hz);
        self.next_window = front.samples + hop as u64;
        let spacing = self.atlas_at(self.chainage_now(t), map).0;
        let speed_for_band = match outcome {
            Outcome::Moving(m) => m.speed_mps,
            _ => self.speed_now(t),
        };
        if let Some(f) = self.front.as_mut() {
            f.tune(speed_for_band, spacing);
        }
    }

    /// A window the correlator measured.
    fn moving(
        &mut self,
        t: u64,
        m: SpeedMeasurement,
        start: Option<Moved>,
        mut diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        self.standing = false;
        self.last_measured_ns = Some(t);
        diag.window = match start {
            Some(_) => "moving_off".into(),
            None => "moving".into(),
        };
        if let Some(s) = &start {
            self.started(s);
        }
        diag.rho = Some(m.rho);
        diag.unwarped_rho = m.unwarped_rho;
        diag.warp_k = m.warp_k;
        diag.warp_acceleration_mps2 = m.acceleration.map(|a| a.0);
        diag.delay_s = Some(m.lag / self.front.as_ref().map_or(1.0, |f| f.rate(m.level)));
        diag.level = Some(m.level as u32);
        match self.settings.kalman {
            true => {
                self.filter_moving(&m, &mut diag, o);
                if let Some(s) = &start {
                    self.start_chainage(s);
                }
            }
            false => {
                self.held = Some(m);
                self.state_of_measurement(m.stamp_ns, o);
                self.record(
                    m.stamp_ns,
                    Some(m.speed_mps),
                    Some(m.speed_variance),
                    None,
                    GateDecision::Accepted,
                    None,
                    diag,
                    o,
                );
            }
        }
    }

    /// A window as quiet as the noise floor: the train stands.
    fn standstill(
        &mut self,
        t: u64,
        stamp_ns: u64,
        mut diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        self.last_measured_ns = Some(t);
        self.last_standstill_ns = Some(t);
        self.standing = true;
        diag.window = "standstill".into();
        if self.settings.kalman {
            let i = self.filter_standstill(stamp_ns);
            self.record(
                stamp_ns,
                Some(0.0),
                Some(STANDSTILL_SPEED_STD_MPS.powi(2)),
                i,
                GateDecision::Accepted,
                Some("standstill: as quiet as the noise floor"),
                diag,
                o,
            );
            self.filter_state(o);
        } else {
            self.held = Some(SpeedMeasurement {
                stamp_ns,
                speed_mps: 0.0,
                speed_variance: STANDSTILL_SPEED_STD_MPS.powi(2),
                acceleration: Some((0.0, STANDSTILL_ACCELERATION_STD_MPS2.powi(2))),
                rho: 0.0,
                warp_k: None,
                unwarped_rho: None,
                level: 0,
                lag: 0.0,
                acquired: false,
            });
            self.state_of_measurement(stamp_ns, o);
            self.record(
                stamp_ns,
                Some(0.0),
                None,
                None,
                GateDecision::Accepted,
                Some("standstill: as quiet as the noise floor"),
                diag,
                o,
            );
        }
    }

    /// A window without a measurement: the filter predicts on, the filterless variants hold.
    fn no_lock(
        &mut self,
        t: u64,
        stamp_ns: u64,
        best_rho: f64,
        mut diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        diag.window = "no_lock".into();
        diag.rho = Some(best_rho);
        let why = match self.departure.is_some() {
            true => format!(
                "moving off: no start fitted yet (the trailing sensor must pass track the leading one saw moving; best ρ {best_rho:.2})"
            ),
            false => format!(
                "no correlation peak of ρ ≥ {} over enough track (best ρ {best_rho:.2})",
                self.settings.min_rho
            ),
        };
        self.record(
            stamp_ns,
            None,
            None,
            None,
            GateDecision::RejectedInvalid,
            Some(&why),
            diag,
            o,
        );
        // The filter predicts on; the filterless variants hold their last value.
        match self.settings.kalman {
            true => {
                // Long without a measurement: the filter knows nothing any more.
                if self
                    .last_measured_ns
                    .is_none_or(|m| t.saturating_sub(m) > FORGET_AFTER_NS)
                {
                    self.kf = None;
                }
                self.advance(stamp_ns, false);
                self.filter_state(o);
            }
            false => {
                if self.held.is_some() {
                    self.state_of_measurement(stamp_ns, o);
                }
            }
        }
    }

    /// A start from a standstill (warped pipelines with `start_fit`, after a standstill,
    /// while the signal is no longer quiet): the start's fit instead of the correlator, until
    /// the start lies before the window the correlator would use. None: the correlator's turn.
    fn departing(&mut self, t: u64, q: &Request) -> Option<(Outcome, Option<Moved>)> {
        let front = self.front.as_ref()?;
        let on = self.settings.warp && self.settings.start_fit;
        if !on || SpeedEstimator::quiet(front, q) {
            self.departure = None;
            return None;
        }
        if self.departure.is_none() && self.standing {
            let quiet_ns = self.last_standstill_ns?;
            let chainage = self.kf.as_ref().map(|kf| kf.estimate.state[0]);
            self.departure = Some(Departure::new(quiet_ns, self.odometer_m, chainage));
        }
        let dep = self.departure.as_mut()?;
        let (stood_odometer_m, stood_chainage_m) = (dep.stood_odometer_m, dep.stood_chainage_m);
        let min_rho = self.settings.min_rho.max(departure::MIN_RHO);
        let max_acceleration = self.settings.max_acceleration_mps2;
        let fit = dep.fit(front, self.spacing_d, max_acceleration, min_rho);
        let nothing = |best_rho| {
            Some((
                Outcome::NoLock {
                    stamp_ns: t,
                    best_rho,
                },
                None,
            ))
        };
        match fit {
            None => {
                self.departure = None;
                None
            }
            Some(Fit::Nothing { best_rho }) => nothing(best_rho),
            Some(Fit::Unconfirmed(start)) => nothing(start.rho),
            Some(Fit::Confirmed(start)) => {
                let since = (start.at_ns - start.onset_ns) as f64 / 1e9;
                let (v, a) = (start.speed_mps, start.acceleration_mps2);
                let l = SpeedEstimator::level_for_motion(front, self.spacing_d, v, a);
                let span = (WINDOW << l) as f64 / front.fs_hz;
                if since > span + HANDOVER_MARGIN_S {
                    self.departure = None;
                }
                let m = SpeedMeasurement {
                    stamp_ns: start.at_ns,
                    speed_mps: start.speed_mps,
                    speed_variance: start.speed_variance(),
                    acceleration: Some((start.acceleration_mps2, start.acceleration_variance())),
                    rho: start.rho,
                    warp_k: None,
                    unwarped_rho: None,
                    level: start.level,
                    lag: self.spacing_d / start.speed_mps * front.rate(start.level),
                    // A start is a jump the filter's gate would refuse.
                    acquired: true,
                };
                let moved = Moved {
                    start,
                    stood_odometer_m,
                    stood_chainage_m,
                };
                Some((Outcome::Moving(m), Some(moved)))
            }
        }
    }

    /// A start fitted: the dead-reckoned distance moves on to what the start covered (it
    /// stood still while the speed was not yet observable).
    fn started(&mut self, m: &Moved) {
        let from = m.stood_odometer_m + m.start.travelled_m;
        self.odometer_m = self.odometer_m.max(from);
    }

    /// The filter's chainage from where it stood plus what the start covered.
    fn start_chainage(&mut self, m: &Moved) {
        let (Some(stood_at), s) = (m.stood_chainage_m, &m.start) else {
            return;
        };
        let z = stood_at + s.travelled_m;
        self.advance(s.at_ns, false);
        if let Some(kf) = self.kf.as_mut() {
            let var = (0.02 + 0.02 * s.travelled_m).powi(2);
            kf.update(&RowVector3::new(1.0, 0.0, 0.0), var, z);
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
        let mut d = measurement_record(stamp_ns, &self.topic(), None, (z, r), i, decision, reason);
        d.eddy_current = Some(diag);
        o.push(Fused {
            diagnostics: Some(d),
            ..Default::default()
        });
    }

    /// The filterless state: the held measurement, the count's chainage.
    fn state_of_measurement(&mut self, stamp_ns: u64, o: &mut Vec<Fused>) {
        let Some(m) = self.held else { return };
        let (a, va) = m.acceleration.unwrap_or((0.0, 1.0));
        let chainage = self.count_chainage().unwrap_or(self.odometer_m);
        let var_s = 0.25;
        // A window centred before the last state (a coarser level's) gives no state: its
        // speed belongs to its middle, and states go out in time order.
        if stamp_ns < self.last_out_ns {
            return;
        }
        self.last_out_ns = stamp_ns;
        let state = FusedState {
            stamp_ns,
            chainage_m: chainage,
            speed_mps: m.speed_mps,
            acceleration_mps2: a,
            covariance: [
                var_s,
                0.0,
                0.0,
                0.0,
                m.speed_variance + self.settings.speed_noise_floor_mps.powi(2),
                0.0,
                0.0,
                0.0,
                va,
            ],
            source: self.topic(),
            sensor_states: Vec::new(),
            plane: None,
        };
        push_state(state, o);
    }

    fn filter_state(&mut self, o: &mut Vec<Fused>) {
        let Some(kf) = &self.kf else { return };
        let x = kf.estimate.state;
        let p = kf.estimate.covariance;
        let state = FusedState {
            stamp_ns: self.kf_ns,
            chainage_m: x[0],
            speed_mps: x[1],
            acceleration_mps2: x[2],
            covariance: [
                p[(0, 0)],
                p[(0, 1)],
                p[(0, 2)],
                p[(1, 0)],
                p[(1, 1)],
                p[(1, 2)],
                p[(2, 0)],
                p[(2, 1)],
                p[(2, 2)],
            ],
            source: self.topic(),
            sensor_states: Vec::new(),
            plane: None,
        };
        push_state(state, o);
    }

    /// The filter to `t`, never backwards; with `count`, fusing the newest sleeper crossing
    /// due by then at its own time (only beside a speed measurement: without one, at a stop
    /// or with no lock, the band-passed signal the crossings come from is not tuned to the
    /// speed, and they are dropped). For a window centred before the filter's time: how much
    /// before (s), so its speed is compared with the state's speed then, `v − a Δ` (constant
    /// acceleration: exact).
    fn advance(&mut self, t: u64, count: bool) -> f64 {
        if self.kf.is_none() {
            return 0.0;
        }
        let mut due = None;
        while self.crossings.front().is_some_and(|c| c.0 <= t) {
            due = self.crossings.pop_front();
        }
        if let (Some((tc, counted)), Some(origin), true) = (due, self.count_origin, count) {
            if tc > self.kf_ns {
                self.predict_to(tc);
                self.fuse_count(origin + counted);
            }
        }
        if t > self.kf_ns {
            self.predict_to(t);
            0.0
        } else {
            (self.kf_ns - t) as f64 / 1e9
        }
    }

    /// Predicts the filter to `t` (after its time). Braking through zero without a
    /// measurement, the train stops where the speed reaches zero (the correlator sees the
    /// speed's magnitude; a train does not run backwards on its brakes): the prediction goes
    /// to that moment, the estimate is projected onto the constraint (its covariance left as
    /// it is: a measurement, not the constraint, should make the filter sure), and it stands
    /// from there.
    fn predict_to(&mut self, t: u64) {
        let Some(kf) = self.kf.as_mut() else { return };
        let dt = t.saturating_sub(self.kf_ns) as f64 / 1e9;
        let x = kf.estimate.state;
        let to_stop = match x[1] > 0.0 && x[2] < 0.0 {
            true => -x[1] / x[2],
            false => f64::INFINITY,
        };
        if to_stop < dt {
            kf.predict(&self.model, to_stop);
            let x = &mut kf.estimate.state;
            (x[1], x[2]) = (0.0, 0.0);
            kf.predict(&self.model, dt - to_stop);
        } else {
            kf.predict(&self.model, dt);
        }
        let x = &mut kf.estimate.state;
        if x[1] < 0.0 {
            (x[1], x[2]) = (0.0, x[2].max(0.0));
        }
        self.kf_ns = t;
    }

    fn filter_moving(
        &mut self,
        m: &SpeedMeasurement,
        diag: &mut EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let r_v = m.speed_variance + self.settings.speed_noise_floor_mps.powi(2);
        if self.kf.is_none() {
            // Started at the first measurement: chainage from the count where there is one.
            let s0 = self.count_chainage().unwrap_or(self.odometer_m);
            let (a0, va) = m.acceleration.unwrap_or((0.0, 1.0));
            self.kf = Some(KalmanFilter::new(
                Vector3::new(s0, m.speed_mps, a0),
                nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, r_v, va)),
            ));
            self.kf_ns = m.stamp_ns;
            self.record(
                m.stamp_ns,
                Some(m.speed_mps),
                Some(r_v),
                None,
                GateDecision::BeforeInitialisation,
                Some("the filter starts here"),
                diag.clone(),
                o,
            );
            self.filter_state(o);
            return;
        }
        let late_s = self.advance(m.stamp_ns, true);
        let kf = self.kf.as_mut().expect("started");
        let a_prior = kf.estimate.state[2];
        let p_aa = kf.estimate.covariance[(2, 2)];
        diag.filter_acceleration_mps2 = Some(a_prior);
        let h_v = RowVector3::new(0.0, 1.0, -late_s);
        let innovation = kf.innovation(&h_v, r_v, m.speed_mps);
        if innovation.nis > SPEED_GATE_NIS && !m.acquired {
            self.gate_refusals += 1;
            self.counts.rejected_gate += 1;
            let why = format!(
                "speed {:.3} m/s, NIS {:.1} beyond {SPEED_GATE_NIS}",
                m.speed_mps, innovation.nis
            );
            self.record(
                m.stamp_ns,
                Some(m.speed_mps),
                Some(r_v),
                Some(innovation),
                GateDecision::RejectedGate,
                Some(&why),
                diag.clone(),
                o,
            );
            if self.gate_refusals >= GATE_RESTART {
                // The correlator has agreed with itself and not the filter five times: the
                // filter is what diverged.
                self.kf = None;
                self.gate_refusals = 0;
            }
            self.filter_state(o);
            return;
        }
        self.gate_refusals = 0;
        let i = kf.update(&h_v, r_v, m.speed_mps);
        let mut reason = None;
        if let Some((acc, var)) = m.acceleration {
            let gap = (acc - a_prior).abs();
            let sigma = (var + p_aa).sqrt();
            if gap > self.settings.acceleration_check_sigma * sigma {
                reason = Some(format!(
                    "warp acceleration {acc:+.2} m/s² and the filter's {a_prior:+.2} m/s² are {:.1} σ apart: divergence or a wrong warp; not fused",
                    gap / sigma
                ));
            } else {
                kf.update(&RowVector3::new(0.0, 0.0, 1.0), var, acc);
            }
        }
        self.record(
            m.stamp_ns,
            Some(m.speed_mps),
            Some(r_v),
            Some(i),
            GateDecision::Accepted,
            reason.as_deref(),
            diag.clone(),
            o,
        );
        self.filter_state(o);
    }

    /// The counted distance `s` as a chainage measurement at the filter's time.
    fn fuse_count(&mut self, s: f64) {
        if let Some(kf) = self.kf.as_mut() {
            let h = RowVector3::new(1.0, 0.0, 0.0);
            if kf.innovation(&h, COUNT_STD_M.powi(2), s).nis <= COUNT_GATE_NIS {
                kf.update(&h, COUNT_STD_M.powi(2), s);
            }
        }
    }

    fn filter_standstill(&mut self, t: u64) -> Option<Innovation> {
        self.kf.as_ref()?;
        self.advance(t, false);
        let kf = self.kf.as_mut()?;
        let i = kf.update(
            &RowVector3::new(0.0, 1.0, 0.0),
            STANDSTILL_SPEED_STD_MPS.powi(2),
            0.0,
        );
        kf.update(
            &RowVector3::new(0.0, 0.0, 1.0),
            STANDSTILL_ACCELERATION_STD_MPS2.powi(2),
            0.0,
        );
        Some(i)
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
