//! Across a stretch where a run has no fix (a tunnel, a stretch without RTK) or whose fixes
//! were set aside ([`crate::multipath`]), its own motion carries the line's shape: the turn
//! its gyro measured and the distance its odometer ran, dead-reckoned through the gap. A run
//! that starts or ends in a stretch set aside is crossed from its fixes on the one side
//! ([`Tied`]).
//!
//! Dead reckoning alone drifts (a gyro bias turns the path by a growing angle, a worn wheel
//! stretches it), so each crossing is tied to the run's fixes on both sides, over
//! [`TIE_S`] before the gap and after it. Six unknowns, by Gauss–Newton least squares over
//! those fixes:
//!
//! ```text
//! ψ(t) = ψ₀ + Σ (turn − (b + ḃ τ) dτ),   p(t) = p₀ + k Σ d·(sin ψ, cos ψ)
//! ```
//!
//! (p₀, ψ₀ where the tie starts, b the gyro bias and ḃ its drift, k the distance scale: a
//! MEMS gyro's bias wanders over the minutes a crossing takes). The heading and bias come
//! from the fixes either side and the gap's far end together, not from the line's tangent at
//! the gap's ends, whose milliradian error would bend a 2 km crossing by decimetres. The tie
//! is short (5 s a side) because that bias wanders: on the default line's seeds 1–9, ties of
//! 5, 10, 20, 40 and 60 s left 0.04–0.13, 0.06–0.14, 0.10–0.19, 0.13–0.30 and 0.14–0.41 m RMS
//! in the gaps. A
//! crossing that needs a scale or a bias no sensor has, or leaves its tie fixes more than
//! [`MAX_TIE_RMS_M`] off, is refused. The path through the gap becomes samples of the line
//! every 5 m, weighted as a fix of [`BRIDGE_SIGMA_M`]; several runs' crossings average.

use crate::fixes::{Fix, RunFixes};
use crate::line::{Line, OnLine};
use crate::motion::MotionStep;
use crate::spline::Sample;

/// A gap in a run's fixes at least this long in time (s) and along the line (m) is crossed.
const MIN_GAP_S: f64 = 2.0;
const MIN_GAP_M: f64 = 30.0;

/// The motion must reach this close to both fixes, ns.
const MAX_EDGE_NS: u64 = 500_000_000;

/// A crossing's samples count as fixes of this σ, m.
pub const BRIDGE_SIGMA_M: f64 = 0.10;

/// A crossing's samples are this far apart, m of distance run.
const BRIDGE_STEP_M: f64 = 5.0;

/// Ties beyond these are refused: the distance scale off 1 by more than this, the gyro bias
/// beyond this (rad/s).
const MAX_SCALE_ERROR: f64 = 0.1;
const MAX_GYRO_BIAS_RADPS: f64 = 0.01;

/// The crossings of one run's gaps: the samples they give and the stretches they span.
#[derive(Debug, Default)]
pub struct Crossings {
    pub samples: Vec<Sample>,
    /// The chainage each crossing spans, from–to, m.
    pub spans: Vec<(f64, f64)>,
    /// Gaps it could not cross (no motion, or a closure no sensor explains).
    pub refused: usize,
}

/// The crossings of `run`'s gaps on `line`, its fixes placed as `placed`.
/// `aside` marks the fixes set aside (their stretch is crossed as a gap).
pub fn cross_gaps(
    line: &Line,
    run: &RunFixes,
    placed: &[Option<OnLine>],
    aside: &[bool],
) -> Crossings {
    let mut out = Crossings::default();
    if run.motion.is_empty() {
        return out;
    }
    for g in gaps(run, placed, aside) {
        let ((i, a), (j, b)) = (g.from, g.to);
        // Only where the run has no fix used: fixes off the line in between are an
        // excursion, not a gap to fill.
        if !(i + 1..j).all(|k| aside[k]) {
            continue;
        }
        let (fa, fb) = (run.fixes[i], run.fixes[j]);
        let gap_s = (fb.stamp_ns - fa.stamp_ns) as f64 / 1e9;
        if gap_s < MIN_GAP_S || (b.chainage_m - a.chainage_m).abs() < MIN_GAP_M {
            continue;
        }
        let psi0 = heading(line, a.chainage_m, b.chainage_m > a.chainage_m);
        match cross(run, (i, j), aside, g.tied, psi0) {
            Some(path) => {
                out.samples
                    .extend(samples(&path, a.chainage_m, b.chainage_m));
                out.spans.push((
                    a.chainage_m.min(b.chainage_m),
                    a.chainage_m.max(b.chainage_m),
                ));
            }
            None => out.refused += 1,
        }
    }
    out
}

