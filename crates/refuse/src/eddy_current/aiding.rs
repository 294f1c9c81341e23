//! Speed aiding (railfuse's, not source 004's): the wheel odometers every train has, fused
//! into the pipeline's Kalman filter beside the correlator.
//!
//! The correlator is blind for the first metre of every start (the trailing sensor must pass
//! track the leading one saw moving) and slow to see a stop (a window must be as quiet as the
//! noise floor); an odometer counts pulses from the first centimetre and reads exactly zero
//! at a stand. Its speed is the mean over its window `W` (`speed_window_s`):
//!
//! ```text
//! z = v − a W / 2 + n,    Var n = σ² + (k v)²
//! ```
//!
//! `σ²` the sensor's variance (its pulse quantisation), `k` `speed_sensor_scale_std` (a worn
//! wheel, a slip under the gate), so that at line speed the correlator, not the wheel, sets
//! the speed. A slipping or sliding wheel disagrees with the filter, and its NIS gate keeps
//! it out; a filter that has refused the wheel for a whole second with no correlation to go
//! by is restarted from it (it is the filter that is wrong). A zero reading, no pulse over a
//! whole window, is a standstill: zero speed and acceleration, as a quiet correlation window
//! gives, but a window after the stop rather than seconds after it.
//!
//! The filter runs at the correlation windows' middles, the times they measure (half a window
//! behind the signal): the samples wait in a bounded queue until a window reaches their stamp,
//! so that the filter takes them, the windows and the sleeper crossings in time order. A
//! sample no window has reached [`AID_WAIT_NS`] after it (the long windows of low speed, the
//! eddy-current channel late or gone) is fused anyway, and the windows come late to the
//! filter (each is fused as a measurement of the state that long before).

use std::collections::VecDeque;
use std::path::Path;

use nalgebra::{RowVector3, Vector3};
use railfuse_catalog::log::LogMessage;
use railfuse_catalog::messages::{EddyCurrentDiagnostics, GateDecision};

use crate::error::{Error, Result};
use crate::filter::KalmanFilter;
use crate::fused::Fused;
use crate::measurement::{Measurement, SensorContext, SensorModel};
use crate::noise::VarianceValue;

use super::*;

/// A speed sample waits at most this long for a correlation window, ns.
pub const AID_WAIT_NS: u64 = 500_000_000;
/// Samples waiting, at most (20 s of two 25 Hz odometers).
const MAX_WAITING: usize = 1024;
/// A speed sample beyond this NIS is refused (a slipping or sliding wheel), unless its
/// sensor has its own `gate`.
const AID_GATE_NIS: f64 = 16.0;
/// Refused this long in a row, with the correlator not measuring, the filter restarts from
/// the wheel, ns.
const AID_RESTART_NS: u64 = 1_000_000_000;
/// The correlator is measuring if it gave an accepted speed this recently, ns.
const CORRELATING_NS: u64 = 1_000_000_000;
/// A correlation standstill is overruled by a wheel that turned this recently, ns.
const AID_FRESH_NS: u64 = 500_000_000;

/// One speed sensor beside the block channel: the pipeline's sensor index and its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedAid {
    pub sensor: usize,
    pub window_s: f64,
}

/// What the pipeline keeps of one speed sensor.
#[derive(Debug, Clone, Default)]
pub(super) struct AidTrack {
    pub variance: Option<VarianceValue>,
    /// Since when it has been refused, in a row.
    refused_since_ns: Option<u64>,
}

/// A speed sample waiting for the signal.
#[derive(Debug, Clone, Copy)]
pub(super) struct Waiting {
    aid: usize,
    m: Measurement,
}

/// The speed sensors' samples and the latest wheel reading, beside the pipeline.
#[derive(Debug, Default)]
pub(super) struct Aiding {
    pub aids: Vec<SpeedAid>,
    pub tracks: Vec<AidTrack>,
    waiting: VecDeque<Waiting>,
    scratch: Vec<Measurement>,
    /// The latest sample fused or judged: when, and whether the wheel turned.
    pub latest: Option<(u64, bool)>,
    /// Since when the wheels have said the train stands (none turning for a window).
    pub standing_since: Option<u64>,
}

