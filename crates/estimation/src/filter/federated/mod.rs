//! The federated filter (Carlson): one local filter per device, a master that fuses them by
//! information weighting, and feedback that shares the fused information back.
//!
//! ```text
//! P_g = (Σ P_i⁻¹)⁻¹,      x_g = P_g Σ P_i⁻¹ x_i                       (master fusion)
//! x_i := x_g,   P_i := P_g / β_i,   Q_i := Q / β_i,   Σ β_i = 1        (fusion-reset feedback)
//! ```
//!
//! With fusion-reset feedback, information sharing of both `P` and `Q`, and a fusion after
//! every update, the federated Kalman filter is algebraically the centralised Kalman filter
//! (each sub-filter starts every cycle with the share `β_i P_g⁻¹` of the common information, so
//! the shares sum back to it). Without reset the sub-filters run on their own and the master
//! fusion counts the common process noise once per device: cheaper to keep apart (a failed
//! device never contaminates the others) but no longer optimal.
//!
//! So the information-sharing coefficients β (source 000's α) change the fused estimate only
//! where the sub-filters run on their shares between master fusions: fusion-reset feedback
//! with a fusion period longer than the updates (1 s in sources 000 and 001). With a fusion
//! after every update they cannot change it (it is the centralised filter whatever β is), and
//! without reset they are not used (each sub-filter keeps its full information). Tested:
//! `information_sharing_changes_the_estimate_only_between_fusions_of_a_reset_filter`.
//!
//! The sources mean their coefficients as weights: source 000's α says the loop is the better
//! sensor at low speed, source 001's β that the INS is trusted most. [`Fusion::Shares`] does
//! that: the master takes `x_g = Σ β_i x_i`, `P_g = Σ β_i P_i` (β renormalised over the
//! healthy devices), which bounds the error covariance whatever the correlation between the
//! local errors, and resets each sub-filter to `(x_g, P_g)` itself. Then β changes the fused
//! estimate in every mode (tested:
//! `weighting_by_shares_makes_beta_change_every_fused_estimate`), at the price of
//! optimality: a sub-filter that sees a state component poorly still gets its β of it.
//!
//! Source 001's INS and radar sub-filters take their devices' navigation solutions (the
//! strapdown INS's position and speed, the radar's integrated position), compensated with the
//! fed-back fused state at each fusion. railfuse's take the raw samples (acceleration, speed)
//! and are reset to the fused state instead, which is the same thing here: started from the
//! same reset, a sub-filter on raw samples carries its device's navigation solution to the
//! next fusion, smoothed by its model. On seed001's settings (IMU 100 Hz σ 0.03 m/s², radar
//! 50 Hz σ 0.1 m/s, fusion every 1 s) the INS sub-filter ends each cycle within 0.1 mm and
//! 1.8 mm/s of the strapdown solution (which is itself within 4.1 mm of the truth), the radar
//! sub-filter within 1.1 cm of the dead-reckoned position (itself within 4.6 cm); tested:
//! `between_fusions_a_sub_filter_on_raw_samples_carries_its_devices_navigation_solution`. What
//! differs is the covariance: here it follows from the sensors' noise, where the source's form
//! needs a variance chosen for a solution whose errors are correlated in time.
//!
//! Local filters are Kalman filters (source 001) or particle filters (source 000); a particle
//! sub-filter is reset by redrawing its cloud from `N(x_g, P_g/β_i)`. β comes from a
//! [`SharingTable`] by speed band; a [`WorkingState`] detector per device takes a failed
//! device out (β = 0, its share redistributed) and lets it back in when it agrees with the
//! fused estimate again. With every device failed the master coasts: the last fused estimate
//! is propagated with the motion model, `x(k) = Φ(k, j) x_g(j)`.

use nalgebra::{SMatrix, SVector};

use super::sharing::{Redistribution, SharingTable};
use super::working_state::{DetectorSettings, WorkingState};
use super::{
    fix_reset, DeviceShare, Estimator, EstimatorDiagnostics, Innovation, KalmanFilter, LocalFilter,
    Outcome, ScalarMeasurement, StateAndCovariance, MASTER,
};
use crate::model::TransitionModel;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Feedback {
    NoReset,
    FusionReset,
}

