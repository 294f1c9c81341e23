//! S7: the summary of a safety pipeline's epochs, as a fault tree wants it. For each basic
//! event (each check: a sensor fault, a divergence test, the map deviation, the odometry
//! mismatch) how often and for how long it fired, and how often it was the first to fail;
//! availability (the share of epochs with a usable position); containment (the share of
//! usable epochs whose U_safe holds the reference, counted by the evaluation's
//! [`AccuracyMeter`](crate::accuracy::AccuracyMeter)); and for each injected fault (a
//! `fault …` window of the log's events) whether and how fast it was flagged.
//!
//! Memory is a few counters per check and per fault window, whatever the log's length.

use std::collections::{BTreeMap, BTreeSet};

use railfuse_catalog::messages::SafetyStatus;
use serde::Serialize;

use crate::accuracy::{Containment, Span};

/// One check's record over the run.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct CheckEval {
    pub check: String,
    /// Epochs in which it failed.
    pub failed_epochs: u64,
    /// Epochs in which it was the first check to fail (the epoch's reason).
    pub first_failure_epochs: u64,
    /// Separate stretches of failure, and their time in all (s): from the first failing
    /// epoch of a stretch to the next epoch where it passed.
    pub episodes: u64,
    pub failed_s: f64,
    /// Epochs in which it passed in a degraded mode (something left out).
    pub degraded_epochs: u64,
}

/// An injected fault and whether the safety checks caught it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FaultEval {
    pub label: String,
    pub start_s: f64,
    /// An epoch after the fault began was unusable, or usable only in a degraded mode that
    /// names what it left out (a wide interval names no fault), before the fault ended.
    pub flagged: bool,
    /// From the fault's start to the first such epoch (s).
    pub delay_s: Option<f64>,
    /// The check that failed first there (or passed degraded).
    pub by: Option<String>,
    /// Every check that failed, or passed only by leaving an input out, while it lasted.
    pub checks: Vec<String>,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SafetyEval {
    pub epochs: u64,
    pub usable_epochs: u64,
    /// Usable epochs in which some check passed only in a degraded mode.
    pub degraded_epochs: u64,
    /// Usable epochs over all epochs.
    pub availability: f64,
    pub containment: Containment,
    /// Contained over checked intervals.
    pub containment_share: Option<f64>,
    pub checks: Vec<CheckEval>,
    pub faults: Vec<FaultEval>,
}

#[derive(Debug, Clone, Default)]
struct Tally {
    eval: CheckEval,
    /// The stamp of the first failing epoch of the stretch now open.
    failing_since_ns: Option<u64>,
}

/// How many changes of usability [`SafetyTally`] keeps to judge late-read fault windows by.
const TRANSITIONS_KEPT: usize = 256;

/// Accumulates a safety channel's statuses.
#[derive(Debug, Clone, Default)]
pub struct SafetyTally {
    epochs: u64,
    usable: u64,
    degraded: u64,
    checks: BTreeMap<String, Tally>,
    /// Per fault window (label, start): the first unusable epoch at or after its start, and
    /// every check that flagged it while it lasted.
    faults: Vec<(Span, Option<(u64, String)>, BTreeSet<String>)>,
    /// The latest changes between usable and not (stamp, usable, first failure), so that a
    /// fault window whose event is read after the statuses of its first moments is judged
    /// on them; at most [`TRANSITIONS_KEPT`].
    transitions: std::collections::VecDeque<(u64, bool, Option<String>)>,
    first_ns: Option<u64>,
    last_ns: u64,
}

impl SafetyTally {
    /// One epoch's status; `spans` are the log's marked windows so far.
    pub fn add(&mut self, s: &SafetyStatus, spans: &[Span]) {
        self.epochs += 1;
        self.usable += u64::from(s.usable);
        self.first_ns.get_or_insert(s.stamp_ns);
        self.last_ns = self.last_ns.max(s.stamp_ns);
        let degraded = s.checks.iter().find(|c| c.degraded.is_some());
        self.degraded += u64::from(s.usable && degraded.is_some());
        for c in &s.checks {
            let t = self.checks.entry(c.check.clone()).or_default();
            t.eval.check.clone_from(&c.check);
            t.eval.degraded_epochs += u64::from(c.degraded.is_some());
            match (c.passed, t.failing_since_ns) {
                (false, None) => {
                    t.failing_since_ns = Some(s.stamp_ns);
                    t.eval.episodes += 1;
                    t.eval.failed_epochs += 1;
                }
                (false, Some(_)) => t.eval.failed_epochs += 1,
                (true, Some(since)) => {
                    t.eval.failed_s += seconds(since, s.stamp_ns);
                    t.failing_since_ns = None;
                }
                (true, None) => {}
            }
        }
        if let Some(first) = &s.first_failure {
            if let Some(t) = self.checks.get_mut(first) {
                t.eval.first_failure_epochs += 1;
            }
        }
        if self.transitions.back().is_none_or(|t| t.1 != s.usable) {
            self.transitions
                .push_back((s.stamp_ns, s.usable, s.first_failure.clone()));
            if self.transitions.len() > TRANSITIONS_KEPT {
                self.transitions.pop_front();
            }
        }
        for span in spans.iter().filter(|w| w.label.starts_with("fault ")) {
            if !self
                .faults
                .iter()
                .any(|(f, ..)| f.label == span.label && f.start_ns == span.start_ns)
            {
                let caught = self.caught_so_far(span);
                let flagged_by = caught.iter().map(|c| c.1.clone()).collect();
                self.faults.push((span.clone(), caught, flagged_by));
            }
        }
        for (span, caught, flagged_by) in &mut self.faults {
            if let Some(end) = span.end_ns.or_else(|| {
                spans
                    .iter()
                    .find(|w| w.label == span.label && w.start_ns == span.start_ns)
                    .and_then(|w| w.end_ns)
            }) {
                span.end_ns = Some(end);
            }
            let by = match s.usable {
                false => Some(s.first_failure.clone().unwrap_or_default()),
                true => s
                    .checks
                    .iter()
                    .find(|c| c.left_out())
                    .map(|c| format!("{} (degraded)", c.check)),
            };
            if span.contains(s.stamp_ns) {
                flagged_by.extend(
                    s.checks
                        .iter()
                        .filter(|c| !c.passed || c.left_out())
                        .map(|c| c.check.clone()),
                );
                if let (None, Some(by)) = (&caught, by) {
                    *caught = Some((s.stamp_ns, by));
                }
            }
        }
    }

