//! Source 002's experiment: `samples/seed002.toml` (the source as stated, and with sensor
//! states) over seeds on the `seed002` preset and the default scenario, fault-free and with
//! each injected fault: availability, containment of the truth in U_safe, and whether and how
//! fast each fault was flagged (S7, from the evaluation).

use std::path::Path;

use railfuse_eval::safety::SafetyEval;
use railfuse_record::simulator::FaultSpec;
use railfuse_refuse::config::embedded_path;
use railfuse_refuse::spec::Pipelines;
use serde::Serialize;

use crate::Result;

pub const SEED002_PIPELINES: &str = include_str!("../../../samples/seed002.toml");

/// The pipelines compared: the source as stated, with sensor states, and with sensor states
/// and railfuse's degraded modes.
pub const PIPELINES: [&str; 3] = ["ekf_safety", "ekf_safety_cal", "ekf_safety_degraded"];

/// One case: a scenario and the faults injected into it.
pub struct Case {
    pub scenario: &'static str,
    pub label: &'static str,
    pub faults: &'static [&'static str],
}

/// The cases: each preset fault-free, then source 002's faults on its line (a GNSS position
/// jump, a stuck axle, an axle slipping far beyond spec, map offsets of 1 to 10 m), each for
/// 10–30 s.
pub const CASES: &[Case] = &[
    Case {
        scenario: "seed002",
        label: "fault-free",
        faults: &[],
    },
    Case {
        scenario: "default",
        label: "fault-free",
        faults: &[],
    },
    Case {
        scenario: "seed002",
        label: "GNSS jumps 20 m along the track (250–260 s)",
        faults: &["gnss:bias=20:250:260"],
    },
    Case {
        scenario: "seed002",
        label: "GNSS jumps 8 m along the track (250–260 s)",
        faults: &["gnss:bias=8:250:260"],
    },
    Case {
        scenario: "seed002",
        label: "axle 1 stuck (200–230 s)",
        faults: &["odometer1:stuck:200:230"],
    },
    Case {
        scenario: "seed002",
        label: "axle 1 slips 3 m/s beyond spec (420–440 s)",
        faults: &["odometer1:bias=3:420:440"],
    },
    Case {
        scenario: "seed002",
        label: "axle 2 stuck (200–230 s)",
        faults: &["odometer2:stuck:200:230"],
    },
    // Map offsets from 1 m to 10 m: the smallest that S4 catches in every run.
    Case {
        scenario: "seed002",
        label: "map offset 1 m where the train runs 300–330 s",
        faults: &["map:offset=1:300:330"],
    },
    Case {
        scenario: "seed002",
        label: "map offset 3 m where the train runs 300–330 s",
        faults: &["map:offset=3:300:330"],
    },
    Case {
        scenario: "seed002",
        label: "map offset 5 m where the train runs 300–330 s",
        faults: &["map:offset=5:300:330"],
    },
    Case {
        scenario: "seed002",
        label: "map offset 7 m where the train runs 300–330 s",
        faults: &["map:offset=7:300:330"],
    },
    Case {
        scenario: "seed002",
        label: "map offset 10 m where the train runs 300–330 s",
        faults: &["map:offset=10:300:330"],
    },
];

/// One case over the seeds, for one pipeline.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub scenario: String,
    pub label: String,
    pub pipeline: String,
    pub runs: u64,
    pub epochs: u64,
    pub usable_epochs: u64,
    /// Usable epochs in a degraded mode (something left out, named).
    pub degraded_epochs: u64,
    /// The lowest availability of any run.
    pub availability_min: f64,
    pub intervals_checked: u64,
    pub intervals_contained: u64,
    /// The lowest containment of any run.
    pub containment_min: f64,
    /// Fault windows flagged, of all, and the longest delay to the flag (s).
    pub faults_flagged: u64,
    pub faults: u64,
    pub delay_max_s: Option<f64>,
    /// The checks that flagged the faults first, with how often.
    pub flagged_by: Vec<(String, u64)>,
    /// Each check with the number of fault windows it flagged at any time while they lasted.
    pub flagged_at_all_by: Vec<(String, u64)>,
    /// Mean position RMSE over runs, m.
    pub position_rmse_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SafetyResults {
    pub seeds: u64,
    pub cases: Vec<CaseResult>,
}

pub fn runs(seeds: u64) -> u64 {
    seeds * CASES.len() as u64
}

/// Every case over `seeds` seeds (1 … seeds).
pub fn run_all(dir: &Path, seeds: u64, step: &dyn Fn(u64)) -> Result<SafetyResults> {
    let pipelines = Pipelines::parse(SEED002_PIPELINES, &embedded_path("seed002"))?;
    let mut cases = Vec::new();
    let mut done = 0;
    for case in CASES {
        let faults: Vec<FaultSpec> = case
            .faults
            .iter()
            .map(|f| f.parse().expect("the cases' fault specs parse"))
            .collect();
        let mut acc: Vec<CaseResult> = PIPELINES
            .iter()
            .map(|p| CaseResult {
                scenario: case.scenario.into(),
                label: case.label.into(),
                pipeline: (*p).into(),
                runs: 0,
                epochs: 0,
                usable_epochs: 0,
                degraded_epochs: 0,
                availability_min: 1.0,
                intervals_checked: 0,
                intervals_contained: 0,
                containment_min: 1.0,
                faults_flagged: 0,
                faults: 0,
                delay_max_s: None,
                flagged_by: Vec::new(),
                flagged_at_all_by: Vec::new(),
                position_rmse_m: 0.0,
            })
            .collect();
        for seed in 1..=seeds {
            let run = crate::run(dir, case.scenario, seed, &faults, &pipelines, "safety")?;
            for a in &mut acc {
                let Some(p) = run.pipelines.iter().find(|p| p.name == a.pipeline) else {
                    continue;
                };
                let Some(s) = &p.safety else { continue };
                add(
                    a,
                    s,
                    p.position_error_m.as_ref().map_or(f64::NAN, |e| e.rmse),
                );
            }
            done += 1;
            step(done);
        }
        for a in &mut acc {
            a.position_rmse_m /= a.runs.max(1) as f64;
        }
        cases.extend(acc);
    }
    Ok(SafetyResults { seeds, cases })
}

fn add(a: &mut CaseResult, s: &SafetyEval, rmse: f64) {
    a.runs += 1;
    a.epochs += s.epochs;
    a.usable_epochs += s.usable_epochs;
    a.degraded_epochs += s.degraded_epochs;
    a.availability_min = a.availability_min.min(s.availability);
    a.intervals_checked += s.containment.checked;
    a.intervals_contained += s.containment.contained;
    if let Some(c) = s.containment_share {
        a.containment_min = a.containment_min.min(c);
    }
    for f in &s.faults {
        a.faults += 1;
        if f.flagged {
            a.faults_flagged += 1;
            a.delay_max_s = Some(a.delay_max_s.unwrap_or(0.0).max(f.delay_s.unwrap_or(0.0)));
            count(&mut a.flagged_by, f.by.clone().unwrap_or_default());
        }
        for check in &f.checks {
            count(&mut a.flagged_at_all_by, check.clone());
        }
    }
    a.position_rmse_m += rmse;
}

/// One more for `key` in a tally kept in first-seen order.
fn count(tally: &mut Vec<(String, u64)>, key: String) {
    match tally.iter_mut().find(|(c, _)| *c == key) {
        Some((_, n)) => *n += 1,
        None => tally.push((key, 1)),
    }
}
