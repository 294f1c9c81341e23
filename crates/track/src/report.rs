//! What a fit says about itself: the residuals across the track, each run's share and
//! excursions, the gaps bridged, where runs disagree and the residual stretch by stretch.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::bridge::Crossings;
use crate::error::FitError;
use crate::fixes::RunFixes;
use crate::line::{increasing, Line, OnLine};
use crate::multipath::SetAside;

/// A chainage stretch, m (in the line's provisional chainage until [`crate::chainage`]
/// places it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stretch {
    pub from_m: f64,
    pub to_m: f64,
}

/// A stretch of line with no fix: crossed by the motion of some runs (their IMU and
/// odometer), else bridged by the spline alone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gap {
    pub from_m: f64,
    pub to_m: f64,
    pub crossed_by_runs: usize,
}

/// A stretch where runs put the line in different places.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Disagreement {
    pub from_m: f64,
    pub to_m: f64,
    /// The largest difference of two runs' mean offsets there, m.
    pub spread_m: f64,
}

/// What one run gave.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunReport {
    pub name: String,
    pub fixes: usize,
    /// On the line and fitted.
    pub used: usize,
    /// On the line, in a stretch set aside.
    pub set_aside: usize,
    pub off_line: usize,
    /// Travelling towards increasing chainage (the line's as fitted), or not.
    pub increasing: bool,
    /// Stretches where it leaves the line: from the last fix on it to the next one (`to`
    /// absent where it does not come back).
    pub leaves_line: Vec<Excursion>,
    pub lateral_rms_m: f64,
    /// What taking its antenna's lean out of its fixes did.
    pub antenna_lean: Option<crate::motion::Lean>,
    /// The antenna's height when its lean is left in (no IMU), m.
    pub antenna_lean_kept_m: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Excursion {
    pub from_m: Option<f64>,
    pub to_m: Option<f64>,
    pub fixes: usize,
    pub largest_offset_m: f64,
}

/// The fitted line and how it was made.
#[derive(Debug, Clone)]
pub struct Centreline {
    pub line: Line,
    pub runs: Vec<RunReport>,
    pub fixes_used: usize,
    pub lateral_rms_m: f64,
    pub lateral_p95_m: f64,
    /// Stretches longer than [`GAP_M`] without a fix used.
    pub gaps: Vec<Gap>,
    /// Stretches whose fixes the runs' motion contradicted, set aside.
    pub set_aside: Vec<SetAside>,
    pub disagreements: Vec<Disagreement>,
    /// Where the first run's first fix on the line lies, and whether it travels towards
    /// increasing chainage: the default origin and direction.
    pub first_run_start: (f64, bool),
    /// The residual across the track stretch by stretch (`FitOptions::stretch_m`).
    pub stretches: Vec<StretchResidual>,
    /// The height profile, once fitted ([`crate::profile`]).
    pub profile: Option<crate::profile::Profile>,
    /// The cant, once fitted ([`crate::cant`]).
    pub cant: Option<crate::cant::Cant>,
}

/// The fixes' residual across the track over one stretch of line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StretchResidual {
    pub from_m: f64,
    pub to_m: f64,
    pub fixes: usize,
    pub rms_m: f64,
}

impl Centreline {
    /// The first stretch whose residual RMS exceeds `tolerance_m`, its chainage placed by
    /// `chainage` (a fit that cannot keep its promise says where).
    pub fn check(&self, tolerance_m: f64, chainage: impl Fn(f64) -> f64) -> Result<(), FitError> {
        match self.stretches.iter().find(|s| s.rms_m > tolerance_m) {
            None => Ok(()),
            Some(s) => {
                let (a, b) = (chainage(s.from_m), chainage(s.to_m));
                let leaning: Vec<&str> = self
                    .runs
                    .iter()
                    .filter(|r| r.antenna_lean_kept_m.is_some())
                    .map(|r| r.name.as_str())
                    .collect();
                let leaning = match leaning.is_empty() {
                    true => String::new(),
                    false => format!(
                        ", or runs whose fixes keep the roof antenna's lean in canted curves \
                         (no IMU to take it out: {})",
                        leaning.join(", ")
                    ),
                };
                Err(FitError::Tolerance {
                    from_m: a.min(b),
                    to_m: a.max(b),
                    rms_m: s.rms_m,
                    tolerance_m,
                    leaning,
                })
            }
        }
    }
}

