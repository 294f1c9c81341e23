//! The pipeline's constant-acceleration Kalman filter: prediction to a stamp, the speed and
//! sleeper-count updates with their gates, standstill, and the states it writes.

use nalgebra::{RowVector3, Vector3};
use railfuse_catalog::messages::{EddyCurrentDiagnostics, FusedState, GateDecision};

use crate::filter::{Innovation, KalmanFilter};
use crate::fused::Fused;
use speed::SpeedMeasurement;

use super::*;

impl EddyCurrentPipeline {
    /// The filterless state: the held measurement, the count's chainage.
    pub(super) fn state_of_measurement(&mut self, stamp_ns: u64, o: &mut Vec<Fused>) {
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
            chainage_m: self.front_chainage(chainage),
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

    pub(super) fn filter_state(&mut self, o: &mut Vec<Fused>) {
        let Some(kf) = &self.kf else { return };
        let x = kf.estimate.state;
        let p = kf.estimate.covariance;
        let state = FusedState {
            stamp_ns: self.kf_ns,
            chainage_m: self.front_chainage(x[0]),
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
        self.last_state_ns = self.kf_ns;
        push_state(state, o);
    }

    /// The filter to `t`, never backwards; with `count`, fusing the newest sleeper crossing
    /// due by then at its own time (only beside a speed measurement: without one, at a stop
    /// or with no lock, the band-passed signal the crossings come from is not tuned to the
    /// speed, and they are dropped). For a window centred before the filter's time: how much
    /// before (s), so its speed is compared with the state's speed then, `v − a Δ` (constant
    /// acceleration: exact).
    pub(super) fn advance(&mut self, t: u64, count: bool) -> f64 {
        if self.kf.is_none() {
            return 0.0;
        }
        let mut due = None;
        while self.crossings.front().is_some_and(|c| c.0 <= t) {
            due = self.crossings.pop_front();
        }
        if let (Some((tc, counted)), Some(origin), true) = (due, self.count_origin, count) {
            match tc > self.kf_ns {
                true => {
                    self.predict_to(tc);
                    self.fuse_count(origin + counted, 0.0);
                }
                // The filter is ahead of the crossing (a wheel took it there): the chainage
                // then, `s − v Δ + a Δ² / 2`.
                false if !self.aiding.aids.is_empty() => {
                    self.fuse_count(origin + counted, (self.kf_ns - tc) as f64 / 1e9)
                }
                false => {}
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
    pub(super) fn predict_to(&mut self, t: u64) {
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

    pub(super) fn filter_moving(
        &mut self,
        m: &SpeedMeasurement,
        diag: &mut EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
        let r_v = m.speed_variance + self.settings.speed_noise_floor_mps.powi(2);
        if self.kf.is_none() {
            self.start_filter(m, r_v, diag, o);
            return;
        }
        if self.aiding.standing_before(m.stamp_ns) {
            // The wheels have seen the stop this window leads up to, and the filter stands.
            let why = "a window of the approach to a stop the wheels have already seen";
            self.counts.rejected_late += 1;
            self.record(
                m.stamp_ns,
                Some(m.speed_mps),
                Some(r_v),
                None,
                GateDecision::RejectedLate,
                Some(why),
                diag.clone(),
                o,
            );
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
            return self.refuse_speed(m, r_v, innovation, diag, o);
        }
        self.gate_refusals = 0;
        self.last_correlation_ns = Some(m.stamp_ns);
        let i = kf.update(&h_v, r_v, m.speed_mps);
        let reason = fuse_acceleration(
            kf,
            m,
            self.settings.acceleration_check_sigma,
            (a_prior, p_aa),
        );
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

    /// A window's speed beyond the gate: refused, and after [`GATE_RESTART`] refusals in a
    /// row the filter started over.
    fn refuse_speed(
        &mut self,
        m: &SpeedMeasurement,
        r_v: f64,
        innovation: Innovation,
        diag: &EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
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
            // The correlator has agreed with itself and not the filter five times: the filter
            // is what diverged.
            self.kf = None;
            self.gate_refusals = 0;
        }
        self.filter_state(o);
    }

    /// The filter started at the first speed measurement: chainage from the sleeper count
    /// where there is one, the warp's acceleration where it gave one.
    fn start_filter(
        &mut self,
        m: &SpeedMeasurement,
        r_v: f64,
        diag: &mut EddyCurrentDiagnostics,
        o: &mut Vec<Fused>,
    ) {
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
    }

    /// The counted distance `s` as a chainage measurement `late_s` before the filter's time.
    pub(super) fn fuse_count(&mut self, s: f64, late_s: f64) {
        if let Some(kf) = self.kf.as_mut() {
            let h = RowVector3::new(1.0, -late_s, late_s * late_s / 2.0);
            if kf.innovation(&h, COUNT_STD_M.powi(2), s).nis <= COUNT_GATE_NIS {
                kf.update(&h, COUNT_STD_M.powi(2), s);
            }
        }
    }

    pub(super) fn filter_standstill(&mut self, t: u64) -> Option<Innovation> {
        self.kf.as_ref()?;
        self.advance(t, false);
        self.zero_velocity()
    }

    /// Zero speed and zero acceleration, at the filter's time: the train stands.
    pub(super) fn zero_velocity(&mut self) -> Option<Innovation> {
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

/// The warp's acceleration fused as a measurement of `a`, unless it lies more than `sigmas`
/// standard deviations from the filter's prior `(a, P_aa)`: then it is left out, and why is
/// returned (a diverged filter or a wrong warp).
fn fuse_acceleration(
    kf: &mut KalmanFilter<3>,
    m: &SpeedMeasurement,
    sigmas: f64,
    (a_prior, p_aa): (f64, f64),
) -> Option<String> {
    let (acc, var) = m.acceleration?;
    let gap = (acc - a_prior).abs();
    let sigma = (var + p_aa).sqrt();
    if gap > sigmas * sigma {
        return Some(format!(
            "warp acceleration {acc:+.2} m/s² and the filter's {a_prior:+.2} m/s² are {:.1} σ apart: divergence or a wrong warp; not fused",
            gap / sigma
        ));
    }
    kf.update(&RowVector3::new(0.0, 0.0, 1.0), var, acc);
    None
}
