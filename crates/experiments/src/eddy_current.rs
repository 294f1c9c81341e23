//! Source 004's experiment: `samples/seed004.toml` (plain correlation, warped correlation,
//! warped plus the Kalman filter) over seeds on the `seed004` preset (shunting moves, hard
//! acceleration and braking, long stops, line speed) and on a rougher track the pipelines'
//! settings were not made for (sleepers laid twice as loosely, twice the noise and vibration,
//! weaker clamps, the sensors 0.3 m apart). Scored against the truth: speed error by speed
//! band (standstill, shunting, two line bands), acceleration error, speed error under hard
//! acceleration below 5 m/s (where warping should pay), distance error as a share of the
//! distance travelled, and sensor a's sleeper count against the true number of sleepers.

use std::path::Path;

use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{FusedDiagnostics, FusedState, GroundTruth, TrackMap};
use railfuse_catalog::topics;
use railfuse_record::simulator::sensors::eddy_current::EddyCurrentParams;
use railfuse_record::Scenario;
use railfuse_refuse::config::embedded_path;
use railfuse_refuse::spec::Pipelines;
use serde::Serialize;

use crate::{Error, Result, Train};

pub const SEED004_PIPELINES: &str = include_str!("../../../samples/seed004.toml");

/// The pipelines compared, simplest first; the last is railfuse's, the filter aided by a
/// wheel odometer.
pub const PIPELINES: [&str; 4] = ["plain", "warped", "warped_kf", "warped_kf_odometer"];

/// A state under this speed, m/s, says the train stands (the standstill band's edge).
pub const STANDING_MPS: f64 = 0.01;

/// Speed bands (m/s, true speed): standstill, shunting, and two line bands.
pub const BANDS: [(&str, f64, f64); 4] = [
    ("standstill", 0.0, 0.01),
    ("0.01–5 m/s", 0.01, 5.0),
    ("5–15 m/s", 5.0, 15.0),
    ("> 15 m/s", 15.0, f64::INFINITY),
];

/// The first seconds of a start from standstill, s: where the speed is not yet observable
/// by correlation (the trailing sensor has not yet passed a clamp the leading one saw
/// moving: about 0.95 m, 1.7 s into a 1.1 m/s² start) and a second window confirms.
pub const STARTING_S: f64 = 2.0;

/// The scenarios: the preset, and the rough track.
pub const SCENARIOS: [&str; 2] = ["seed004", "seed004_rough"];

fn scenario(name: &str) -> Result<Scenario> {
    let base =
        Scenario::preset("seed004").ok_or_else(|| Error::UnknownScenario("seed004".into()))?;
    match name {
        "seed004" => Ok(base),
        "seed004_rough" => {
            let Scenario::Seed004(mut line) = base else {
                unreachable!("the seed004 preset is a line run")
            };
            let e = line
                .eddy_current
                .take()
                .expect("seed004 has an eddy-current pair");
            line.eddy_current = Some(EddyCurrentParams {
                spacing_m: 0.3,
                sleeper_jitter_m: 2.0 * e.sleeper_jitter_m,
                amplitude_spread: 2.0 * e.amplitude_spread,
                sleeper_amplitude_v: 0.7 * e.sleeper_amplitude_v,
                noise_v: 2.0 * e.noise_v,
                vibration_m: 2.0 * e.vibration_m,
                defects_per_km: 3.0 * e.defects_per_km,
                gain_b: 0.9,
                ..e
            });
            Ok(Scenario::Seed004(line))
        }
        other => Err(Error::UnknownScenario(other.into())),
    }
}

/// Errors in one band, kept whole for percentiles (a few thousand per run).
#[derive(Debug, Default, Clone, Serialize)]
pub struct Errors {
    #[serde(skip)]
    values: Vec<f64>,
    /// Relative errors (|e| / true value), for the bands above standstill.
    #[serde(skip)]
    relative: Vec<f64>,
}