    /// For a fault window first seen now: the first unusable moment at or after its start
    /// among the statuses already taken (unusable at its start counts from its start).
    fn caught_so_far(&self, span: &Span) -> Option<(u64, String)> {
        let before = self.transitions.iter().rev().find(|t| t.0 <= span.start_ns);
        if let Some((_, false, why)) = before {
            return Some((span.start_ns, why.clone().unwrap_or_default()));
        }
        self.transitions
            .iter()
            .find(|t| !t.1 && t.0 >= span.start_ns && span.end_ns.is_none_or(|e| t.0 < e))
            .map(|t| (t.0, t.2.clone().unwrap_or_default()))
    }

    /// The summary; `containment` is what the evaluation counted, `t0_ns` where the run's
    /// seconds count from.
    pub fn finish(mut self, containment: Containment, t0_ns: u64) -> SafetyEval {
        for t in self.checks.values_mut() {
            if let Some(since) = t.failing_since_ns.take() {
                t.eval.failed_s += seconds(since, self.last_ns);
            }
        }
        SafetyEval {
            epochs: self.epochs,
            usable_epochs: self.usable,
            degraded_epochs: self.degraded,
            availability: self.usable as f64 / self.epochs.max(1) as f64,
            containment,
            containment_share: (containment.checked > 0)
                .then(|| containment.contained as f64 / containment.checked as f64),
            checks: self.checks.into_values().map(|t| t.eval).collect(),
            faults: self
                .faults
                .into_iter()
                .map(|(span, caught, flagged_by)| FaultEval {
                    start_s: seconds(t0_ns, span.start_ns),
                    flagged: caught.is_some(),
                    delay_s: caught.as_ref().map(|(t, _)| seconds(span.start_ns, *t)),
                    by: caught.map(|(_, c)| c),
                    checks: flagged_by.into_iter().collect(),
                    label: span.label,
                })
                .collect(),
        }
    }
}

fn seconds(a_ns: u64, b_ns: u64) -> f64 {
    railfuse_catalog::seconds_between(a_ns, b_ns).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::messages::SafetyCheck;

    fn status(t_s: u64, failing: &[&str]) -> SafetyStatus {
        let checks: Vec<SafetyCheck> = ["s1_gnss", "s3a_variance"]
            .iter()
            .map(|c| SafetyCheck {
                check: (*c).into(),
                passed: !failing.contains(c),
                value: None,
                limit: None,
                reason: None,
                degraded: None,
            })
            .collect();
        SafetyStatus {
            stamp_ns: t_s * 1_000_000_000,
            usable: failing.is_empty(),
            first_failure: failing.first().map(|c| (*c).to_owned()),
            reason: None,
            checks,
            safe_interval: None,
        }
    }

    #[test]
    fn episodes_durations_availability_and_a_caught_fault_are_counted() {
        let fault = Span {
            label: "fault gnss: bias 20".into(),
            start_ns: 2_000_000_000,
            end_ns: Some(6_000_000_000),
        };
        let mut t = SafetyTally::default();
        let plan: [&[&str]; 8] = [
            &[],
            &[],
            &[],
            &["s3a_variance"],
            &["s3a_variance", "s1_gnss"],
            &[],
            &["s1_gnss"],
            &[],
        ];
        for (k, failing) in plan.iter().enumerate() {
            t.add(&status(k as u64, failing), std::slice::from_ref(&fault));
        }
        let e = t.finish(Containment::default(), 0);
        assert_eq!((e.epochs, e.usable_epochs), (8, 5));
        let s3a = e.checks.iter().find(|c| c.check == "s3a_variance").unwrap();
        assert_eq!(
            (s3a.failed_epochs, s3a.episodes, s3a.first_failure_epochs),
            (2, 1, 2)
        );
        assert_eq!(s3a.failed_s, 2.0);
        let gnss = e.checks.iter().find(|c| c.check == "s1_gnss").unwrap();
        assert_eq!(
            (gnss.failed_epochs, gnss.episodes, gnss.first_failure_epochs),
            (2, 2, 1)
        );
        assert_eq!(gnss.failed_s, 2.0);
        assert_eq!(e.faults.len(), 1);
        assert!(e.faults[0].flagged);
        assert_eq!(e.faults[0].delay_s, Some(1.0));
        assert_eq!(e.faults[0].by.as_deref(), Some("s3a_variance"));

        // The same with the fault's event read only after the statuses: the same verdict.
        let mut late = SafetyTally::default();
        for (k, failing) in plan.iter().enumerate() {
            let spans: &[Span] = if k < 6 {
                &[]
            } else {
                std::slice::from_ref(&fault)
            };
            late.add(&status(k as u64, failing), spans);
        }
        let f = &late.finish(Containment::default(), 0).faults[0];
        assert_eq!(
            (f.flagged, f.delay_s, f.by.as_deref()),
            (true, Some(1.0), Some("s3a_variance"))
        );
    }
}