impl Aiding {
    pub fn new(aids: Vec<SpeedAid>) -> Self {
        Self {
            tracks: vec![AidTrack::default(); aids.len()],
            aids,
            ..Default::default()
        }
    }

    pub fn index(&self, sensor: usize) -> Option<usize> {
        self.aids.iter().position(|a| a.sensor == sensor)
    }

    /// Whether the wheels said the train stood before `t`: a correlation window measuring
    /// then is of the approach to the stop.
    pub fn standing_before(&self, t: u64) -> bool {
        self.standing_since.is_some_and(|s| s > t)
    }

    /// Whether a wheel turned within [`AID_FRESH_NS`] of `t`.
    pub fn turning_at(&self, t: u64) -> bool {
        self.latest
            .is_some_and(|(at, turning)| turning && t.abs_diff(at) <= AID_FRESH_NS)
    }
}

impl EddyCurrentPipeline {
    /// A speed sensor's message: checked, queued, and what the signal has reached fused.
    pub(super) fn aid_message(
        &mut self,
        aid: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
        o: &mut Vec<Fused>,
    ) -> Result<()> {
        let a = &mut self.aiding;
        a.scratch.clear();
        if let Some(model) = SensorModel::for_schema(msg.channel.schema_name()) {
            model.decode(msg, input, context, &mut a.scratch)?;
        }
        let Some(mut m) = a.scratch.pop() else {
            return Err(Error::Channel {
                input: input.to_owned(),
                pipeline: self.base.name.clone(),
                topic: msg.channel.topic.clone(),
                declared: "an eddy_current pipeline's speed sensor".into(),
                problem: "gives no speed".into(),
            });
        };
        let variance = crate::noise::speed_variance(&m, a.tracks[aid].variance);
        if let Err(why) = variance {
            self.counts.rejected_invalid += 1;
            let topic = msg.channel.topic.clone();
            o.push(Fused {
                diagnostics: Some(measurement_record(
                    m.stamp_ns,
                    &topic,
                    None,
                    (Some(m.value), None),
                    None,
                    GateDecision::RejectedInvalid,
                    Some(why),
                )),
                ..Default::default()
            });
            return Ok(());
        }
        m.reported_variance = variance.ok();
        if a.waiting.len() == MAX_WAITING {
            let oldest = a.waiting.pop_front().expect("full");
            self.fuse_aid(oldest, o);
        }
        self.aiding.waiting.push_back(Waiting { aid, m });
        let signal = self.front.as_ref().map_or(0, |f| f.now_ns());
        self.drain_aids(signal.max(m.stamp_ns).saturating_sub(AID_WAIT_NS), o);
        Ok(())
    }

    /// Fuses the waiting samples stamped at or before `t`.
    pub(super) fn drain_aids(&mut self, t: u64, o: &mut Vec<Fused>) {
        while let Some(w) = self.aiding.waiting.front().copied() {
            if w.m.stamp_ns > t {
                break;
            }
            self.aiding.waiting.pop_front();
            self.fuse_aid(w, o);
        }
    }