/// A run's stretches between the fixes it uses on the line, and from the first (to the
/// last) where it starts (ends) in a stretch set aside: a station at the line's end, from
/// its first (last) fix there that its motion reaches.
fn gaps(run: &RunFixes, placed: &[Option<OnLine>], aside: &[bool]) -> Vec<Gap> {
    let on: Vec<(usize, &OnLine)> = placed
        .iter()
        .enumerate()
        .filter(|(i, _)| !aside[*i])
        .filter_map(|(i, m)| Some((i, m.as_ref()?)))
        .collect();
    let mut gaps: Vec<Gap> = on
        .windows(2)
        .map(|w| Gap {
            from: (w[0].0, *w[0].1),
            to: (w[1].0, *w[1].1),
            tied: Tied::BothSides,
        })
        .collect();
    let (m0, m1) = (
        run.motion[0].stamp_ns,
        run.motion[run.motion.len() - 1].stamp_ns,
    );
    let outer = |k: usize| {
        let reached = (m0 + MAX_EDGE_NS..m1).contains(&run.fixes[k].stamp_ns);
        placed[k].filter(|_| aside[k] && reached).map(|m| (k, m))
    };
    let (first_on, last_on) = match (on.first(), on.last()) {
        (Some(f), Some(l)) => (f.0, l.0),
        _ => return gaps,
    };
    let first_outer = (0..first_on).find_map(outer);
    let last_outer = (last_on + 1..placed.len()).rev().find_map(outer);
    if let (Some(&(i, a)), Some(first)) = (on.first(), first_outer) {
        gaps.push(Gap {
            from: first,
            to: (i, *a),
            tied: Tied::After,
        });
    }
    if let (Some(&(j, b)), Some(last)) = (on.last(), last_outer) {
        gaps.push(Gap {
            from: (j, *b),
            to: last,
            tied: Tied::Before,
        });
    }
    gaps
}

/// Which fixes tie a crossing: those either side of a gap, or only those after (before) a
/// stretch set aside where the run starts (ends).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Tied {
    BothSides,
    After,
    Before,
}

/// A stretch of a run to cross: from fix `from` to fix `to` (in time order), with their
/// places on the line.
struct Gap {
    from: (usize, OnLine),
    to: (usize, OnLine),
    tied: Tied,
}

/// The line's heading (clockwise from north) at `s`, the way a train travelling towards
/// increasing chainage (or not) faces.
fn heading(line: &Line, s: f64, increasing: bool) -> f64 {
    use railfuse_catalog::map_matching::locate_on;
    let h = locate_on(&line.vertices, s).map_or(0.0, |(_, _, h)| h);
    if increasing {
        h
    } else {
        h + std::f64::consts::PI
    }
}

/// The tie's unknowns: start east, north, heading, gyro bias, its drift, distance scale.
const N: usize = 6;

/// Fixes this long before a gap and after it tie its crossing, s.
pub const TIE_S: f64 = 5.0;

/// A crossing whose tie fixes are further off than this across the track (RMS) is refused,
/// m.
const MAX_TIE_RMS_M: f64 = 0.15;

/// A point of a crossing: distance run from the gap's first fix, and position.
type PathPoint = (f64, f64, f64);

/// The dead-reckoned positions at each step's end from `x = [e₀, n₀, ψ₀, b, ḃ, k]`.
fn reckon(steps: &[MotionStep], start_ns: u64, x: &[f64; N]) -> Vec<(u64, f64, f64)> {
    let [e0, n0, psi0, bias, drift, scale] = *x;
    let (mut p, mut turn, mut last_ns) = ((e0, n0), 0.0, start_ns);
    let mut out = Vec::with_capacity(steps.len() + 1);
    out.push((start_ns, e0, n0));
    for s in steps {
        let dt = (s.stamp_ns - last_ns) as f64 / 1e9;
        let mid = ((last_ns + s.stamp_ns) / 2 - start_ns) as f64 / 1e9;
        last_ns = s.stamp_ns;
        let step_turn = s.turn_rad - (bias + drift * mid) * dt;
        let psi = psi0 + turn + step_turn / 2.0;
        turn += step_turn;
        let len = scale * s.distance_m;
        p = (p.0 + len * psi.sin(), p.1 + len * psi.cos());
        out.push((s.stamp_ns, p.0, p.1));
    }
    out
}

