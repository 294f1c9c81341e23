//! Stretches where the fixes bend and the trains did not: a steady multipath pull.
//!
//! A station building or a cutting wall pulls every run's fixes the same way at the same
//! place, so the runs agree with each other and the spline follows the pull. Their gyros do
//! not: a 3 m pull over 600 m swings the fixes' heading by 16 mrad, which no train turned.
//!
//! For each run with motion, every step's turn is compared with the line's change of heading
//! over the chainage the step ran (placed between the run's fixes by the distance its
//! odometer ran), as the line's direction of travel goes:
//!
//! ```text
//! e_k = turn_k − (ψ_line(s_k) − ψ_line(s_{k−1}))
//! ```
//!
//! On a right line `e_k` is the gyro's bias and noise. The bias, which wanders, is its mean
//! over [`BIAS_WINDOW_S`] either side: a pull's own heading swings sum to nothing across it,
//! and a train standing in one measures only the bias. What is left, summed over
//! [`BIN_M`] of chainage while the train moves and averaged over the runs by their
//! variance (the gyro's angle noise `q²T` and the bias's error `(σ_b T)²` for the time `T`
//! spent), is the line's error of heading change there. A bin where it stands out of the
//! bins' own robust spread by [`THRESHOLD`] times, and by [`MIN_MRAD`] at least, is suspect;
//! suspect bins closer than [`MERGE_M`] merge, and each stretch is widened by one bin either
//! side. [`crate::fit`] sets the fixes there aside and lets the runs' motion cross the
//! stretch, as it crosses a gap.

use serde::Serialize;

use crate::fixes::RunFixes;
use crate::line::{Line, OnLine};
use crate::tie::wrap;
use railfuse_catalog::map_matching::locate_on;

/// Length of the bins the runs' turn is compared over, m.
pub const BIN_M: f64 = 50.0;

/// The gyro's bias is averaged over this long either side of a step, s.
pub const BIAS_WINDOW_S: f64 = 20.0;

/// The offset is taken at a bin's middle from the chord this far either side, m.
pub const SAG_HALF_M: f64 = 150.0;

/// A bin is suspect when its offset exceeds this many times its σ (the bins' robust spread
/// scaling the nominal gyro) …
pub const THRESHOLD: f64 = 8.0;

/// … and this many metres.
pub const MIN_SAG_M: f64 = 0.2;

/// Suspect bins closer than this are one stretch, m: the two sides of one pull, whose
/// middle a train slowing into a station sees through few metres of motion.
pub const MERGE_M: f64 = 2.0 * SAG_HALF_M + BIN_M;

/// The nominal gyro: angle noise, rad/√s, and the error of the windowed bias, rad/s. They
/// weigh runs and bins against each other; the threshold is set on the bins' own spread.
const ANGLE_NOISE: f64 = 1e-4;
const BIAS_ERROR: f64 = 5e-5;

/// A stretch whose fixes were set aside: the runs' motion disagreed with their shape.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SetAside {
    pub from_m: f64,
    pub to_m: f64,
    /// The largest offset of the fixes' line from the runs' motion there, m.
    pub peak_m: f64,
}

/// One run's discrepancy per bin: Σ residual turn (rad), the information it carries.
#[derive(Debug, Default, Clone, Copy)]
struct Bin {
    /// Σ w·δψ and Σ w over runs.
    weighted: f64,
    weight: f64,
}