    fn fuse_aid(&mut self, w: Waiting, o: &mut Vec<Fused>) {
        let SpeedAid { sensor, window_s } = self.aiding.aids[w.aid];
        let (t, z) = (w.m.stamp_ns, w.m.value);
        let r0 = w.m.reported_variance.expect("checked when queued");
        let topic = self.base.topics[sensor].clone();
        let gate = self.base.gates[sensor].unwrap_or(AID_GATE_NIS);
        // No pulse over its whole window: one pulse in 0.2 s is 7 cm/s, a speed a braking
        // train passes in a few hundredths of a second.
        let standing = z == 0.0;
        self.aiding.latest = Some((t, z > 0.0));
        let since = self.aiding.standing_since;
        self.aiding.standing_since = standing.then(|| since.unwrap_or(t));
        let diag = self.wheel_diagnostics();
        if self.kf.is_none() {
            self.start_from_wheel(t, z, r0, &topic, diag, o);
            return;
        }
        let late_s = self.advance(t, false);
        if standing {
            return self.hold_standing(w.aid, t, &topic, diag, o);
        }
        let kf = self.kf.as_mut().expect("checked above");
        let v = kf.estimate.state[1].max(0.0);
        let r = r0 + (self.settings.speed_sensor_scale_std * v).powi(2);
        let h = RowVector3::new(0.0, 1.0, -(late_s + window_s / 2.0));
        let innovation = kf.innovation(&h, r, z);
        if innovation.nis > gate {
            let since = *self.aiding.tracks[w.aid].refused_since_ns.get_or_insert(t);
            let correlating = self
                .last_correlation_ns
                .is_some_and(|c| t.saturating_sub(c) < CORRELATING_NS);
            if t.saturating_sub(since) >= AID_RESTART_NS && !correlating {
                // Refused for a second with nothing else to go by: it is the filter that is
                // wrong. Start it over from the wheel.
                self.kf = None;
                self.aiding.tracks[w.aid].refused_since_ns = None;
                self.start_from_wheel(t, z, r, &topic, diag, o);
                return;
            }
            self.counts.rejected_gate += 1;
            let why = format!(
                "wheel {z:.3} m/s, filter {:.3} m/s: NIS {:.1} beyond {gate} (a slip or a slide)",
                (h * kf.estimate.state)[0],
                innovation.nis
            );
            self.record_as(
                &topic,
                t,
                Some(z),
                Some(r),
                Some(innovation),
                GateDecision::RejectedGate,
                Some(&why),
                diag,
                o,
            );
            self.wheel_state(t, o);
            return;
        }
        self.aiding.tracks[w.aid].refused_since_ns = None;
        let i = kf.update(&h, r, z);
        self.counts.accepted += 1;
        self.record_as(
            &topic,
            t,
            Some(z),
            Some(r),
            Some(i),
            GateDecision::Accepted,
            None,
            diag,
            o,
        );
        self.wheel_state(t, o);
    }

    /// A wheel sample's diagnostics: the sleepers counted so far.
    fn wheel_diagnostics(&self) -> EddyCurrentDiagnostics {
        EddyCurrentDiagnostics {
            window: "wheel".into(),
            sleepers_a: self.counters[0].sleepers,
            sleepers_b: self.counters[1].sleepers,
            ..Default::default()
        }
    }

    /// The wheel turned no pulse over its window: zero speed fused, and the train held where
    /// it stands.
    fn hold_standing(
        &mut self,
        aid: usize,
        t: u64,
        topic: &str,
        diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let i = self.zero_velocity();
        // Held there: a standing train's chainage does not wander with the residue of its
        // speed (the estimate projected onto the constraint, its covariance as the updates
        // left it).
        if let Some(kf) = self.kf.as_mut() {
            let x = &mut kf.estimate.state;
            (x[1], x[2]) = (0.0, 0.0);
        }
        self.aiding.tracks[aid].refused_since_ns = None;
        self.record_as(
            topic,
            t,
            Some(0.0),
            Some(STANDSTILL_SPEED_STD_MPS.powi(2)),
            i,
            GateDecision::Accepted,
            Some("standstill: the wheel turned no pulse over its window"),
            diag,
            o,
        );
        self.filter_state(o);
    }

    /// A state at a wheel's sample where the windows leave a gap of more than one and a half
    /// hops (the long windows of low speed): where they come every hop, at line speed, they
    /// set the states' pace as without the wheel (a state between two windows would be a
    /// prediction of what the next one measures).
    fn wheel_state(&mut self, t: u64, o: &mut Vec<Fused>) {
        if t.saturating_sub(self.last_state_ns) as f64 / 1e9 > 1.5 * MIN_HOP_S {
            self.filter_state(o);
        }
    }

    /// The filter started from a wheel: where the count or the dead reckoning puts the train,
    /// the wheel's speed, no acceleration known.
    fn start_from_wheel(
        &mut self,
        t: u64,
        z: f64,
        r: f64,
        topic: &str,
        diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let s0 = self.count_chainage().unwrap_or(self.odometer_m);
        self.kf = Some(KalmanFilter::new(
            Vector3::new(s0, z, 0.0),
            nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, r, 1.0)),
        ));
        self.kf_ns = t;
        self.record_as(
            topic,
            t,
            Some(z),
            Some(r),
            None,
            GateDecision::BeforeInitialisation,
            Some("the filter starts here, from the wheel"),
            diag,
            o,
        );
        self.filter_state(o);
    }
}
