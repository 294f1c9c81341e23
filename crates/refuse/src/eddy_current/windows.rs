//! One correlation window: what the correlator is asked, when the next window comes, and
//! what a measured, standstill or lockless window does to the pipeline (with a start from
//! standstill fitted instead of correlated).

use nalgebra::RowVector3;
use railfuse_catalog::messages::{EddyCurrentDiagnostics, GateDecision, TrackMap};

use crate::fused::Fused;
use departure::{Departure, Fit, Moved};
use front_end::WINDOW;
use speed::{Outcome, Request, SpeedEstimator, SpeedMeasurement};

use super::*;

impl EddyCurrentPipeline {
    /// One correlation window ending at `t`: a measurement, the filter, a state.
    pub(super) fn window(&mut self, t: u64, map: Option<&TrackMap>, o: &mut Vec<Fused>) {
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
        // The wheels' samples up to the time this window measures go first.
        let measures_ns = match &outcome {
            Outcome::Moving(m) => m.stamp_ns,
            Outcome::Standstill { stamp_ns } | Outcome::NoLock { stamp_ns, .. } => *stamp_ns,
        };
        self.drain_aids(measures_ns, o);
        match outcome {
            Outcome::Moving(m) => self.moving(t, m, start, diag, o),
            Outcome::Standstill { stamp_ns } => self.standstill(t, stamp_ns, diag, o),
            Outcome::NoLock { stamp_ns, best_rho } => self.no_lock(t, stamp_ns, best_rho, diag, o),
        }
    }

    /// What the correlator is asked, with the speed the last measurement says now (nothing
    /// when it is too old to go by).
    pub(super) fn request(&self, t: u64) -> (Request, Option<f64>) {
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
    pub(super) fn schedule(
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
    pub(super) fn moving(
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
    pub(super) fn standstill(
        &mut self,
        t: u64,
        stamp_ns: u64,
        mut diag: EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        if self.aiding.turning_at(t) {
            // A wheel turns: the track under the sensors is as quiet as the noise floor (the
            // first centimetres of a start), not the train standing.
            let why = "quiet, but a wheel turns: not a standstill";
            self.record(
                stamp_ns,
                None,
                None,
                None,
                GateDecision::RejectedInvalid,
                Some(why),
                diag,
                o,
            );
            return;
        }
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
    pub(super) fn no_lock(
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
    pub(super) fn departing(&mut self, t: u64, q: &Request) -> Option<(Outcome, Option<Moved>)> {
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
    pub(super) fn started(&mut self, m: &Moved) {
        let from = m.stood_odometer_m + m.start.travelled_m;
        self.odometer_m = self.odometer_m.max(from);
    }

    /// The filter's chainage from where it stood plus what the start covered.
    pub(super) fn start_chainage(&mut self, m: &Moved) {
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
}