/// The stretches of `line` where the runs' turn contradicts the line's, their fixes placed
/// as `placed` (the fixes a fit uses; `None` for the rest).
pub fn suspect(line: &Line, runs: &[RunFixes], placed: &[Vec<Option<OnLine>>]) -> Vec<SetAside> {
    let start = line.start_m();
    let count = ((line.end_m() - start) / BIN_M).ceil().max(1.0) as usize;
    let mut bins = vec![Bin::default(); count];
    for (run, p) in runs.iter().zip(placed) {
        for (bin, dpsi, t) in run_bins(line, run, p) {
            let var = ANGLE_NOISE * ANGLE_NOISE * t + (BIAS_ERROR * t).powi(2);
            if let Some(b) = bins.get_mut(bin) {
                b.weighted += dpsi / var;
                b.weight += 1.0 / var;
            }
        }
    }
    // Each bin's discrepancy and its variance (as weighed: the spread scales it).
    let seen: Vec<Option<(f64, f64)>> = bins
        .iter()
        .map(|b| (b.weight > 0.0).then(|| (b.weighted / b.weight, 1.0 / b.weight)))
        .collect();
    let spread = 1.4826
        * median(
            seen.iter()
                .flatten()
                .map(|(d, v)| (d / v.sqrt()).abs())
                .collect(),
        );
    let mut out: Vec<SetAside> = Vec::new();
    for i in 0..count {
        let Some((sag, var)) = sag(&seen, i) else {
            continue;
        };
        let z = sag / (var.sqrt() * spread);
        if z.abs() <= THRESHOLD || sag.abs() <= MIN_SAG_M {
            continue;
        }
        let (from, to) = (
            start + (i as f64 - 1.0) * BIN_M,
            start + (i as f64 + 2.0) * BIN_M,
        );
        match out.last_mut() {
            Some(s) if from - s.to_m <= MERGE_M => {
                s.to_m = to;
                s.peak_m = s.peak_m.max(sag.abs());
            }
            _ => out.push(SetAside {
                from_m: from,
                to_m: to,
                peak_m: sag.abs(),
            }),
        }
    }
    // One that comes within a chord of an end of the line runs to it (an end is seen only
    // from one side, its pull faintly) and takes in what lies just past it (where a train
    // stands at the end, its fixes a little beyond the line's last sample).
    let reach = 2.0 * SAG_HALF_M;
    for s in &mut out {
        if s.from_m <= start + reach {
            s.from_m = start - BIN_M;
        }
        if s.to_m >= line.end_m() - reach {
            s.to_m = line.end_m() + BIN_M;
        }
    }
    out
}

/// The line's offset from the runs' motion at bin `i`'s middle, against the chord over
/// [`SAG_HALF_M`] either side: the bins' heading-change discrepancies weighed by the Green's
/// function of `y'' = δκ` with `y = 0` at the chord's ends. Within that of an end of the line,
/// against the line's tangent [`SAG_HALF_M`] twice further in (`y = y' = 0` there): a pull at
/// the end has no far side. With its variance; `None` where fewer than half the bins have
/// data.
fn sag(bins: &[Option<(f64, f64)>], i: usize) -> Option<(f64, f64)> {
    let h = (SAG_HALF_M / BIN_M).round() as usize;
    let m = i as f64 + 0.5;
    // The window of bins and each one's lever on the offset at m (in bins).
    let (lo, hi, lever): (usize, usize, Box<dyn Fn(f64) -> f64>) = if i < h {
        (i, i + 2 * h, Box::new(move |s: f64| s - m))
    } else if i + h >= bins.len() {
        (i.checked_sub(2 * h)?, i, Box::new(move |s: f64| m - s))
    } else {
        let (a, b) = ((i - h) as f64, (i + h) as f64 + 1.0);
        let chord = move |s: f64| match s < m {
            true => (s - a) * (b - m) / (b - a),
            false => (m - a) * (b - s) / (b - a),
        };
        (i - h, i + h, Box::new(chord))
    };
    if hi >= bins.len() {
        return None;
    }
    let (mut sag, mut var, mut seen) = (0.0, 0.0, 0);
    for (j, bin) in bins.iter().enumerate().take(hi + 1).skip(lo) {
        let Some((d, v)) = bin else { continue };
        let g = BIN_M * lever(j as f64 + 0.5);
        sag += g * d;
        var += g * g * v;
        seen += 1;
    }
    (2 * seen > hi - lo + 1).then_some((sag, var))
}