impl Errors {
    fn push(&mut self, e: f64, truth: f64) {
        if e.is_finite() {
            self.values.push(e);
            if truth.abs() > 0.01 {
                self.relative.push(e.abs() / truth.abs());
            }
        }
    }
    pub fn n(&self) -> usize {
        self.values.len()
    }
    pub fn rmse(&self) -> f64 {
        (self.values.iter().map(|e| e * e).sum::<f64>() / self.values.len().max(1) as f64).sqrt()
    }
    fn pct(v: &[f64], p: f64) -> f64 {
        if v.is_empty() {
            return f64::NAN;
        }
        let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
        a.sort_by(f64::total_cmp);
        a[((p * (a.len() - 1) as f64).round() as usize).min(a.len() - 1)]
    }
    pub fn p95(&self) -> f64 {
        Self::pct(&self.values, 0.95)
    }
    pub fn relative_p95(&self) -> f64 {
        Self::pct(&self.relative, 0.95)
    }
}

/// One pipeline on one scenario, pooled over the seeds.
#[derive(Debug, Default, Clone, Serialize)]
pub struct PipelineErrors {
    pub scenario: String,
    pub pipeline: String,
    pub runs: u64,
    #[serde(skip)]
    pub speed: Vec<Errors>,
    #[serde(skip)]
    pub acceleration: Errors,
    /// Speed below 5 m/s while |a| ≥ 0.8 m/s².
    #[serde(skip)]
    pub hard_acceleration: Errors,
    /// Speed from 0.01 to 5 m/s within the first [`STARTING_S`] of a start from standstill,
    /// and the rest of that band.
    #[serde(skip)]
    pub starting: Errors,
    #[serde(skip)]
    pub slow_otherwise: Errors,
    /// Every stop: how long after the train stopped the states said so for good (∞: never),
    /// and how far the chainage moved from then until the train moved off.
    pub stop_latency_s: Vec<f64>,
    pub standing_drift_m: Vec<f64>,
    /// Per run: distance error as a share of the distance travelled, and the count error.
    pub distance_share: Vec<f64>,
    pub count_error: Vec<i64>,
    pub true_count: Vec<u64>,
    /// States per run, and the windows without a measurement.
    pub states: u64,
    pub no_lock: u64,
    pub windows: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct EddyCurrentResults {
    pub seeds: u64,
    pub rows: Vec<PipelineErrors>,
}

pub fn runs(seeds: u64) -> u64 {
    seeds * SCENARIOS.len() as u64
}

/// Every scenario over `seeds` seeds (1 … seeds).
pub fn run_all(dir: &Path, seeds: u64, step: &dyn Fn(u64)) -> Result<EddyCurrentResults> {
    let pipelines = Pipelines::parse(SEED004_PIPELINES, &embedded_path("seed004"))?;
    let mut rows = Vec::new();
    let mut done = 0;
    for name in SCENARIOS {
        let preset = scenario(name)?;
        let mut acc: Vec<PipelineErrors> = PIPELINES
            .iter()
            .map(|p| PipelineErrors {
                scenario: name.into(),
                pipeline: (*p).into(),
                speed: vec![Errors::default(); BANDS.len()],
                ..Default::default()
            })
            .collect();
        for seed in 1..=seeds {
            // The rough track runs under the preset's name: tag it apart.
            crate::score_fused_run(
                dir,
                &preset,
                seed,
                (&pipelines, Train::AsConfigured),
                name,
                |fused| score(fused, &mut acc),
            )?;
            done += 1;
            step(done);
        }
        rows.extend(acc);
    }
    Ok(EddyCurrentResults { seeds, rows })
}

/// The sleepers of the map's atlas in (a, b] that the pipeline counts: its sections' grid
/// points, less those within the pipeline's margin of a switch (bridged, not counted).
pub fn sleepers_between(map: &TrackMap, a: f64, b: f64) -> u64 {
    let margin = railfuse_refuse::eddy_current::SWITCH_MARGIN_M;
    let bridged: Vec<(f64, f64)> = map
        .switches
        .iter()
        .map(|w| (w.start_chainage_m - margin, w.end_chainage_m + margin))
        .collect();
    map.sleeper_sections
        .iter()
        .map(|s| {
            // Grid points start + (k + ½)·spacing inside the section, clear of the bridged
            // stretches at its ends, and inside (a, b].
            let mut lo = a.max(s.start_chainage_m);
            let mut hi = b.min(s.end_chainage_m);
            for &(p, q) in &bridged {
                if (p..=q).contains(&lo) {
                    lo = q;
                }
                if (p..=q).contains(&hi) {
                    hi = p;
                }
            }
            if hi <= lo {
                return 0;
            }
            let k = |x: f64| ((x - s.start_chainage_m) / s.spacing_m - 0.5).floor();
            (k(hi) - k(lo)).max(0.0) as u64
        })
        .sum()
}

/// One pipeline's windows in one run: (stamp, sensor a's count) of the first and the last
/// window that counted, how many windows, how many without a measurement.
#[derive(Debug, Default, Clone, Copy)]
struct WindowCounts {
    first: Option<(u64, u64)>,
    last: Option<(u64, u64)>,
    windows: u64,
    no_lock: u64,
}

/// Adds one fused run's errors to `acc` (one row per pipeline).
fn score(fused: &Path, acc: &mut [PipelineErrors]) -> Result<()> {
    let run = Run::read(fused, acc)?;
    let truth = Truth::new(run.truth);
    for ((a, states), counts) in acc.iter_mut().zip(&run.states).zip(&run.counts) {
        score_pipeline(a, states, counts, &truth, run.map.as_ref());
    }
    Ok(())
}

/// What one fused log holds for the scores: the truth, the map, and each pipeline's states
/// and window counts.
struct Run {
    truth: Vec<GroundTruth>,
    map: Option<TrackMap>,
    states: Vec<Vec<FusedState>>,
    counts: Vec<WindowCounts>,
}

impl Run {
    fn read(fused: &Path, acc: &[PipelineErrors]) -> Result<Self> {
        let state_topics: Vec<String> = acc
            .iter()
            .map(|a| topics::fused_state(&a.pipeline))
            .collect();
        let diag_topics: Vec<String> = acc
            .iter()
            .map(|a| topics::fused_diagnostics(&a.pipeline))
            .collect();
        let mut run = Run {
            truth: Vec::new(),
            map: None,
            states: vec![Vec::new(); acc.len()],
            counts: vec![WindowCounts::default(); acc.len()],
        };
        let mut r = LogReader::open(fused)?;
        while let Some(rec) = r.next() {
            let LogRecord::Message(m) = rec? else {
                continue;
            };
            let topic = m.channel.topic.as_str();
            if topic == topics::GROUND_TRUTH {
                run.truth.push(m.decode(fused)?);
            } else if topic == topics::TRACK_MAP {
                run.map = Some(m.decode(fused)?);
            } else if let Some(k) = state_topics.iter().position(|t| t == topic) {
                run.states[k].push(m.decode(fused)?);
            } else if let Some(k) = diag_topics.iter().position(|t| t == topic) {
                let d: FusedDiagnostics = m.decode(fused)?;
                if let Some(e) = d.eddy_current {
                    let c = &mut run.counts[k];
                    c.windows += 1;
                    c.no_lock += u64::from(e.window == "no_lock");
                    if e.sleepers_a > 0 {
                        c.first.get_or_insert((d.stamp_ns, e.sleepers_a));
                        c.last = Some((d.stamp_ns, e.sleepers_a));
                    }
                }
            }
        }
        Ok(run)
    }
}

/// The truth, interpolated to any stamp, and when the train stopped and moved off.
struct Truth {
    samples: Vec<GroundTruth>,
    onsets: Vec<u64>,
    stops: Vec<u64>,
}

impl Truth {
    fn new(samples: Vec<GroundTruth>) -> Self {
        let edges = |starting: bool| {
            samples
                .windows(2)
                .filter(|w| match starting {
                    true => w[0].speed_mps == 0.0 && w[1].speed_mps > 0.0,
                    false => w[0].speed_mps > 0.0 && w[1].speed_mps == 0.0,
                })
                .map(|w| w[usize::from(!starting)].stamp_ns)
                .collect()
        };
        let (onsets, stops) = (edges(true), edges(false));
        Self {
            samples,
            onsets,
            stops,
        }
    }