/// How the master combines the local estimates (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Fusion {
    /// Information weighting, `P_g = (Σ P_i⁻¹)⁻¹`; β is the share of the fused information
    /// each sub-filter is reset with (Carlson).
    #[default]
    Information,
    /// β as the weight of each local estimate, `x_g = Σ β_i x_i`, `P_g = Σ β_i P_i` (a bound
    /// that holds whatever the correlation between the local errors); the sub-filters are
    /// reset to `(x_g, P_g)` itself.
    Shares,
}

impl Fusion {
    /// The information share a sub-filter with weight `b` is reset with: `b` under
    /// information fusion, all of it (1) when β weights the estimates instead.
    fn reset_share(self, b: f64) -> f64 {
        match self {
            Fusion::Information => b,
            Fusion::Shares => 1.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct FederatedSettings {
    pub feedback: Feedback,
    pub fusion: Fusion,
    /// Master fusion period; 0 fuses after every accepted measurement.
    pub fusion_period_ns: u64,
    pub sharing: SharingTable,
    pub redistribution: Redistribution,
    pub detector: DetectorSettings,
}

struct Device<const N: usize, F> {
    name: String,
    filter: F,
    health: WorkingState,
    /// Master fusions left during which a cold-restarted device is spared the consistency
    /// test, so that it can pull back an estimate the others let drift.
    grace: u32,
    /// While failed: the squared disagreement with the fused estimate per state component
    /// (how far a cold restart must widen its covariance).
    disagreement: SVector<f64, N>,
}

pub struct Federated<const N: usize, F: LocalFilter<N>> {
    settings: FederatedSettings,
    model: Box<dyn TransitionModel<N>>,
    devices: Vec<Device<N, F>>,
    /// The last fused estimate, propagated with the model (what the master coasts on).
    master: KalmanFilter<N>,
    beta: Vec<f64>,
    time_ns: u64,
    next_fusion_ns: u64,
}

impl<const N: usize, F: LocalFilter<N>> Federated<N, F> {
    /// `make(i, β_i)` builds device i's local filter; each starts from `initial` with its share
    /// `P(0)/β_i` under fusion-reset, or from `initial` itself without reset.
    pub fn new(
        settings: FederatedSettings,
        model: Box<dyn TransitionModel<N>>,
        names: Vec<String>,
        initial: &StateAndCovariance<N>,
        time_ns: u64,
        mut make: impl FnMut(usize, &StateAndCovariance<N>) -> F,
    ) -> Self {
        let beta = settings.sharing.shares(
            initial.state[1.min(N - 1)],
            &vec![true; names.len()],
            settings.redistribution,
        );
        let devices = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                let share = share_of(
                    initial,
                    settings.fusion.reset_share(beta[i]),
                    settings.feedback,
                );
                Device {
                    name,
                    filter: make(i, &share),
                    health: WorkingState::new(settings.detector, time_ns),
                    grace: 0,
                    disagreement: SVector::zeros(),
                }
            })
            .collect();
        let next_fusion_ns = time_ns + settings.fusion_period_ns;
        Self {
            master: KalmanFilter::new(initial.state, initial.covariance),
            settings,
            model,
            devices,
            beta,
            time_ns,
            next_fusion_ns,
        }
    }

    fn healthy(&self) -> Vec<bool> {
        self.devices.iter().map(|d| d.health.healthy()).collect()
    }

    fn speed(&self) -> f64 {
        self.master.estimate.state[1.min(N - 1)]
    }

    /// Information fusion of the healthy devices; None when none is healthy or the
    /// information is singular. The states are fused as offsets from the master's own
    /// (propagated) state, `x_g = x_m + P_g Σ P_i⁻¹ (x_i − x_m)`: the same estimate, but
    /// without multiplying kilometres of chainage by a precise sub-filter's large information
    /// and cancelling them again.
    fn fuse(&self) -> Option<StateAndCovariance<N>> {
        if self.settings.fusion == Fusion::Shares {
            return self.fuse_by_shares();
        }
        let origin = self.master.estimate.state;
        let mut info = SMatrix::<f64, N, N>::zeros();
        let mut info_state = SVector::<f64, N>::zeros();
        let mut any = false;
        for (d, &b) in self.devices.iter().zip(&self.beta) {
            if !d.health.healthy() || (self.settings.feedback == Feedback::FusionReset && b <= 0.0)
            {
                continue;
            }
            let e = d.filter.estimate();
            let Some(inv) = inverse_spd(&e.covariance) else {
                continue;
            };
            info += inv;
            info_state += inv * (e.state - origin);
            any = true;
        }
        let p = inverse_spd(&info).filter(|_| any)?;
        let fused = StateAndCovariance {
            state: origin + p * info_state,
            covariance: super::symmetric(p),
        };
        fused.is_finite().then_some(fused)
    }

    /// The healthy devices' estimates weighted by their β (renormalised over them):
    /// `x_g = Σ β_i x_i`, `P_g = Σ β_i P_i`. Since `(Σ β_i e_i)(Σ β_i e_i)ᵀ ≤ Σ β_i e_i e_iᵀ` for
    /// weights summing to one, `P_g` bounds the error covariance however the local errors
    /// are correlated (they are: every sub-filter starts each cycle from the same reset).
    fn fuse_by_shares(&self) -> Option<StateAndCovariance<N>> {
        let mut state = SVector::<f64, N>::zeros();
        let mut covariance = SMatrix::<f64, N, N>::zeros();
        let mut total = 0.0;
        for (d, &b) in self.devices.iter().zip(&self.beta) {
            if !d.health.healthy() || b <= 0.0 {
                continue;
            }
            let e = d.filter.estimate();
            state += e.state * b;
            covariance += e.covariance * b;
            total += b;
        }
        if total <= 0.0 {
            return None;
        }
        let fused = StateAndCovariance {
            state: state / total,
            covariance: super::symmetric(covariance / total),
        };
        fused.is_finite().then_some(fused)
    }

    /// The consistency test at a master fusion: with three or more healthy devices, the one
    /// whose estimate differs most from the information fusion of the others,
    /// `d = x_i − x_{−i}`, `d' (P_i + P_{−i})⁻¹ d`, is failed when that exceeds the bound.
    /// (Sub-filters share the last reset, so `P_i + P_{−i}` overstates the difference's
    /// covariance: the test is conservative.)
    fn consistency_test(&mut self) -> bool {
        let bound = self.settings.detector.consistency_chi2;
        let healthy: Vec<usize> = (0..self.devices.len())
            .filter(|&i| self.devices[i].health.healthy() && self.devices[i].grace == 0)
            .collect();
        if bound <= 0.0 || healthy.len() < 3 {
            return false;
        }
        let estimates: Vec<StateAndCovariance<N>> = healthy
            .iter()
            .map(|&i| self.devices[i].filter.estimate())
            .collect();
        let infos: Vec<Option<SMatrix<f64, N, N>>> = estimates
            .iter()
            .map(|e| inverse_spd(&e.covariance))
            .collect();
        let mut worst: Option<(usize, f64)> = None;
        for (k, &i) in healthy.iter().enumerate() {
            let mut info = SMatrix::<f64, N, N>::zeros();
            let mut info_state = SVector::<f64, N>::zeros();
            for (j, (e, inv)) in estimates.iter().zip(&infos).enumerate() {
                if let (true, Some(inv)) = (j != k, inv) {
                    info += inv;
                    info_state += inv * e.state;
                }
            }
            let Some(p_others) = inverse_spd(&info) else {
                continue;
            };
            let d = estimates[k].state - p_others * info_state;
            let Some(s_inv) = inverse_spd(&(estimates[k].covariance + p_others)) else {
                continue;
            };
            let stat = (d.transpose() * s_inv * d)[0];
            if stat.is_finite() && worst.is_none_or(|(_, w)| stat > w) {
                worst = Some((i, stat));
            }
        }
        let culprit = worst.filter(|&(_, stat)| stat > bound).map(|(i, _)| i);
        let mut failed = false;
        for &i in &healthy {
            failed |= self.devices[i].health.on_consistency(culprit == Some(i));
        }
        failed
    }

    /// Master fusion, then (under fusion-reset) feedback with β for the current speed. Also
    /// where wrong devices are caught (consistency test) and where they prove themselves
    /// again (their shadow sub-filters against the fused estimate).
    fn fuse_and_feed_back(&mut self) {
        let fusion = self.settings.fusion;
        self.consistency_test();
        if let Some(fused) = self.fuse() {
            self.master.estimate = fused;
        }
        let bound = self.settings.detector.agreement_chi2;
        let master = self.master.estimate.clone();
        for d in &mut self.devices {
            d.health.check_exclusion(self.time_ns);
        }
        for d in self
            .devices
            .iter_mut()
            .filter(|d| d.health.must_prove_agreement())
        {
            let e = d.filter.estimate();
            let agrees = match inverse_spd(&(e.covariance + master.covariance)) {
                Some(s_inv) => {
                    let diff = e.state - master.state;
                    (diff.transpose() * s_inv * diff)[0] <= bound
                }
                None => false,
            };
            // Rejoining after agreeing: the reset below brings it in with its share.
            d.health.on_readmission_test(agrees);
        }
        self.beta = self.settings.sharing.shares(
            self.speed(),
            &self.healthy(),
            self.settings.redistribution,
        );
        let nominal = self.settings.sharing.at(self.speed()).to_vec();
        for ((d, &b), &b0) in self.devices.iter_mut().zip(&self.beta).zip(&nominal) {
            d.grace = d.grace.saturating_sub(1);
            if self.settings.feedback == Feedback::FusionReset && b > 0.0 {
                let mut share = share_of(
                    &self.master.estimate,
                    fusion.reset_share(b),
                    Feedback::FusionReset,
                );
                if d.grace > 0 {
                    // Still re-converging after a cold restart: keep the covariance wide by
                    // what the device still disagrees, so the reset does not undo the restart.
                    for k in 0..N {
                        share.covariance[(k, k)] += d.disagreement[k];
                    }
                } else {
                    d.disagreement = SVector::zeros();
                }
                d.filter.reset(&share);
            } else if d.health.must_prove_agreement() {
                // The shadow restarts from the fused estimate each cycle, so that what it shows
                // at the next fusion is its disagreement over one cycle only.
                d.filter.reset(&share_of(
                    &self.master.estimate,
                    fusion.reset_share(if b0 > 0.0 { b0 } else { 1.0 }),
                    Feedback::FusionReset,
                ));
            }
        }
    }

    fn predict_all(&mut self, t_ns: u64) {
        if t_ns <= self.time_ns {
            return;
        }
        let dt = (t_ns - self.time_ns) as f64 / 1e9;
        let fusion = self.settings.fusion;
        for (d, &b) in self.devices.iter_mut().zip(&self.beta) {
            let q_scale = if self.settings.feedback == Feedback::FusionReset && b > 0.0 {
                1.0 / fusion.reset_share(b)
            } else {
                1.0
            };
            d.filter.predict(self.model.as_ref(), dt, q_scale);
        }
        self.master.predict(self.model.as_ref(), dt);
        self.time_ns = t_ns;
    }

    /// A device's health changed: new shares now. A device back from silence restarts cold:
    /// from the fused estimate with its covariance widened by the disagreement it showed.
    fn health_changed(&mut self, rejoined: Option<usize>) {
        if let Some(fused) = self.fuse() {
            self.master.estimate = fused;
        }
        self.beta = self.settings.sharing.shares(
            self.speed(),
            &self.healthy(),
            self.settings.redistribution,
        );
        if let Some(i) = rejoined {
            let b = self.beta[i];
            let mut share = share_of(
                &self.master.estimate,
                self.settings
                    .fusion
                    .reset_share(if b > 0.0 { b } else { 1.0 }),
                self.settings.feedback,
            );
            let d = &mut self.devices[i];
            for k in 0..N {
                share.covariance[(k, k)] += d.disagreement[k];
            }
            d.filter.reset(&share);
            d.grace = 2 * self.settings.detector.consistency_fusions;
        }
    }
}

fn share_of<const N: usize>(
    e: &StateAndCovariance<N>,
    beta: f64,
    feedback: Feedback,
) -> StateAndCovariance<N> {
    match feedback {
        Feedback::FusionReset => StateAndCovariance {
            state: e.state,
            covariance: e.covariance / beta,
        },
        Feedback::NoReset => e.clone(),
    }
}

fn inverse_spd<const N: usize>(p: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    p.cholesky().map(|c| c.inverse())
}

impl<const N: usize, F: LocalFilter<N>> Federated<N, F> {
    /// A measurement of the master (an absolute fix): gated and updated against the fused
    /// estimate, then shared back to every sub-filter with a share β > 0 at once, whatever the
    /// feedback mode; otherwise the next fusion would forget it.
    fn process_master(&mut self, m: &ScalarMeasurement<N>, z: f64) -> Outcome {
        let mut master = KalmanFilter {
            estimate: self.estimate(),
        };
        let innovation = master.innovation(&m.h, m.r, z);
        if !innovation.passes(m.gate_nis) {
            return Outcome::RejectedGate(innovation);
        }
        if !LocalFilter::update(&mut master, &m.h, m.r, z) {
            return Outcome::RejectedNumerics(innovation);
        }
        self.master = master;
        self.share_master();
        Outcome::Accepted(innovation)
    }