/// One run's residual turn summed per bin while it moves: (bin, rad, s moving).
fn run_bins(line: &Line, run: &RunFixes, placed: &[Option<OnLine>]) -> Vec<(usize, f64, f64)> {
    let steps = &run.motion;
    if steps.len() < 2 {
        return Vec::new();
    }
    let chainage = step_chainage(run, placed);
    let heading = |s: f64| locate_on(&line.vertices, s).map_or(0.0, |(_, _, h)| h);
    // Each step's residual turn and duration, where it has a place on the line.
    let mut e = vec![0.0; steps.len()];
    let mut dt = vec![0.0; steps.len()];
    let mut valid = vec![false; steps.len()];
    for k in 1..steps.len() {
        let (Some(a), Some(b)) = (chainage[k - 1], chainage[k]) else {
            continue;
        };
        let d = (steps[k].stamp_ns - steps[k - 1].stamp_ns) as f64 / 1e9;
        if d > 0.5 {
            continue;
        }
        let line_turn = wrap(heading(b) - heading(a));
        e[k] = steps[k].turn_rad - line_turn;
        dt[k] = d;
        valid[k] = true;
    }
    // Prefix sums for the windowed bias.
    let mut se = vec![0.0; steps.len() + 1];
    let mut st = vec![0.0; steps.len() + 1];
    for k in 0..steps.len() {
        se[k + 1] = se[k] + if valid[k] { e[k] } else { 0.0 };
        st[k + 1] = st[k] + if valid[k] { dt[k] } else { 0.0 };
    }
    let window = (BIAS_WINDOW_S * 1e9) as u64;
    let start = line.start_m();
    let mut out: Vec<(usize, f64, f64)> = Vec::new();
    for k in 1..steps.len() {
        let moved = steps[k].distance_m > 0.0;
        let (Some(a), Some(b)) = (chainage[k - 1], chainage[k]) else {
            continue;
        };
        if !valid[k] || !moved || a == b {
            continue;
        }
        let t = steps[k].stamp_ns;
        let lo = steps.partition_point(|s| s.stamp_ns + window < t);
        let hi = steps.partition_point(|s| s.stamp_ns <= t + window);
        let span = st[hi] - st[lo];
        if span < BIAS_WINDOW_S {
            continue;
        }
        let bias = (se[hi] - se[lo]) / span;
        // In the line's own sense (towards increasing chainage).
        let r = (e[k] - bias * dt[k]) * (b - a).signum();
        let bin = (((a + b) / 2.0 - start) / BIN_M).floor().max(0.0) as usize;
        match out.last_mut() {
            Some(last) if last.0 == bin => {
                last.1 += r;
                last.2 += dt[k];
            }
            _ => out.push((bin, r, dt[k])),
        }
    }
    out
}

/// Each motion step's chainage: between the run's placed fixes around it, in proportion to
/// the distance run; `None` before the first and after the last.
fn step_chainage(run: &RunFixes, placed: &[Option<OnLine>]) -> Vec<Option<f64>> {
    let steps = &run.motion;
    let mut distance = Vec::with_capacity(steps.len());
    let mut d = 0.0;
    for s in steps {
        d += s.distance_m;
        distance.push(d);
    }
    // Distance run at a time, between the steps around it.
    let run_at = |t: u64| -> f64 {
        let i = steps.partition_point(|s| s.stamp_ns < t);
        if i == 0 {
            return 0.0;
        }
        if i >= steps.len() {
            return d;
        }
        let (a, b) = (&steps[i - 1], &steps[i]);
        let f = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns).max(1) as f64;
        distance[i - 1] + f * (distance[i] - distance[i - 1])
    };
    let anchors: Vec<(u64, f64, f64)> = run
        .fixes
        .iter()
        .zip(placed)
        .filter_map(|(f, m)| Some((f.stamp_ns, run_at(f.stamp_ns), m.as_ref()?.chainage_m)))
        .collect();
    steps
        .iter()
        .zip(&distance)
        .map(|(s, &dk)| {
            let j = anchors.partition_point(|a| a.0 <= s.stamp_ns);
            let (a, b) = (anchors.get(j.checked_sub(1)?)?, anchors.get(j)?);
            let run = b.1 - a.1;
            Some(match run > 1e-3 {
                true => a.2 + (b.2 - a.2) * ((dk - a.1) / run).clamp(0.0, 1.0),
                false => a.2,
            })
        })
        .collect()
}

/// The median of `x` (0 when empty).
pub(crate) fn median(mut x: Vec<f64>) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mid = x.len() / 2;
    *x.select_nth_unstable_by(mid, f64::total_cmp).1
}