    /// Each stop: when the train stopped, and when it moved off again (the end of the run).
    fn stands(&self) -> impl Iterator<Item = (u64, u64)> + '_ {
        self.stops.iter().map(|&stop| {
            let off = self.onsets.iter().find(|&&o| o > stop);
            (stop, off.copied().unwrap_or(u64::MAX))
        })
    }

    fn at(&self, t: u64) -> Option<GroundTruth> {
        let truth = &self.samples;
        let i = truth.partition_point(|g| g.stamp_ns < t);
        let (a, b) = (truth.get(i.checked_sub(1)?)?, truth.get(i)?);
        let w = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns).max(1) as f64;
        let lerp = |x: f64, y: f64| x + w * (y - x);
        Some(GroundTruth {
            stamp_ns: t,
            chainage_m: lerp(a.chainage_m, b.chainage_m),
            speed_mps: lerp(a.speed_mps, b.speed_mps),
            acceleration_mps2: lerp(a.acceleration_mps2, b.acceleration_mps2),
            ..a.clone()
        })
    }

    /// Within the first [`STARTING_S`] of a start from standstill.
    fn starting(&self, t: u64) -> bool {
        let i = self.onsets.partition_point(|&o| o <= t);
        i > 0 && (t - self.onsets[i - 1]) as f64 / 1e9 < STARTING_S
    }
}

