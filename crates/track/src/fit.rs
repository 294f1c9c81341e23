//! One centre line from the fixes of several runs.
//!
//! 1. The run that travels furthest seeds the line: its fixes, thinned to one every 2 m of
//!    travel (a standing train adds nothing), are fitted by the distance travelled.
//! 2. Every run's fixes are placed on that line in their order (a window around the last
//!    match, so a line that passes near itself is not jumped across): chainage and offset.
//!    A fix further off than `off_line_m` (plus three of its σ), or beyond the line's ends,
//!    is off the line; a run's stretch of such fixes is reported as leaving the line (a
//!    branch, a siding), not averaged in.
//! 3. The spline is refitted on every fix on the line by its chainage, weighted by its σ and
//!    down-weighted (Huber) where its offset stands out, with each run's motion across the
//!    gaps in its fixes ([`crate::bridge`]).
//! 4. Where the runs' gyros say the line bends and they did not (a steady multipath pull,
//!    [`crate::multipath`]), the fixes are set aside and the runs' motion crosses the stretch
//!    as a gap; then 2 and 3 again, four passes in all, so chainage becomes the fitted line's
//!    own arc length.
//!
//! Runs in either direction merge: a fix's place on the line does not depend on where the
//! train was heading.

use crate::bridge::{cross_gaps, Crossings};
use crate::error::{FitError, MIN_TRAVEL_M};
use crate::fixes::{Fix, RunFixes};
use crate::line::{Line, OnLine};
use crate::multipath::{self, median, SetAside};
use crate::report::{Centreline, Fitted};
use crate::spline::{Knots, PlaneSpline, Sample};

/// How the line is fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Knot spacing of the spline, m.
    pub knot_spacing_m: f64,
    /// Length the spline smooths over, m.
    pub smoothing_m: f64,
    /// A fix further than this (plus three of its σ) from the line is off it, m.
    pub off_line_m: f64,
    /// Cross the gaps in the fixes with each run's own motion (IMU turn, odometer distance);
    /// else the spline alone bridges them.
    pub cross_gaps: bool,
    /// Runs whose mean offsets over 100 m differ by more than this disagree there, m.
    pub disagreement_m: f64,
    /// Length of the stretches the residual is reported on, m.
    pub stretch_m: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            knot_spacing_m: 5.0,
            smoothing_m: 10.0,
            off_line_m: 0.5,
            cross_gaps: true,
            disagreement_m: 0.10,
            stretch_m: 500.0,
        }
    }
}

/// Fixes closer than this to the last one kept add nothing to the seed line, m.
const SEED_SPACING_M: f64 = 2.0;

/// A run needs this share of its fixes on the line to be on the same line.
const MIN_ON_LINE_SHARE: f64 = 0.2;

/// Passes over the runs: the fixes alone; with the gaps crossed by the runs' motion; with
/// the stretches that motion contradicts set aside (found on the line of the pass before,
/// [`crate::multipath`]); once more, so chainage is the final line's arc length.
const PASSES: usize = 4;

/// The pass that looks for stretches to set aside.
const SET_ASIDE_PASS: usize = 2;

/// Fits one centre line to `runs` (the first run sets chainage's origin and direction).
pub fn fit(runs: &[RunFixes], opts: &FitOptions) -> Result<Centreline, FitError> {
    let seed = seed_run(runs)?;
    let mut line = seed_line(&runs[seed], opts)?;
    let mut suspect: Vec<SetAside> = Vec::new();
    for pass in 0..PASSES {
        let placed = place_all(&line, runs, opts, &suspect);
        check_overlap(runs, &placed, &runs[seed].name)?;
        if pass == SET_ASIDE_PASS && opts.cross_gaps {
            suspect = multipath::suspect(&line, runs, &placed);
        }
        let aside = set_aside(&placed, &suspect);
        let mut samples = samples(runs, &placed, &aside, pass > 0);
        // Once the line holds where there are fixes, the runs' own motion crosses the gaps.
        if pass > 0 && opts.cross_gaps {
            for c in crossings(&line, runs, &placed, &aside) {
                samples.extend(c.samples);
            }
        }
        line = refit(&samples, opts)?;
    }
    let placed = place_all(&line, runs, opts, &suspect);
    check_overlap(runs, &placed, &runs[seed].name)?;
    let aside = set_aside(&placed, &suspect);
    let profile = crate::profile::fit(&mut line, runs, &placed, &aside);
    let cant = crate::cant::fit(&mut line, runs, &placed, &aside);
    let crossed = match opts.cross_gaps {
        true => crossings(&line, runs, &placed, &aside),
        false => Vec::new(),
    };
    let mut centreline = crate::report::finish(
        line,
        runs,
        Fitted {
            placed: &placed,
            aside: &aside,
            set_aside: suspect,
        },
        &crossed,
        opts.stretch_m,
        opts.disagreement_m,
    );
    centreline.profile = Some(profile);
    centreline.cant = Some(cant);
    Ok(centreline)
}

