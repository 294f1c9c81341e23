//! The working-state detector of one federated device: decides when a device has failed and
//! when it may rejoin the fusion.
//!
//! A device fails when
//! - no message arrived for `timeout_s` (dead cable, crashed driver),
//! - its output repeats the very same value `stuck_messages` times while the train moves
//!   (a frozen sensor: real noise never repeats exactly),
//! - `gate_failures` of its measurements in a row fail their innovation gate (a bias jump,
//!   a multipath trap), or
//! - the log holds an explicit fault event naming it (the device reported itself).
//!
//! A failed device rejoins after `readmit_after` consecutive measurements that agree with
//! the fused estimate (pass the gate against it) and are not stuck; a reported fault only
//! clears on the matching recovery event.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorSettings {
    pub timeout_s: f64,
    pub stuck_messages: u32,
    pub gate_failures: u32,
    pub readmit_after: u32,
    /// Honour fault/recovery events in the log's `/events` channel.
    pub fault_events: bool,
    /// The gate for re-admission tests when the sensor has none (χ², 1 dof, 99 %).
    pub readmit_gate_nis: f64,
}

impl Default for DetectorSettings {
    fn default() -> Self {
        Self { timeout_s: 2.0, stuck_messages: 10, gate_failures: 5, readmit_after: 5, fault_events: true, readmit_gate_nis: 6.63 }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    Timeout,
    Stuck,
    GateFailures,
    Reported,
}

impl Fault {
    pub fn describe(self) -> &'static str {
        match self {
            Fault::Timeout => "timeout",
            Fault::Stuck => "stuck",
            Fault::GateFailures => "gate_failures",
            Fault::Reported => "reported",
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
    gate_run: u32,
    good_run: u32,
}

impl WorkingState {
    pub fn new(settings: DetectorSettings, start_ns: u64) -> Self {
        Self { settings, fault: None, last_message_ns: start_ns, last_value: [f64::NAN; 3], repeats: [0; 3], gate_run: 0, good_run: 0 }
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
    pub fn on_gate(&mut self, passed: bool) -> bool {
        self.gate_run = if passed { 0 } else { self.gate_run + 1 };
        if self.fault.is_none() && self.gate_run >= self.settings.gate_failures {
            self.fail(Fault::GateFailures);
            return true;
        }
        false
    }

    /// Records a re-admission test of a failed device; true when it rejoins.
    pub fn on_readmission_test(&mut self, agrees: bool) -> bool {
        if self.fault == Some(Fault::Reported) || self.fault.is_none() {
            return false;
        }
        self.good_run = if agrees { self.good_run + 1 } else { 0 };
        if self.good_run >= self.settings.readmit_after {
            self.fault = None;
            self.gate_run = 0;
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
                // Back on probation, like any other failed device.
                self.fault = Some(Fault::GateFailures);
                self.good_run = 0;
                false
            }
            _ => false,
        }
    }

    pub fn readmit_gate(&self, sensor_gate: Option<f64>) -> f64 {
        sensor_gate.unwrap_or(self.settings.readmit_gate_nis)
    }

    fn fail(&mut self, f: Fault) {
        self.fault = Some(f);
        self.good_run = 0;
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
        for k in 0..4 {
            w.on_message(3_000_000_000 + k, 1, k as f64, true);
            assert!(!w.on_readmission_test(true));
        }
        assert!(w.on_readmission_test(true));
        assert!(w.healthy());

        let stuck: Vec<bool> = (0..10).map(|k| w.on_message(4_000_000_000 + k, 1, 42.0, true)).collect();
        assert_eq!(stuck.iter().position(|&b| b), Some(9));
        let mut w = WorkingState::new(s, 0);
        assert!(!(0..9).any(|k| w.on_message(k, 1, 0.0, false)), "a standing train's zeros are not stuck");
        assert!(!(0..4).any(|_| w.on_gate(false)));
        assert!(w.on_gate(false));
        assert!(w.report(true) && w.fault() == Some(Fault::Reported));
        assert!(!(0..10).any(|_| w.on_readmission_test(true)), "a reported fault waits for its recovery event");
        w.report(false);
        assert!((0..5).any(|_| w.on_readmission_test(true)));
    }
}