    /// The master's estimate shared back to every sub-filter with a share β > 0 at once,
    /// whatever the feedback mode (an absolute fix the next fusion must not forget).
    fn share_master(&mut self) {
        self.beta = self.settings.sharing.shares(
            self.speed(),
            &self.healthy(),
            self.settings.redistribution,
        );
        let fusion = self.settings.fusion;
        for (d, &b) in self.devices.iter_mut().zip(&self.beta) {
            if b > 0.0 {
                d.filter.reset(&share_of(
                    &self.master.estimate,
                    fusion.reset_share(b),
                    self.settings.feedback,
                ));
            }
        }
    }

    /// A measurement of a device out of the fusion: it either updates the device's own
    /// sub-filter ungated (a shadow update: the next fusion sees where the device pulls), or
    /// its disagreement with the fused estimate is the readmission test's evidence.
    fn process_unhealthy(&mut self, m: &ScalarMeasurement<N>, z: f64) -> Outcome {
        let (i, quantity) = (m.device, m.quantity);
        let fused = KalmanFilter {
            estimate: self.estimate(),
        };
        let innovation = fused.innovation(&m.h, m.r, z);
        let d = &mut self.devices[i];
        if d.health.must_prove_agreement() {
            // Shadow update, ungated: the next fusion sees where the device pulls.
            d.filter.update(&m.h, m.r, z);
        } else {
            d.disagreement[quantity] = innovation.residual * innovation.residual;
            if d.health.on_readmission_test(!d.health.is_stuck(quantity)) {
                self.health_changed(Some(i));
            }
        }
        Outcome::RejectedDeviceFault(Some(innovation))
    }
}

impl<const N: usize, F: LocalFilter<N>> Estimator<N> for Federated<N, F> {
    fn advance_to(&mut self, t_ns: u64) {
        if self.settings.fusion_period_ns > 0 {
            while self.next_fusion_ns <= t_ns {
                self.predict_all(self.next_fusion_ns);
                self.fuse_and_feed_back();
                self.next_fusion_ns += self.settings.fusion_period_ns;
            }
        }
        self.predict_all(t_ns);
        let mut changed = false;
        for d in &mut self.devices {
            changed |= d.health.check_timeout(t_ns);
        }
        if changed {
            self.health_changed(None);
        }
    }