/// The reckoned position at `t_ns`, between the steps around it, and the unit direction of
/// travel there.
fn at(path: &[(u64, f64, f64)], t_ns: u64) -> (f64, f64, f64, f64) {
    let i = path
        .partition_point(|p| p.0 < t_ns)
        .clamp(1, path.len() - 1);
    let (a, b) = (path[i - 1], path[i]);
    let f = if b.0 > a.0 {
        ((t_ns.saturating_sub(a.0)) as f64 / (b.0 - a.0) as f64).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (de, dn) = (b.1 - a.1, b.2 - a.2);
    let len = de.hypot(dn).max(1e-9);
    (a.1 + f * de, a.2 + f * dn, de / len, dn / len)
}

/// Along the track a tie fix counts this much of its miss: an odometer slides when the train
/// brakes and its distance is then off by metres, which says nothing of the line's shape.
const ALONG_WEIGHT: f64 = 0.05;

/// What a crossing is tied to: its fixes, and where the train stood, the gyro's bias then.
struct Tie<'a> {
    steps: &'a [MotionStep],
    start_ns: u64,
    fixes: &'a [Fix],
    /// The bias the gyro read standing (rad/s) and when (s from `start_ns`).
    standstill: Option<(f64, f64)>,
}

/// A standstill's bias counts as a miss of this many metres per rad/s: 1 cm for 1e-5
/// rad/s, a tenth of what a MEMS gyro's bias wanders in a minute.
const STANDSTILL_WEIGHT: f64 = 1e3;

impl Tie<'_> {
    /// The tie fixes' misses (along the track, weighted by [`ALONG_WEIGHT`], and across) for
    /// `x`, then the standstill's.
    fn misses(&self, x: &[f64; N]) -> Vec<f64> {
        let path = reckon(self.steps, self.start_ns, x);
        let fixes = self.fixes.iter().flat_map(|f| {
            let (e, n, ue, un) = at(&path, f.stamp_ns);
            let (me, mn) = (e - f.east_m, n - f.north_m);
            [ALONG_WEIGHT * (me * ue + mn * un), me * un - mn * ue]
        });
        let standstill = self
            .standstill
            .map(|(bias, t)| STANDSTILL_WEIGHT * (x[3] + x[4] * t - bias));
        fixes.chain(standstill).collect()
    }

    /// Gauss–Newton from `x` (the parameters not `free` kept as they are); the parameters and
    /// the fixes' misses across the track (RMS).
    fn solve(&self, mut x: [f64; N], free: [bool; N]) -> Option<([f64; N], f64)> {
        for _ in 0..8 {
            let r = self.misses(&x);
            let mut jt: Vec<Vec<f64>> = Vec::with_capacity(N);
            for (k, h) in [1e-3, 1e-3, 1e-6, 1e-8, 1e-10, 1e-6]
                .into_iter()
                .enumerate()
            {
                let mut xh = x;
                xh[k] += h;
                let rh = self.misses(&xh);
                jt.push(rh.iter().zip(&r).map(|(a, b)| (a - b) / h).collect());
            }
            // Normal equations JᵀJ dx = −Jᵀr.
            let mut a = [[0.0; N]; N];
            let mut g = [0.0; N];
            for i in 0..N {
                for j in 0..N {
                    a[i][j] = match free[i] && free[j] {
                        true => jt[i].iter().zip(&jt[j]).map(|(p, q)| p * q).sum(),
                        false => f64::from(u8::from(i == j)),
                    };
                }
                if free[i] {
                    g[i] = -jt[i].iter().zip(&r).map(|(p, q)| p * q).sum::<f64>();
                }
            }
            let dx = solve(a, g)?;
            for k in 0..N {
                x[k] += dx[k];
            }
        }
        let r = self.misses(&x);
        let cross = r[..2 * self.fixes.len()].iter().skip(1).step_by(2);
        let rms = (cross.map(|e| e * e).sum::<f64>() / self.fixes.len() as f64).sqrt();
        Some((x, rms))
    }
}