/// One pipeline's states of one run added to its errors: speed by band, acceleration, the
/// starts, distance and the sleeper count.
fn score_pipeline(
    a: &mut PipelineErrors,
    states: &[FusedState],
    counts: &WindowCounts,
    truth: &Truth,
    map: Option<&TrackMap>,
) {
    a.runs += 1;
    a.states += states.len() as u64;
    a.windows += counts.windows;
    a.no_lock += counts.no_lock;
    for s in states {
        let Some(g) = truth.at(s.stamp_ns) else {
            continue;
        };
        let band = BANDS
            .iter()
            .position(|(_, lo, hi)| g.speed_mps >= *lo && g.speed_mps < *hi)
            .unwrap_or(0);
        let e = s.speed_mps - g.speed_mps;
        a.speed[band].push(e, g.speed_mps);
        a.acceleration.push(
            s.acceleration_mps2 - g.acceleration_mps2,
            g.acceleration_mps2,
        );
        if g.speed_mps > 0.01 && g.speed_mps < 5.0 && g.acceleration_mps2.abs() >= 0.8 {
            a.hard_acceleration.push(e, g.speed_mps);
        }
        if (0.01..5.0).contains(&g.speed_mps) {
            match truth.starting(s.stamp_ns) {
                true => a.starting.push(e, g.speed_mps),
                false => a.slow_otherwise.push(e, g.speed_mps),
            }
        }
    }
    for (stop, off) in truth.stands() {
        let (latency, drift) = standstill(states, stop, off);
        a.stop_latency_s.push(latency);
        a.standing_drift_m.extend(drift);
    }
    // The first and the last state the truth covers (a wheel's last sample may come after
    // the truth's).
    let covered = |s: &&FusedState| truth.at(s.stamp_ns).is_some();
    let (Some(first), Some(last)) = (
        states.iter().find(covered),
        states.iter().rev().find(covered),
    ) else {
        return;
    };
    if let (Some(g0), Some(g1)) = (truth.at(first.stamp_ns), truth.at(last.stamp_ns)) {
        let travelled = g1.chainage_m - g0.chainage_m;
        let measured = last.chainage_m - first.chainage_m;
        if travelled > 0.0 {
            a.distance_share.push((measured - travelled) / travelled);
        }
    }
    if let (Some(map), Some((t0, c0)), Some((t1, c1))) = (map, counts.first, counts.last) {
        if let (Some(g0), Some(g1)) = (truth.at(t0), truth.at(t1)) {
            let n = sleepers_between(map, g0.chainage_m, g1.chainage_m);
            a.true_count.push(n);
            a.count_error.push((c1 - c0) as i64 - n as i64);
        }
    }
}

/// One stop from `stop` to `off`: how long until the states said it for good (from their
/// first state under [`STANDING_MPS`] after which every one is), and how far their chainage
/// moved from then on. ∞ and nothing if they never did.
fn standstill(states: &[FusedState], stop: u64, off: u64) -> (f64, Option<f64>) {
    let during: Vec<&FusedState> = states
        .iter()
        .filter(|s| s.stamp_ns >= stop && s.stamp_ns < off)
        .collect();
    let moving = during
        .iter()
        .rposition(|s| s.speed_mps.abs() >= STANDING_MPS);
    let from = moving.map_or(0, |i| i + 1);
    let Some(first) = during.get(from) else {
        return (f64::INFINITY, None);
    };
    let drift = during[from..]
        .iter()
        .map(|s| (s.chainage_m - first.chainage_m).abs())
        .fold(0.0, f64::max);
    ((first.stamp_ns - stop) as f64 / 1e9, Some(drift))
}