    fn process(&mut self, m: &ScalarMeasurement<N>) -> Outcome {
        let z = m.z - m.offset;
        if m.device == MASTER {
            return self.process_master(m, z);
        }
        let moving = self.speed().abs() > 1.0;
        let quantity = m.quantity;
        let i = m.device;
        if self.devices[i]
            .health
            .on_message(self.time_ns, quantity, m.z, moving)
        {
            self.health_changed(None);
            return Outcome::RejectedDeviceFault(None);
        }
        if !self.devices[i].health.healthy() {
            return self.process_unhealthy(m, z);
        }
        if self.devices[i].grace > 0 {
            // How far the fused estimate still is from this device (not its own sub-filter,
            // which follows the device): what the next reset must leave room for.
            let fused = KalmanFilter {
                estimate: self.estimate(),
            };
            let nu = fused.innovation(&m.h, m.r, z).residual;
            self.devices[i].disagreement[quantity] = (nu * nu - m.r).max(0.0);
        }
        let d = &mut self.devices[i];
        let innovation = d.filter.innovation(&m.h, m.r, z);
        let passed = innovation.passes(m.gate_nis);
        let failed_now = d.health.on_gate(quantity, passed);
        let outcome = if !passed {
            Outcome::RejectedGate(innovation)
        } else if d.filter.update(&m.h, m.r, z) {
            Outcome::Accepted(innovation)
        } else {
            Outcome::RejectedNumerics(innovation)
        };
        if failed_now {
            self.health_changed(None);
        } else if self.settings.fusion_period_ns == 0 && matches!(outcome, Outcome::Accepted(_)) {
            self.fuse_and_feed_back();
        }
        outcome
    }