/// A stretch of line longer than this without a fix is a gap, m.
pub const GAP_M: f64 = 50.0;

/// Runs' mean offsets are compared over bins this long, m.
const DISAGREEMENT_BIN_M: f64 = 100.0;

/// A run's stretch off the line shorter than this many fixes is noise, not an excursion.
const MIN_EXCURSION_FIXES: usize = 5;

/// A run's mean offset in a bin counts from this many fixes.
const MIN_BIN_FIXES: usize = 3;

/// Where a fit left each run's fixes.
pub(crate) struct Fitted<'a> {
    /// Each fix's place on the line (`None`: off it).
    pub placed: &'a [Vec<Option<OnLine>>],
    /// Each fix set aside (on the line, in a stretch its runs' motion contradicts).
    pub aside: &'a [Vec<bool>],
    pub set_aside: Vec<SetAside>,
}

pub(crate) fn finish(
    line: Line,
    runs: &[RunFixes],
    fitted: Fitted,
    crossed: &[Crossings],
    stretch_m: f64,
    disagreement_m: f64,
) -> Centreline {
    let Fitted {
        placed,
        aside,
        set_aside,
    } = fitted;
    // The fixes the line was fitted to.
    let used: Vec<Vec<Option<OnLine>>> = placed
        .iter()
        .zip(aside)
        .map(|(p, a)| p.iter().zip(a).map(|(m, &a)| m.filter(|_| !a)).collect())
        .collect();
    // `on_line`: every fix on the line, those set aside included; `placed`: those fitted.
    let (on_line, placed) = (placed, &used[..]);
    let on: Vec<&OnLine> = placed.iter().flatten().flatten().collect();
    let with_sigma: Vec<(&OnLine, f64)> = runs
        .iter()
        .zip(placed)
        .flat_map(|(r, p)| r.fixes.iter().zip(p))
        .filter_map(|(f, m)| Some((m.as_ref()?, f.sigma_m)))
        .collect();
    let mut abs: Vec<f64> = on.iter().map(|m| m.lateral_m.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let p95 = abs
        .get(((abs.len() as f64 * 0.95).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(0.0);
    // Where the first run starts on the line, its fixes set aside included.
    let first_run_start = on_line[0]
        .iter()
        .flatten()
        .next()
        .map_or((line.start_m(), true), |m| {
            (m.chainage_m, increasing(&on_line[0]))
        });
    Centreline {
        runs: runs
            .iter()
            .zip(placed)
            .zip(on_line)
            .map(|((r, used), all)| run_report(r, used, all))
            .collect(),
        set_aside,
        fixes_used: on.len(),
        lateral_rms_m: rms(on.iter().map(|m| m.lateral_m)),
        lateral_p95_m: p95,
        gaps: gaps(&on, &line, crossed),
        disagreements: disagreements(placed, disagreement_m),
        first_run_start,
        stretches: stretches(&with_sigma, stretch_m),
        line,
        profile: None,
        cant: None,
    }
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (n, sq) = x.fold((0usize, 0.0), |(n, sq), e| (n + 1, sq + e * e));
    if n == 0 {
        0.0
    } else {
        (sq / n as f64).sqrt()
    }
}

/// The residual RMS across the track over each `length_m` stretch with fixes, each fix
/// weighted by 1/σ² (a float fix among fixed ones counts as little as the fit let it).
fn stretches(on: &[(&OnLine, f64)], length_m: f64) -> Vec<StretchResidual> {
    // bin → (fixes, Σw, Σw·r²)
    let mut bins: BTreeMap<i64, (usize, f64, f64)> = BTreeMap::new();
    for (m, sigma) in on {
        let w = 1.0 / (sigma * sigma).max(1e-6);
        let b = bins
            .entry((m.chainage_m / length_m).floor() as i64)
            .or_default();
        b.0 += 1;
        b.1 += w;
        b.2 += w * m.lateral_m * m.lateral_m;
    }
    bins.into_iter()
        .map(|(bin, (n, sw, swr))| StretchResidual {
            from_m: bin as f64 * length_m,
            to_m: (bin + 1) as f64 * length_m,
            fixes: n,
            rms_m: (swr / sw).sqrt(),
        })
        .collect()
}

/// A run's report from its fixes `used` and all it has on the line.
fn run_report(run: &RunFixes, used: &[Option<OnLine>], on_line: &[Option<OnLine>]) -> RunReport {
    let (n_used, n_on) = (
        used.iter().flatten().count(),
        on_line.iter().flatten().count(),
    );
    RunReport {
        name: run.name.clone(),
        fixes: run.fixes.len(),
        used: n_used,
        set_aside: n_on - n_used,
        off_line: run.fixes.len() - n_on,
        increasing: increasing(on_line),
        leaves_line: excursions(run, on_line),
        lateral_rms_m: rms(used.iter().flatten().map(|m| m.lateral_m)),
        antenna_lean: run.lean,
        antenna_lean_kept_m: run.lean_kept_m,
    }
}

/// A run's stretches of consecutive fixes off the line.
fn excursions(run: &RunFixes, placed: &[Option<OnLine>]) -> Vec<Excursion> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < placed.len() {
        if placed[i].is_some() {
            i += 1;
            continue;
        }
        let start = i;
        while i < placed.len() && placed[i].is_none() {
            i += 1;
        }
        if i - start < MIN_EXCURSION_FIXES {
            continue;
        }
        // How far off: from the nearest fix on the line before it.
        let anchor = start
            .checked_sub(1)
            .map(|a| (run.fixes[a].east_m, run.fixes[a].north_m));
        let largest = run.fixes[start..i]
            .iter()
            .filter_map(|f| anchor.map(|(e, n)| (f.east_m - e).hypot(f.north_m - n)))
            .fold(0.0, f64::max);
        out.push(Excursion {
            from_m: start
                .checked_sub(1)
                .and_then(|a| placed[a])
                .map(|m| m.chainage_m),
            to_m: placed.get(i).copied().flatten().map(|m| m.chainage_m),
            fixes: i - start,
            largest_offset_m: largest,
        });
    }
    out
}

/// Stretches longer than [`GAP_M`] with no fix on the line, each with the number of runs
/// whose motion crossed it.
fn gaps(on: &[&OnLine], line: &Line, crossed: &[Crossings]) -> Vec<Gap> {
    let mut s: Vec<f64> = on.iter().map(|m| m.chainage_m).collect();
    s.push(line.start_m());
    s.push(line.end_m());
    s.sort_by(f64::total_cmp);
    s.windows(2)
        .filter(|w| w[1] - w[0] > GAP_M)
        .map(|w| {
            let mid = (w[0] + w[1]) / 2.0;
            let covers = |c: &Crossings| c.spans.iter().any(|&(a, b)| (a..=b).contains(&mid));
            Gap {
                from_m: w[0],
                to_m: w[1],
                crossed_by_runs: crossed.iter().filter(|c| covers(c)).count(),
            }
        })
        .collect()
}

/// Bins where two runs' mean offsets differ by more than `limit_m`, neighbours merged.
fn disagreements(placed: &[Vec<Option<OnLine>>], limit_m: f64) -> Vec<Disagreement> {
    // bin → run → (n, Σ offset)
    let mut bins: BTreeMap<i64, BTreeMap<usize, (usize, f64)>> = BTreeMap::new();
    for (r, p) in placed.iter().enumerate() {
        for m in p.iter().flatten() {
            let e = bins
                .entry((m.chainage_m / DISAGREEMENT_BIN_M).floor() as i64)
                .or_default()
                .entry(r)
                .or_default();
            e.0 += 1;
            e.1 += m.lateral_m;
        }
    }
    let mut out: Vec<Disagreement> = Vec::new();
    for (bin, per_run) in bins {
        let means: Vec<f64> = per_run
            .values()
            .filter(|(n, _)| *n >= MIN_BIN_FIXES)
            .map(|(n, s)| s / *n as f64)
            .collect();
        if means.len() < 2 {
            continue;
        }
        let spread = means.iter().fold(f64::MIN, |a, &b| a.max(b))
            - means.iter().fold(f64::MAX, |a, &b| a.min(b));
        if spread <= limit_m {
            continue;
        }
        let from = bin as f64 * DISAGREEMENT_BIN_M;
        match out.last_mut() {
            Some(d) if d.to_m == from => {
                d.to_m = from + DISAGREEMENT_BIN_M;
                d.spread_m = d.spread_m.max(spread);
            }
            _ => out.push(Disagreement {
                from_m: from,
                to_m: from + DISAGREEMENT_BIN_M,
                spread_m: spread,
            }),
        }
    }
    out
}
