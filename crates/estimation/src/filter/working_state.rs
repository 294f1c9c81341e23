//! The working-state detector of one federated device: decides when a device has failed and
//! when it may rejoin the fusion.
//!
//! A device fails when
//! - no message arrived for `timeout_s` (dead cable, crashed driver),
//! - its output repeats the very same value `stuck_messages` times while the train moves
//!   (a frozen sensor: real noise never repeats exactly),
//! - `gate_failures` of its measurements in a row fail their innovation gate (a bias jump,
//!   a multipath trap),
//! - at a master fusion, its estimate is the one that disagrees most with the fusion of the
//!   other devices, beyond the χ² bound `consistency_chi2` (needs three healthy devices to
//!   say which one is wrong: this is what catches a biased INS, whose own innovations stay
//!   small because it alone observes the acceleration), or
//! - the log holds an explicit fault event naming it (the device reported itself).
//!
//! How a failed device rejoins depends on why it failed:
//! - silent or frozen (timeout, stuck) or recovered after a reported fault: it did not lie,
//!   so it is back after `readmit_after` consecutive live, changing messages — and restarts
//!   cold, with its covariance widened to the disagreement it shows, because the others have
//!   been dead-reckoning meanwhile and may be the ones that drifted;
//! - wrong (gate failures, inconsistent): it must prove itself: its sub-filter keeps running
//!   in the shadow (reset to the fused estimate at each fusion, updated ungated) and it rejoins
//!   after `readmit_after` consecutive master fusions at which it agrees with the fused
//!   estimate;
//! - a reported fault waits for its recovery event, then is on probation like a silent one.
//!
//! A wrong device that is the only one observing a quantity (GNSS, the only absolute
//! position) may never agree again once the others have dead-reckoned past the bound: nothing
//! can say who is right. `max_exclusion_s` then forces a cold restart after that long; it is
//! off by default because a restart while the fault lasts lets the fault back in.

#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "schema", derive(schemars::JsonSchema))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct DetectorSettings {
    pub timeout_s: f64,
    pub stuck_messages: u32,
    pub gate_failures: u32,
    pub readmit_after: u32,
    /// Honour fault/recovery events in the log's `/events` channel.
    pub fault_events: bool,
    /// Bound of the fusion-time consistency test (χ² with the state's dimension, e.g. 21.1
    /// for three states at 99.99 %); 0, the default, turns the test off: a sub-filter's
    /// estimate averages many samples, so an unmodelled systematic error (a radar's 0.3 %
    /// scale factor) makes it fire in normal running unless the bound is set to the data.
    pub consistency_chi2: f64,
    /// Fusions in a row a device must be the one beyond the bound before it is failed: real
    /// sensors carry slow biases their variances do not describe, a real fault persists.
    pub consistency_fusions: u32,
    /// Bound of the agreement test a wrong device passes to rejoin: its shadow estimate
    /// against the fused one, χ² with the state's dimension (16.3: three states at 99.9 %).
    pub agreement_chi2: f64,
    /// Longest exclusion of a device that keeps disagreeing before it is given a cold restart
    /// anyway; 0, the default, never: a restart while the fault lasts lets it back in.
    pub max_exclusion_s: f64,
}

impl Default for DetectorSettings {
    fn default() -> Self {
        Self {
            timeout_s: 2.0,
            stuck_messages: 10,
            gate_failures: 5,
            readmit_after: 5,
            fault_events: true,
            consistency_chi2: 0.0,
            consistency_fusions: 5,
            agreement_chi2: 16.27,
            max_exclusion_s: 0.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    Timeout,
    Stuck,
    GateFailures,
    Inconsistent,
    Reported,
    /// Recovered after a reported fault, waiting for live messages.
    Probation,
}

impl Fault {
    pub fn describe(self) -> &'static str {
        match self {
            Fault::Timeout => "timeout",
            Fault::Stuck => "stuck",
            Fault::GateFailures => "gate_failures",
            Fault::Inconsistent => "inconsistent",
            Fault::Reported => "reported",
            Fault::Probation => "probation",
        }
    }
}

#[derive(Debug, Clone)]
pub struct WorkingState {
    settings: DetectorSettings,
    fault: Option<Fault>,
    last_message_ns: u64,
    /// Last value and its repeat count per measured quantity (chainage, speed, acceleration).
    last_value: [f64; 3],
    repeats: [u32; 3],
    /// Gate failures in a row per quantity (a GNSS fix's chainage can fail while its speed
    /// passes).
    gate_run: [u32; 3],
    good_run: u32,
    inconsistent_run: u32,
    failed_since_ns: u64,
}

impl WorkingState {
    pub fn new(settings: DetectorSettings, start_ns: u64) -> Self {
        Self {
            settings,
            fault: None,
            last_message_ns: start_ns,
            last_value: [f64::NAN; 3],
            repeats: [0; 3],
            gate_run: [0; 3],
            good_run: 0,
            inconsistent_run: 0,
            failed_since_ns: 0,
        }
    }

    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    pub fn healthy(&self) -> bool {
        self.fault.is_none()
    }

    /// True when this call failed the device.
    pub fn check_timeout(&mut self, now_ns: u64) -> bool {
        let silent = now_ns.saturating_sub(self.last_message_ns) as f64 / 1e9;
        if self.fault.is_none() && silent > self.settings.timeout_s {
            self.fail(Fault::Timeout);
            return true;
        }
        false
    }