    fn estimate(&self) -> StateAndCovariance<N> {
        self.fuse().unwrap_or_else(|| self.master.estimate.clone())
    }

    /// Against the fused estimate for the master's fixes and a failed device's measurements;
    /// against its sub-filter for a healthy device's.
    fn innovation(&self, m: &ScalarMeasurement<N>) -> Innovation {
        let z = m.z - m.offset;
        match self.devices.get(m.device) {
            Some(d) if d.health.healthy() => d.filter.innovation(&m.h, m.r, z),
            _ => KalmanFilter {
                estimate: self.estimate(),
            }
            .innovation(&m.h, m.r, z),
        }
    }

    /// The fused estimate reset to the fix, and shared to every sub-filter: an absolute fix
    /// is the truth of the train's position, not one device's view of it.
    fn reset_to_fix(&mut self, m: &ScalarMeasurement<N>) -> Outcome {
        let fused = KalmanFilter {
            estimate: self.estimate(),
        };
        let innovation = fused.innovation(&m.h, m.r, m.z - m.offset);
        let Some(after) = fix_reset(&fused.estimate, m) else {
            return Outcome::RejectedNumerics(innovation);
        };
        self.master.estimate = after;
        self.share_master();
        Outcome::Reset(innovation)
    }

    fn linearisation_point(&self, device: usize) -> SVector<f64, N> {
        match self.devices.get(device) {
            // A healthy device updates its own sub-filter; it is also far cheaper than a fusion.
            Some(d) if d.health.healthy() => d.filter.estimate().state,
            _ => self.estimate().state,
        }
    }

