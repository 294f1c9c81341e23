//! Across a stretch where a run has no fix (a tunnel, a stretch without RTK) or whose fixes
//! were set aside ([`crate::multipath`]), its own motion carries the line's shape: the turn
//! its gyro measured and the distance its odometer ran, dead-reckoned through the gap. A run
//! that starts or ends in a stretch set aside is crossed from its fixes on the one side
//! ([`Tied`]).
//!
//! Dead reckoning alone drifts (a gyro bias turns the path by a growing angle, a worn wheel
//! stretches it), so each crossing is tied to the run's fixes on both sides, over
//! [`TIE_S`] before the gap and after it, and to the receiver's Doppler course and the
//! train's standstills in between ([`crate::tie`]: start, heading, distance scale and the
//! gyro's wandering bias, by least squares). The heading and bias come from the fixes
//! either side and the gap's far end together, not from the line's tangent at the gap's
//! ends, whose milliradian error would bend a 2 km crossing by decimetres. A crossing that
//! needs a scale or a bias no sensor has, or leaves its tie fixes more than
//! [`MAX_TIE_RMS_M`] off, is refused. The path through the gap becomes samples of the line
//! every 5 m, weighted as a fix of [`BRIDGE_SIGMA_M`]; several runs' crossings average.

use crate::fixes::{Fix, RunFixes};
use crate::line::{Line, OnLine};
use crate::spline::Sample;
use crate::tie::{at, standstill_bias, Point, Tie, BIAS, SCALE};

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

/// Fixes this long before a gap and after it tie its crossing, s.
pub const TIE_S: f64 = 5.0;

/// A crossing whose tie fixes are further off than this across the track (RMS) is refused,
/// m.
const MAX_TIE_RMS_M: f64 = 0.15;

/// A point of a crossing: distance run from the gap's first fix, and position.
type PathPoint = (f64, f64, f64);

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
    let (c0, c1) = (
        run.courses.partition_point(|c| c.stamp_ns < start_ns),
        run.courses.partition_point(|c| c.stamp_ns <= end_ns),
    );
    let tie = Tie {
        steps,
        start_ns,
        fixes: &tie_fixes,
        courses: &run.courses[c0..c1],
        standstill: standstill_bias(steps, start_ns, MIN_STANDSTILL_S),
    };
    let first = tie_fixes.first()?;
    let x = tie.start(first.east_m, first.north_m, psi0);
    let mut free = vec![true; x.len()];
    // Fixes on one side only cannot tell the odometer's scale.
    free[SCALE] = tied == Tied::BothSides;
    let (x, rms) = tie.solve(x, &free)?;
    let plausible = (x[SCALE] - 1.0).abs() <= MAX_SCALE_ERROR
        && x[BIAS..].iter().all(|b| b.abs() <= MAX_GYRO_BIAS_RADPS);
    if !(plausible && rms <= MAX_TIE_RMS_M) {
        return None;
    }
    Some(between(&tie.reckon(&x), fa.stamp_ns, fb.stamp_ns))
}

/// The reckoned `path` from `from_ns` to `to_ns`, as points with the distance run from the
/// first.
fn between(path: &[Point], from_ns: u64, to_ns: u64) -> Vec<PathPoint> {
    let (a, b) = (at(path, from_ns), at(path, to_ns));
    let (a, b) = ((a.0, a.1), (b.0, b.1));
    let mut d = 0.0;
    let mut last = a;
    let mut out = vec![(0.0, a.0, a.1)];
    for &(t, e, n) in path {
        if t <= from_ns || t >= to_ns {
            continue;
        }
        d += (e - last.0).hypot(n - last.1);
        last = (e, n);
        out.push((d, e, n));
    }
    d += (b.0 - last.0).hypot(b.1 - last.1);
    out.push((d, b.0, b.1));
    out
}

/// A standstill this long gives the gyro's bias, s.
const MIN_STANDSTILL_S: f64 = 5.0;

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
    use crate::fixes::Course;
    use crate::motion::MotionStep;

    /// The crossing of `run`'s gap that opens after its fix at 29.9 s, setting out east.
    fn cross_from_29_9_s_facing_east(run: &RunFixes) -> Vec<PathPoint> {
        let gap = run
            .fixes
            .iter()
            .position(|f| f.stamp_ns >= 29_900_000_000)
            .unwrap();
        let aside = vec![false; run.fixes.len()];
        cross(
            run,
            (gap, gap + 1),
            &aside,
            Tied::BothSides,
            std::f64::consts::FRAC_PI_2,
        )
        .expect("crosses")
    }

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
                    up_m: None,
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
            ..RunFixes::default()
        };
        let path = cross_from_29_9_s_facing_east(&run);
        let worst = path
            .iter()
            .map(|&(_, e, n)| (e.hypot(n + r) - r).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.02, "the crossing leaves the curve by {worst} m");
        let length = path.last().unwrap().0;
        // From the fix at 29.9 s to the one at 90 s.
        assert!((length - 1202.0).abs() < 0.5, "{length} m");
    }

    /// A run due east at 20 m/s with no fix from 30 s to 120 s (1.8 km); its gyro's bias
    /// wanders (5e-4 rad/s, a period of 80 s); with `courses`, the receiver's course (2 mrad
    /// of noise) through the gap. How far the crossing leaves the straight, m.
    fn wandering_crossing(courses: bool) -> f64 {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 0.002).unwrap();
        let ns = |t: f64| (t * 1e9).round() as u64;
        let fixes: Vec<Fix> = (0..=1500)
            .map(|i| i as f64 * 0.1)
            .filter(|t| !(30.0..120.0).contains(t))
            .map(|t| Fix {
                stamp_ns: ns(t),
                east_m: 20.0 * t,
                north_m: 0.0,
                sigma_m: 0.02,
                up_m: None,
            })
            .collect();
        let bias = |t: f64| 5e-4 * (std::f64::consts::TAU * t / 80.0).sin();
        let motion = (1..=1500)
            .map(|i| {
                let t = i as f64 * 0.1;
                MotionStep {
                    stamp_ns: ns(t),
                    distance_m: 2.0,
                    turn_rad: bias(t - 0.05) * 0.1,
                }
            })
            .collect();
        let courses = (300..1200)
            .filter(|_| courses)
            .map(|i| Course {
                stamp_ns: ns(i as f64 * 0.1),
                course_rad: std::f64::consts::FRAC_PI_2 + noise.sample(&mut rng),
                speed_mps: 20.0,
            })
            .collect();
        let run = RunFixes {
            name: "straight".into(),
            fixes,
            motion,
            courses,
            ..RunFixes::default()
        };
        let path = cross_from_29_9_s_facing_east(&run);
        path.iter().map(|p| p.2.abs()).fold(0.0, f64::max)
    }

    #[test]
    fn the_receivers_course_steers_a_wandering_gyro_bias_through_a_gap() {
        let (with, without) = (wandering_crossing(true), wandering_crossing(false));
        // 0.14 m and 1.3 m when written.
        assert!(
            with < 0.2,
            "with the course the crossing leaves the line by {with} m"
        );
        assert!(
            without > 5.0 * with,
            "without the course {without} m, with it {with} m"
        );
    }
}
