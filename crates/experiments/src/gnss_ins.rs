//! Source 003's experiment: `samples/seed003.toml` (plain KF, AKF, adaptive RLS and PU-RLS)
//! over seeds on the `seed003` preset (the source's hardware, a 150 s GNSS loss), on
//! `seed003_3d` (the same on the railway in three dimensions with a 104 m train), and on the
//! default scenario and its flat twin (a 200 Hz IMU whose errors the pipelines' IMU model does
//! not describe),
//! scored in the plane: velocity-error standard deviation and maximum east and north, the mean
//! absolute east and north position error, and the position-error standard deviation through
//! the loss, each beside the source's figure and as the improvement over the plain KF.

use std::path::Path;

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{FusedState, GroundTruth};
use railfuse_catalog::topics;
use railfuse_record::Scenario;
use railfuse_refuse::config::embedded_path;
use railfuse_refuse::spec::Pipelines;
use serde::Serialize;

use crate::{Error, Result, Train};

pub const SEED003_PIPELINES: &str = include_str!("../../../samples/seed003.toml");

/// The pipelines compared, the plain KF first (the improvements are over it); the source's
/// four, then railfuse's with the train's constraints (and its speed sensors).
pub const PIPELINES: [&str; 6] = ["kf", "akf", "rls", "pu_rls", "kf_track", "kf_track_speed"];

/// railfuse's pipelines, which the source has no counterpart of.
pub const TRAIN_PIPELINES: [&str; 2] = ["kf_track", "kf_track_speed"];

/// The 95 % interval of χ² with one degree of freedom.
const NEES_95: (f64, f64) = (0.000_982, 5.024);

/// The scenarios, the GNSS loss each has (s from the start, length) if scored, and the train
/// each run is re-fused with: the source's experiment in its flat world and on the railway in
/// three dimensions with a 104 m train, and the default run in both worlds. A railway run's
/// train is built to a tolerance of its drawing: its IMU's mounting is calibrated from the run
/// first, as a field engineer does (`railfuse calibrate`, then `refuse --vehicle`).
pub const SCENARIOS: [(&str, Option<(f64, f64)>, Train); 5] = [
    ("seed003", Some((330.0, 150.0)), Train::AsConfigured),
    ("seed003_3d", Some((330.0, 150.0)), Train::Calibrated),
    ("seed003_3d_flat", Some((330.0, 150.0)), Train::AsConfigured),
    ("default", None, Train::Calibrated),
    ("flat", None, Train::AsConfigured),
];

/// A running mean, variance and largest magnitude.
#[derive(Debug, Default, Clone, Copy, Serialize)]
pub struct Spread {
    pub n: u64,
    mean: f64,
    m2: f64,
    abs_sum: f64,
    pub max_abs: f64,
}

impl Spread {
    fn push(&mut self, x: f64) {
        if !x.is_finite() {
            return;
        }
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
        self.abs_sum += x.abs();
        self.max_abs = self.max_abs.max(x.abs());
    }

    pub fn std(&self) -> f64 {
        (self.m2 / (self.n.max(2) - 1) as f64).sqrt()
    }

    pub fn mean_abs(&self) -> f64 {
        self.abs_sum / self.n.max(1) as f64
    }
}

/// How often the along-track NEES lay inside its 95 % interval.
#[derive(Debug, Default, Clone, Copy, Serialize)]
pub struct Consistency {
    pub n: u64,
    pub inside: u64,
}

impl Consistency {
    fn push(&mut self, error: f64, variance: f64) {
        if !(error.is_finite() && variance > 0.0) {
            return;
        }
        let nees = error * error / variance;
        self.n += 1;
        self.inside += u64::from(nees >= NEES_95.0 && nees <= NEES_95.1);
    }

    /// The share inside, 0–1 (NaN with no samples).
    pub fn share(&self) -> f64 {
        self.inside as f64 / self.n as f64
    }
}

/// One pipeline on one scenario, pooled over the seeds.
#[derive(Debug, Default, Clone, Serialize)]
pub struct PlaneErrors {
    pub scenario: String,
    pub pipeline: String,
    pub runs: u64,
    pub velocity_east: Spread,
    pub velocity_north: Spread,
    pub position_east: Spread,
    pub position_north: Spread,
    /// Through the GNSS loss only.
    pub outage_east: Spread,
    pub outage_north: Spread,
    /// Along-track (chainage) error through the loss.
    pub outage_along: Spread,
    /// The chainage's NEES against its variance, over the whole run and through the loss.
    pub nees: Consistency,
    pub outage_nees: Consistency,
}

#[derive(Debug, Clone, Serialize)]
pub struct GnssInsResults {
    pub seeds: u64,
    pub rows: Vec<PlaneErrors>,
}

pub fn runs(seeds: u64) -> u64 {
    seeds * SCENARIOS.len() as u64
}