    fn diagnostics(&self) -> EstimatorDiagnostics {
        let mut out = EstimatorDiagnostics::default();
        // Particle sub-filters: the smallest effective sample size among them.
        for d in &self.devices {
            let mut dd = EstimatorDiagnostics::default();
            d.filter.diagnostics(&mut dd);
            if let Some(ess) = dd.effective_sample_size {
                out.effective_sample_size =
                    Some(out.effective_sample_size.map_or(ess, |e: f64| e.min(ess)));
                out.resampled =
                    Some(out.resampled.unwrap_or(false) | dd.resampled.unwrap_or(false));
            }
        }
        out.sharing = Some(
            self.devices
                .iter()
                .zip(&self.beta)
                .map(|(d, &b)| DeviceShare {
                    device: d.name.clone(),
                    beta: b,
                    fault: d.health.fault().map(|f| f.describe().to_owned()),
                })
                .collect(),
        );
        out
    }

    fn heard_from(&mut self, device: usize, t_ns: u64) {
        if let Some(d) = self.devices.get_mut(device) {
            d.health.heard(t_ns);
        }
    }

    fn device_event(&mut self, device: &str, failed: bool) {
        if !self.settings.detector.fault_events {
            return;
        }
        if let Some(i) = self.devices.iter().position(|d| d.name == device) {
            if self.devices[i].health.report(failed) {
                self.health_changed(None);
            }
        }
    }
}

#[cfg(test)]
mod tests;