/// `A x = b` for a small symmetric positive definite `A` (Gaussian elimination with partial
/// pivoting); `None` if it is singular.
#[allow(clippy::needless_range_loop)] // Elimination reads clearest with indices.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for c in 0..N {
        let p = (c..N).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if !a[p][c].is_normal() {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..N {
            let f = a[r][c] / a[c][c];
            for k in c..N {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let s: f64 = (r + 1..N).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

/// The crossing of the gap between fixes `i` and `j` of `run`, tied to its fixes as `tied`
/// says (not those set `aside`), as points from the gap's first fix to its last; `None`
/// where the motion does not cover it or the tie fails.
///
/// A crossing tied on one side only (a run that starts or stops in a stretch set aside) has
/// no fixes on the far side to bound the gyro's bias there: where the train stood long
/// enough ([`MIN_STANDSTILL_S`]), the gyro's mean rate then ties the bias's drift (a train
/// that stands does not turn); else the bias is taken constant. The odometer's scale is kept:
/// ten seconds of fixes cannot tell it.
fn cross(
    run: &RunFixes,
    (i, j): (usize, usize),
    aside: &[bool],
    tied: Tied,
    psi0: f64,
) -> Option<Vec<PathPoint>> {
    let (fa, fb) = (run.fixes[i], run.fixes[j]);
    let tie_ns = (TIE_S * 1e9) as u64;
    let (from_ns, to_ns) = match tied {
        Tied::BothSides => (fa.stamp_ns.saturating_sub(tie_ns), fb.stamp_ns + tie_ns),
        Tied::After => (fb.stamp_ns, fb.stamp_ns + 2 * tie_ns),
        Tied::Before => (fa.stamp_ns.saturating_sub(2 * tie_ns), fa.stamp_ns),
    };
    let lo = run.fixes.partition_point(|f| f.stamp_ns < from_ns);
    let hi = run.fixes.partition_point(|f| f.stamp_ns <= to_ns);
    let tie_fixes: Vec<Fix> = (lo..hi)
        .filter(|&k| !aside[k])
        .map(|k| run.fixes[k])
        .collect();
    // The motion from the earlier of the first tie fix and the gap's start, covering both.
    let first_ns = tie_fixes.first()?.stamp_ns.min(fa.stamp_ns);
    let end_ns = tie_fixes.last()?.stamp_ns.max(fb.stamp_ns);
    // From the end of the step before the first tie fix (a step's motion is all before its
    // stamp), to the step after the last.
    let s0 = run
        .motion
        .partition_point(|s| s.stamp_ns <= first_ns)
        .checked_sub(1)?;
    let start_ns = run.motion[s0].stamp_ns;
    let s1 = (run.motion.partition_point(|s| s.stamp_ns <= end_ns) + 1).min(run.motion.len());
    let steps = &run.motion[s0 + 1..s1];
    // Motion from before `t` (the steps' start) to a step within reach after it.
    let covers = |t: u64| {
        let k = steps.partition_point(|s| s.stamp_ns < t);
        t >= start_ns && k < steps.len() && steps[k].stamp_ns - t <= MAX_EDGE_NS
    };
    if steps.is_empty() || !covers(fa.stamp_ns) || !covers(fb.stamp_ns) {
        return None;
    }
    let first = tie_fixes.first()?;
    let x = [first.east_m, first.north_m, psi0, 0.0, 0.0, 1.0];
    let mut free = [true; N];
    let mut tie = Tie {
        steps,
        start_ns,
        fixes: &tie_fixes,
        standstill: None,
    };
    if tied != Tied::BothSides {
        // The odometer's scale kept; the bias where the train stood ties its far end.
        free[5] = false;
        tie.standstill = standstill_bias(steps, start_ns);
        free[4] = tie.standstill.is_some();
    }
    let (x, rms) = tie.solve(x, free)?;
    let plausible = (x[5] - 1.0).abs() <= MAX_SCALE_ERROR && x[3].abs() <= MAX_GYRO_BIAS_RADPS;
    if !(plausible && rms <= MAX_TIE_RMS_M) {
        return None;
    }
    let path = reckon(steps, start_ns, &x);
    let (a, b) = (at(&path, fa.stamp_ns), at(&path, fb.stamp_ns));
    let (a, b) = ((a.0, a.1), (b.0, b.1));
    let mut d = 0.0;
    let mut last = a;
    let mut out = vec![(0.0, a.0, a.1)];
    for &(t, e, n) in &path {
        if t <= fa.stamp_ns || t >= fb.stamp_ns {
            continue;
        }
        d += (e - last.0).hypot(n - last.1);
        last = (e, n);
        out.push((d, e, n));
    }
    d += (b.0 - last.0).hypot(b.1 - last.1);
    out.push((d, b.0, b.1));
    Some(out)
}

/// A standstill this long gives the gyro's bias, s.
const MIN_STANDSTILL_S: f64 = 5.0;

/// The gyro's mean rate over the steps where the train stood, and their mean time (s from
/// `start_ns`), if it stood long enough.
fn standstill_bias(steps: &[MotionStep], start_ns: u64) -> Option<(f64, f64)> {
    let (mut turn, mut time, mut when, mut last) = (0.0, 0.0, 0.0, start_ns);
    for s in steps {
        let dt = (s.stamp_ns - last) as f64 / 1e9;
        if s.distance_m == 0.0 {
            turn += s.turn_rad;
            time += dt;
            when += dt * ((s.stamp_ns - start_ns) as f64 / 1e9 - dt / 2.0);
        }
        last = s.stamp_ns;
    }
    (time >= MIN_STANDSTILL_S).then(|| (turn / time, when / time))
}

/// Samples of a closed path every [`BRIDGE_STEP_M`], at chainage in proportion to the
/// distance run between the gap's ends.
fn samples(path: &[PathPoint], from_m: f64, to_m: f64) -> Vec<Sample> {
    let total = path.last().map_or(0.0, |p| p.0);
    let weight = 1.0 / (BRIDGE_SIGMA_M * BRIDGE_SIGMA_M);
    let mut next = BRIDGE_STEP_M;
    let mut out = Vec::new();
    for &(d, e, n) in path {
        if d >= next && d < total - BRIDGE_STEP_M / 2.0 {
            out.push(Sample {
                chainage_m: from_m + (to_m - from_m) * d / total,
                east_m: e,
                north_m: n,
                weight,
            });
            next = d + BRIDGE_STEP_M;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_biased_gyro_and_a_worn_wheel_cross_a_gap_tied_to_the_fixes_either_side() {
        // 20 m/s along a 1200 m radius curve to the right, heading east at first; no fix
        // from 30 s to 90 s (1.2 km). The gyro reads 0.001 rad/s high, drifting by 1e-5
        // rad/s each second; the wheel reads 2 % long.
        let (r, v) = (1200.0, 20.0);
        let point = |t: f64| {
            let a = v * t / r;
            (r * a.sin(), -r * (1.0 - a.cos()))
        };
        let fixes: Vec<Fix> = (0..=1200)
            .map(|i| i as f64 * 0.1)
            .filter(|t| !(30.0..90.0).contains(t))
            .map(|t| {
                let (e, n) = point(t);
                Fix {
                    stamp_ns: (t * 1e9) as u64,
                    east_m: e,
                    north_m: n,
                    sigma_m: 0.02,
                }
            })
            .collect();
        let motion: Vec<MotionStep> = (1..=1200)
            .map(|i| {
                let t = i as f64 * 0.1;
                MotionStep {
                    stamp_ns: (t * 1e9) as u64,
                    distance_m: 1.02 * v * 0.1,
                    turn_rad: (v / r + 0.001 + 1e-5 * t) * 0.1,
                }
            })
            .collect();
        let run = RunFixes {
            name: "curve".into(),
            fixes,
            motion,
        };
        let gap = run
            .fixes
            .iter()
            .position(|f| f.stamp_ns >= 29_900_000_000)
            .unwrap();
        let aside = vec![false; run.fixes.len()];
        let path = cross(
            &run,
            (gap, gap + 1),
            &aside,
            Tied::BothSides,
            std::f64::consts::FRAC_PI_2,
        )
        .expect("crosses");
        let worst = path
            .iter()
            .map(|&(_, e, n)| (e.hypot(n + r) - r).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.02, "the crossing leaves the curve by {worst} m");
        let length = path.last().unwrap().0;
        // From the fix at 29.9 s to the one at 90 s.
        assert!((length - 1202.0).abs() < 0.5, "{length} m");
    }
}