/// Every scenario over `seeds` seeds (1 … seeds).
pub fn run_all(dir: &Path, seeds: u64, step: &dyn Fn(u64)) -> Result<GnssInsResults> {
    let pipelines = Pipelines::parse(SEED003_PIPELINES, &embedded_path("seed003"))?;
    let mut rows = Vec::new();
    let mut done = 0;
    for (scenario, outage, train) in SCENARIOS {
        let preset = Scenario::preset(scenario)
            .ok_or_else(|| Error::UnknownScenario(scenario.to_owned()))?;
        let mut acc: Vec<PlaneErrors> = PIPELINES
            .iter()
            .map(|p| PlaneErrors {
                scenario: scenario.into(),
                pipeline: (*p).into(),
                ..Default::default()
            })
            .collect();
        for seed in 1..=seeds {
            crate::score_fused_run(
                dir,
                &preset,
                seed,
                (&pipelines, train),
                "gnss_ins",
                |fused| score(fused, outage, &mut acc),
            )?;
            done += 1;
            step(done);
        }
        rows.extend(acc);
    }
    Ok(GnssInsResults { seeds, rows })
}

/// Adds one fused run's plane errors to `acc` (one row per pipeline). Two passes over the
/// file: the truth first (it is needed at every state's stamp), then the states, streamed.
fn score(fused: &Path, outage: Option<(f64, f64)>, acc: &mut [PlaneErrors]) -> Result<()> {
    let mut truth: Vec<GroundTruth> = Vec::new();
    let mut r = LogReader::open(fused)?;
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec? {
            if m.channel.topic == topics::GROUND_TRUTH {
                truth.push(m.decode(fused)?);
            }
        }
    }
    let Some(t0) = truth.first().map(|g| g.stamp_ns) else {
        return Ok(());
    };
    for a in acc.iter_mut() {
        a.runs += 1;
    }
    let topics: Vec<String> = acc
        .iter()
        .map(|a| topics::fused_state(&a.pipeline))
        .collect();
    let mut r = LogReader::open(fused)?;
    while let Some(rec) = r.next() {
        let LogRecord::Message(m) = rec? else {
            continue;
        };
        let Some(k) = topics.iter().position(|t| *t == m.channel.topic) else {
            continue;
        };
        let s: FusedState = m.decode(fused)?;
        let Some(p) = &s.plane else { continue };
        let Some(g) = truth_at(&truth, s.stamp_ns) else {
            continue;
        };
        let a = &mut acc[k];
        let (ee, en) = (p.east_m - g.east_m, p.north_m - g.north_m);
        let along = s.chainage_m - g.chainage_m;
        a.position_east.push(ee);
        a.position_north.push(en);
        a.nees.push(along, s.covariance[0]);
        if let Some([ve, vn]) = p.velocity_en_mps {
            let (te, tn) = (
                g.speed_mps * g.heading_rad.sin(),
                g.speed_mps * g.heading_rad.cos(),
            );
            a.velocity_east.push(ve - te);
            a.velocity_north.push(vn - tn);
        }
        let at = (s.stamp_ns.saturating_sub(t0)) as f64 / 1e9;
        if outage.is_some_and(|(start, len)| at >= start && at < start + len) {
            a.outage_east.push(ee);
            a.outage_north.push(en);
            a.outage_along.push(along);
            a.outage_nees.push(along, s.covariance[0]);
        }
    }
    Ok(())
}

/// The truth at `t`, interpolated between its samples.
fn truth_at(truth: &[GroundTruth], t: u64) -> Option<GroundTruth> {
    let i = truth.partition_point(|g| g.stamp_ns < t);
    let (a, b) = (truth.get(i.checked_sub(1)?)?, truth.get(i)?);
    let w = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns).max(1) as f64;
    let lerp = |x: f64, y: f64| x + w * (y - x);
    Some(GroundTruth {
        stamp_ns: t,
        chainage_m: lerp(a.chainage_m, b.chainage_m),
        east_m: lerp(a.east_m, b.east_m),
        north_m: lerp(a.north_m, b.north_m),
        speed_mps: lerp(a.speed_mps, b.speed_mps),
        // Headings change by milliradians between 100 Hz samples: no wrap to handle.
        heading_rad: if w < 0.5 {
            a.heading_rad
        } else {
            b.heading_rad
        },
        ..a.clone()
    })
}

/// Source 003's figures (its car test, table 2 and section 3.1), for the comparison.
pub struct SourceFigures {
    pub pipeline: &'static str,
    pub velocity_std_en: Option<(f64, f64)>,
    pub velocity_max_en: Option<(f64, f64)>,
    pub mean_east_m: Option<f64>,
    pub outage_std_en: Option<(f64, f64)>,
}

pub const SOURCE: [SourceFigures; 4] = [
    SourceFigures {
        pipeline: "kf",
        velocity_std_en: Some((0.5146, 0.9949)),
        velocity_max_en: Some((7.2403, 38.8381)),
        mean_east_m: Some(3.26),
        outage_std_en: Some((12.3963, 2.5411)),
    },
    SourceFigures {
        pipeline: "akf",
        velocity_std_en: None,
        velocity_max_en: None,
        mean_east_m: Some(3.08),
        outage_std_en: None,
    },
    SourceFigures {
        pipeline: "rls",
        velocity_std_en: Some((0.4414, 0.8533)),
        velocity_max_en: Some((6.2099, 33.3112)),
        mean_east_m: Some(2.43),
        outage_std_en: None,
    },
    SourceFigures {
        pipeline: "pu_rls",
        velocity_std_en: Some((0.2241, 0.4233)),
        velocity_max_en: Some((3.0095, 17.0946)),
        mean_east_m: Some(1.21),
        outage_std_en: Some((5.0772, 1.0007)),
    },
];