/// Which fixes of each run lie in a stretch set aside.
fn set_aside(placed: &[Vec<Option<OnLine>>], stretches: &[SetAside]) -> Vec<Vec<bool>> {
    let inside = |m: &Option<OnLine>| {
        m.is_some_and(|m| {
            stretches
                .iter()
                .any(|s| (s.from_m..=s.to_m).contains(&m.chainage_m))
        })
    };
    placed
        .iter()
        .map(|p| p.iter().map(inside).collect())
        .collect()
}

fn crossings(
    line: &Line,
    runs: &[RunFixes],
    placed: &[Vec<Option<OnLine>>],
    aside: &[Vec<bool>],
) -> Vec<Crossings> {
    runs.iter()
        .zip(placed)
        .zip(aside)
        .map(|((r, p), a)| cross_gaps(line, r, p, a))
        .collect()
}

/// The run that travels furthest.
fn seed_run(runs: &[RunFixes]) -> Result<usize, FitError> {
    let travel = |r: &RunFixes| {
        thin(&r.fixes)
            .windows(2)
            .map(|w| dist(w[0], w[1]))
            .sum::<f64>()
    };
    // The first run seeds the line unless another goes a tenth further.
    let (best, moved) = runs
        .iter()
        .enumerate()
        .map(|(i, r)| (i, travel(r)))
        .reduce(|a, b| if b.1 > 1.1 * a.1 { b } else { a })
        .ok_or(FitError::NoRuns)?;
    if moved < MIN_TRAVEL_M {
        return Err(FitError::TooShort {
            run: runs[best].name.clone(),
            moved_m: moved,
        });
    }
    Ok(best)
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// A run's fixes, one every [`SEED_SPACING_M`] of travel.
fn thin(fixes: &[Fix]) -> Vec<(f64, f64)> {
    let mut kept: Vec<(f64, f64)> = Vec::new();
    for f in fixes {
        let p = (f.east_m, f.north_m);
        if kept.last().is_none_or(|&q| dist(p, q) >= SEED_SPACING_M) {
            kept.push(p);
        }
    }
    kept
}

/// The seed run's thinned fixes, fitted by the distance travelled along them.
fn seed_line(run: &RunFixes, opts: &FitOptions) -> Result<Line, FitError> {
    let path = Line::through(&thin(&run.fixes));
    let samples: Vec<Sample> = path
        .vertices
        .iter()
        .map(|v| Sample {
            chainage_m: v.chainage_m,
            east_m: v.east_m,
            north_m: v.north_m,
            weight: 1.0,
        })
        .collect();
    let (from, to) = (path.start_m(), path.end_m());
    let spline = PlaneSpline::fit(
        Knots::covering(from, to, opts.knot_spacing_m),
        &samples,
        opts.smoothing_m,
    )?;
    Ok(Line::from_spline(&spline, from, to))
}

/// How far beyond the pull the runs' motion saw in a stretch set aside its fixes may lie: the
/// offset seen against a chord 300 m long is a third of a 600 m pull's.
const PULL_REACH: f64 = 3.0;

/// Where each fix of each run lies on `line`: `None` where it is off the line. In a stretch
/// set aside a fix may lie further off, by [`PULL_REACH`] times the pull the runs' motion saw
/// there.
fn place_all(
    line: &Line,
    runs: &[RunFixes],
    opts: &FitOptions,
    aside: &[SetAside],
) -> Vec<Vec<Option<OnLine>>> {
    let pull = |s: f64| {
        aside
            .iter()
            .find(|a| (a.from_m..=a.to_m).contains(&s))
            .map_or(0.0, |a| PULL_REACH * a.peak_m)
    };
    runs.iter()
        .map(|run| {
            let mut last: Option<f64> = None;
            run.fixes
                .iter()
                .map(|f| {
                    let limit = opts.off_line_m + 3.0 * f.sigma_m;
                    let on = |m: &OnLine| {
                        !m.beyond_end && m.lateral_m.abs() <= limit + pull(m.chainage_m)
                    };
                    // Near the last match first; after a gap (a tunnel, an excursion) the
                    // train may be anywhere along the line.
                    let m = line
                        .locate(f.east_m, f.north_m, last)
                        .filter(on)
                        .or_else(|| line.locate(f.east_m, f.north_m, None).filter(on))?;
                    last = Some(m.chainage_m);
                    Some(m)
                })
                .collect()
        })
        .collect()
}

fn check_overlap(
    runs: &[RunFixes],
    placed: &[Vec<Option<OnLine>>],
    seed: &str,
) -> Result<(), FitError> {
    for (run, p) in runs.iter().zip(placed) {
        let on_line = p.iter().flatten().count();
        if (on_line as f64) < MIN_ON_LINE_SHARE * run.fixes.len() as f64 {
            return Err(FitError::NoOverlap {
                run: run.name.clone(),
                seed: seed.to_owned(),
                fixes: run.fixes.len(),
                on_line,
            });
        }
    }
    Ok(())
}

/// The fixes on the line as spline samples at their chainage, weighted by 1/σ², and (once
/// `robust`) down-weighted where their offset stands out of their own σ (Huber, beyond 2.5
/// times the robust spread of the offsets in σ: a receiver whose σ is honest keeps its
/// weight, fixes pulled by multipath lose theirs).
fn samples(
    runs: &[RunFixes],
    placed: &[Vec<Option<OnLine>>],
    aside: &[Vec<bool>],
    robust: bool,
) -> Vec<Sample> {
    let fixes = || {
        runs.iter()
            .zip(placed)
            .zip(aside)
            .flat_map(|((run, p), a)| run.fixes.iter().zip(p).zip(a))
            .filter(|(_, aside)| !**aside)
            .filter_map(|((f, m), _)| Some((f, m.as_ref()?)))
    };
    let normalised: Vec<f64> = fixes()
        .map(|(f, m)| (m.lateral_m / f.sigma_m).abs())
        .collect();
    let k = 2.5 * (1.4826 * median(normalised)).max(1.0);
    fixes()
        .map(|(f, m)| {
            let z = (m.lateral_m / f.sigma_m).abs();
            let mut weight = 1.0 / (f.sigma_m * f.sigma_m).max(1e-6);
            if robust && z > k {
                weight *= k / z;
            }
            Sample {
                chainage_m: m.chainage_m,
                east_m: f.east_m,
                north_m: f.north_m,
                weight,
            }
        })
        .collect()
}

/// The spline through `samples`, over their chainage span.
fn refit(samples: &[Sample], opts: &FitOptions) -> Result<Line, FitError> {
    let (from, to) = samples.iter().fold((f64::MAX, f64::MIN), |(a, b), s| {
        (a.min(s.chainage_m), b.max(s.chainage_m))
    });
    let spline = PlaneSpline::fit(
        Knots::covering(from, to, opts.knot_spacing_m),
        samples,
        opts.smoothing_m,
    )?;
    Ok(Line::from_spline(&spline, from, to))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::MotionStep;

    /// A line: 300 m straight east, a 400 m arc of radius 400 m to the left, 300 m straight.
    fn true_point(s: f64) -> (f64, f64) {
        let r = 400.0;
        if s <= 300.0 {
            return (s, 0.0);
        }
        let a = ((s - 300.0).min(400.0)) / r;
        let (e, n) = (300.0 + r * a.sin(), r - r * a.cos());
        if s <= 700.0 {
            return (e, n);
        }
        (e + (s - 700.0) * a.cos(), n + (s - 700.0) * a.sin())
    }

    /// Fixes every 3 m with 2 cm of Gaussian noise each way (seeded); `offset(s)` moves a
    /// fix to the left of the line (a branch).
    fn run(name: &str, seed: u64, offset: impl Fn(f64) -> f64) -> RunFixes {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 0.02).unwrap();
        let fixes = (0..=333)
            .map(|i| {
                let s = i as f64 * 3.0;
                let (e, n) = true_point(s);
                let (e2, n2) = true_point(s + 0.1);
                let (te, tn) = ((e2 - e) / 0.1, (n2 - n) / 0.1);
                // Left of the direction (te, tn) is (−tn, te).
                let off = offset(s) + noise.sample(&mut rng);
                let along = noise.sample(&mut rng);
                Fix {
                    stamp_ns: i as u64 * 100_000_000,
                    east_m: e - tn * off + along * te,
                    north_m: n + te * off + along * tn,
                    sigma_m: 0.02,
                    up_m: None,
                }
            })
            .collect();
        RunFixes {
            name: name.into(),
            fixes,
            ..RunFixes::default()
        }
    }

    #[test]
    fn runs_both_ways_merge_and_a_branch_is_reported_not_averaged_in() {
        let forward = run("forward", 1, |_| 0.0);
        let mut backward = run("backward", 2, |_| 0.0);
        backward.fixes.reverse();
        // Leaves at 500 m onto a branch that swings 20 m to the left, rejoining at 650 m.
        let branch = run("branch", 3, |s| {
            if (500.0..650.0).contains(&s) {
                20.0 * ((s - 500.0) / 150.0 * std::f64::consts::PI).sin()
            } else {
                0.0
            }
        });
        let c = fit(&[forward, backward, branch], &FitOptions::default()).unwrap();
        // The fitted line lies on the true one to centimetres; the most where the curvature
        // jumps from nothing to 1/400 m (no transition curve), which a spline smooths.
        let truth = Line::through(
            &(0..=2000)
                .map(|k| true_point(k as f64 * 0.5))
                .collect::<Vec<_>>(),
        );
        let off: Vec<f64> = c
            .line
            .vertices
            .iter()
            .filter(|v| (20.0..980.0).contains(&v.chainage_m))
            .map(|v| {
                truth
                    .locate(v.east_m, v.north_m, None)
                    .unwrap()
                    .lateral_m
                    .abs()
            })
            .collect();
        let worst = off.iter().copied().fold(0.0, f64::max);
        let rms = (off.iter().map(|x| x * x).sum::<f64>() / off.len() as f64).sqrt();
        assert!(
            worst < 0.08 && rms < 0.02,
            "fitted line {rms} m RMS, {worst} m at most off the true one"
        );
        // Its chainage is the length along it.
        let length = c.line.end_m() - c.line.start_m();
        // The ends are the outermost fixes, each 2 cm along.
        assert!(
            (length - 999.0).abs() < 0.15,
            "{length} m long, from {}",
            c.line.start_m()
        );
        assert!(c.runs[0].increasing && !c.runs[1].increasing);
        // The branch: one excursion from about 500 m to about 650 m, its fixes not used.
        let b = &c.runs[2];
        assert_eq!(b.leaves_line.len(), 1, "{:?}", b.leaves_line);
        let e = &b.leaves_line[0];
        assert!((e.from_m.unwrap() - 510.0).abs() < 15.0, "{e:?}");
        assert!((e.to_m.unwrap() - 640.0).abs() < 15.0, "{e:?}");
        assert!(e.largest_offset_m > 15.0);
        assert!(c.lateral_rms_m < 0.03, "{}", c.lateral_rms_m);
        assert!(c.disagreements.is_empty(), "{:?}", c.disagreements);
    }

    #[test]
    fn a_run_on_another_line_is_refused() {
        let here = run("here", 1, |_| 0.0);
        let mut elsewhere = run("elsewhere", 2, |_| 0.0);
        for f in &mut elsewhere.fixes {
            f.north_m += 5000.0;
        }
        let e = fit(&[here, elsewhere], &FitOptions::default()).unwrap_err();
        assert!(
            matches!(e, FitError::NoOverlap { ref run, .. } if run == "elsewhere"),
            "{e}"
        );
    }

    #[test]
    fn a_fit_that_cannot_keep_its_promise_says_where() {
        // Fixes 0.3 m either side of the line between 600 and 900 m that claim 2 cm (a
        // receiver in multipath does not know).
        let mut r = run("noisy", 1, |_| 0.0);
        for (i, f) in r.fixes.iter_mut().enumerate() {
            if (200..300).contains(&i) {
                f.north_m += if i % 2 == 0 { 0.3 } else { -0.3 };
            }
        }
        let c = fit(&[r], &FitOptions::default()).unwrap();
        let e = c.check(0.10, |s| s).unwrap_err();
        let FitError::Tolerance { from_m, rms_m, .. } = e else {
            panic!("{e}")
        };
        assert!((500.0..=1000.0).contains(&from_m) && rms_m > 0.1, "{e}");
    }

    /// A run due east at 20 m/s for 150 s (3 km): fixes at 10 Hz with 2 cm of noise, pulled
    /// `pull_m` to the left over 1200–1800 m (a raised cosine, as a station building's
    /// multipath), and its motion: a gyro with a bias and white noise, an odometer.
    fn straight_run(seed: u64, pull_m: f64) -> RunFixes {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let fix_noise = Normal::new(0.0, 0.02).unwrap();
        let turn_noise = Normal::new(0.0, 1e-4 * 0.1f64.sqrt()).unwrap();
        let bias = 3e-4 * (seed as f64 - 2.0);
        let pull = |s: f64| match (1200.0..1800.0).contains(&s) {
            true => pull_m * 0.5 * (1.0 - ((s - 1200.0) / 600.0 * std::f64::consts::TAU).cos()),
            false => 0.0,
        };
        let fixes = (0..=1500)
            .map(|i| {
                let s = i as f64 * 2.0;
                Fix {
                    stamp_ns: i as u64 * 100_000_000,
                    east_m: s + fix_noise.sample(&mut rng),
                    north_m: pull(s) + fix_noise.sample(&mut rng),
                    sigma_m: 0.02,
                    up_m: None,
                }
            })
            .collect();
        let motion = (1..=1500)
            .map(|i| MotionStep {
                stamp_ns: i as u64 * 100_000_000,
                distance_m: 2.0,
                turn_rad: bias * 0.1 + turn_noise.sample(&mut rng),
            })
            .collect();
        RunFixes {
            name: format!("run{seed}"),
            fixes,
            motion,
            ..RunFixes::default()
        }
    }

    /// The fitted line's offset to the north (left of east) at `east_m`.
    fn north_at(c: &Centreline, east_m: f64) -> f64 {
        let v = &c.line.vertices;
        let i = v.partition_point(|p| p.east_m < east_m).min(v.len() - 1);
        v[i].north_m
    }

    #[test]
    fn fixes_the_runs_motion_contradicts_are_set_aside_and_crossed() {
        let runs: Vec<RunFixes> = (1..=3).map(|seed| straight_run(seed, 3.0)).collect();
        let c = fit(&runs, &FitOptions::default()).unwrap();
        // One stretch set aside, around the pull; the line straight through it.
        assert_eq!(c.set_aside.len(), 1, "{:?}", c.set_aside);
        let a = c.set_aside[0];
        let start = c.line.start_m();
        let (from, to) = (a.from_m - start, a.to_m - start);
        assert!(
            (1050.0..=1260.0).contains(&from) && (1740.0..=1950.0).contains(&to),
            "{a:?}"
        );
        assert!(a.peak_m > 1.0, "{a:?}");
        for e in [1300.0, 1500.0, 1700.0] {
            assert!(north_at(&c, e).abs() < 0.10, "{} m at {e}", north_at(&c, e));
        }
        assert!(c.runs.iter().all(|r| r.set_aside > 200 && r.off_line == 0));
        assert!(c.lateral_rms_m < 0.03, "{}", c.lateral_rms_m);
        // Without the runs' motion the line follows the pull.
        let no_motion = FitOptions {
            cross_gaps: false,
            ..FitOptions::default()
        };
        let pulled = fit(&runs, &no_motion).unwrap();
        assert!(pulled.set_aside.is_empty());
        assert!(
            north_at(&pulled, 1500.0) > 2.5,
            "{}",
            north_at(&pulled, 1500.0)
        );
        // Without a pull nothing is set aside.
        let clean: Vec<RunFixes> = (1..=3).map(|seed| straight_run(seed, 0.0)).collect();
        let c = fit(&clean, &FitOptions::default()).unwrap();
        assert!(c.set_aside.is_empty(), "{:?}", c.set_aside);
    }
}