    /// Records a message; true when it failed the device (stuck).
    pub fn on_message(&mut self, t_ns: u64, quantity: usize, value: f64, moving: bool) -> bool {
        self.last_message_ns = self.last_message_ns.max(t_ns);
        let q = quantity.min(2);
        if value == self.last_value[q] && moving {
            self.repeats[q] += 1;
        } else {
            self.repeats[q] = 0;
        }
        self.last_value[q] = value;
        if self.fault.is_none() && self.repeats[q] + 1 >= self.settings.stuck_messages {
            self.fail(Fault::Stuck);
            return true;
        }
        false
    }

    pub fn is_stuck(&self, quantity: usize) -> bool {
        self.repeats[quantity.min(2)] > 0
    }

    /// Records a gate result of a healthy device; true when it failed the device.
    pub fn on_gate(&mut self, quantity: usize, passed: bool) -> bool {
        let run = &mut self.gate_run[quantity.min(2)];
        *run = if passed { 0 } else { *run + 1 };
        if self.fault.is_none() && *run >= self.settings.gate_failures {
            self.fail(Fault::GateFailures);
            return true;
        }
        false
    }

    /// Marks the device alive at `t_ns` (any message, usable or not).
    pub fn heard(&mut self, t_ns: u64) {
        self.last_message_ns = self.last_message_ns.max(t_ns);
    }

    /// The result of a fusion-time consistency test for this device (true: it was the one in
    /// disagreement beyond the bound); true when that failed the device.
    pub fn on_consistency(&mut self, inconsistent: bool) -> bool {
        self.inconsistent_run = if inconsistent {
            self.inconsistent_run + 1
        } else {
            0
        };
        if self.fault.is_none() && self.inconsistent_run >= self.settings.consistency_fusions.max(1)
        {
            self.fail(Fault::Inconsistent);
            return true;
        }
        false
    }

    /// Records a re-admission test of a failed device; true when it rejoins.
    pub fn on_readmission_test(&mut self, agrees: bool) -> bool {
        if matches!(self.fault, None | Some(Fault::Reported)) {
            return false;
        }
        self.good_run = if agrees { self.good_run + 1 } else { 0 };
        if self.good_run >= self.settings.readmit_after {
            self.fault = None;
            self.gate_run = [0; 3];
            self.inconsistent_run = 0;
            self.repeats = [0; 3];
            return true;
        }
        false
    }

    /// An explicit fault or recovery report; true when the health changed.
    pub fn report(&mut self, failed: bool) -> bool {
        match (failed, self.fault) {
            (true, f) if f != Some(Fault::Reported) => {
                self.fail(Fault::Reported);
                true
            }
            (false, Some(Fault::Reported)) => {
                self.fault = Some(Fault::Probation);
                self.good_run = 0;
                false
            }
            _ => false,
        }
    }

    /// True when the device rejoins by proving agreement at master fusions (it was wrong),
    /// false when live messages suffice (it was silent, frozen or reported).
    pub fn must_prove_agreement(&self) -> bool {
        matches!(self.fault, Some(Fault::GateFailures | Fault::Inconsistent))
    }

    fn fail(&mut self, f: Fault) {
        self.fault = Some(f);
        self.good_run = 0;
        self.failed_since_ns = self.last_message_ns;
    }

    /// A wrong device excluded longer than `max_exclusion_s` goes on probation (cold restart
    /// once it talks); true when that happened.
    pub fn check_exclusion(&mut self, now_ns: u64) -> bool {
        let excluded = now_ns.saturating_sub(self.failed_since_ns) as f64 / 1e9;
        if self.settings.max_exclusion_s > 0.0
            && self.must_prove_agreement()
            && excluded > self.settings.max_exclusion_s
        {
            self.fault = Some(Fault::Probation);
            self.good_run = 0;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeout_stuck_and_gate_runs_fail_a_device_and_agreement_readmits_it() {
        let s = DetectorSettings::default();
        let mut w = WorkingState::new(s, 0);
        assert!(!w.check_timeout(1_900_000_000));
        assert!(w.check_timeout(2_100_000_000));
        assert_eq!(w.fault(), Some(Fault::Timeout));
        assert!(
            !w.must_prove_agreement(),
            "a silent device needs only live messages"
        );
        for k in 0..4 {
            w.on_message(3_000_000_000 + k, 1, k as f64, true);
            assert!(!w.on_readmission_test(true));
        }
        assert!(w.on_readmission_test(true));
        assert!(w.healthy());

        let stuck: Vec<bool> = (0..10)
            .map(|k| w.on_message(4_000_000_000 + k, 1, 42.0, true))
            .collect();
        assert_eq!(stuck.iter().position(|&b| b), Some(9));
        let mut w = WorkingState::new(s, 0);
        assert!(
            !(0..9).any(|k| w.on_message(k, 1, 0.0, false)),
            "a standing train's zeros are not stuck"
        );
        assert!(
            !(0..4).any(|_| w.on_gate(0, false) | w.on_gate(1, true)),
            "failures of one quantity count in a row"
        );
        assert!(w.on_gate(0, false));
        assert!(
            w.must_prove_agreement(),
            "a device that failed its gates must agree again"
        );
        assert!(w.report(true) && w.fault() == Some(Fault::Reported));
        assert!(
            !(0..10).any(|_| w.on_readmission_test(true)),
            "a reported fault waits for its recovery event"
        );
        w.report(false);
        assert!((0..5).any(|_| w.on_readmission_test(true)));
    }
}
