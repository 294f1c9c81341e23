//! The track's height profile from the runs' fixes: the top of rail's height as a smooth
//! function of chainage, fitted as the centre line is ([`ProfileSpline`], the same penalised
//! spline on one coordinate) through every fix used for the line that has an altitude, the
//! antenna's height above the rail taken off by the fix reader.
//!
//! A receiver's height is about twice as noisy as its position in the plane, and multipath
//! pulls it further; so the fit is weighted by the fix's σ doubled, smoothed over
//! [`SMOOTHING_M`] (a vertical curve of 2 500 m bends the gradient by 4 ‰ over 10 m: the
//! smoothing leaves it), and refitted once without the fixes more than [`OUTLIER_SIGMAS`]
//! robust σ off the first fit. A profile steeper than a line can be (over
//! [`MAX_GRADIENT`](railfuse_catalog::track_profile::MAX_GRADIENT)) says the heights are not
//! good enough: the line is then written flat, with the reason.

use railfuse_catalog::track_profile::MAX_GRADIENT;
use serde::Serialize;

use crate::fixes::RunFixes;
use crate::line::{Line, OnLine};
use crate::spline::{Knots, ProfileSpline};

/// Knot spacing of the height spline, m.
const KNOT_SPACING_M: f64 = 10.0;
/// How far the height profile is smoothed, m.
const SMOOTHING_M: f64 = 40.0;
/// Fixes further off the first fit than this many robust σ are left out of the second.
const OUTLIER_SIGMAS: f64 = 4.0;
/// A profile needs this share of the fixes used for the line to have a height.
const MIN_SHARE: f64 = 0.5;

/// What the height fit found.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Profile {
    /// The vertices have heights.
    Fitted {
        fixes: usize,
        /// Fixes left out as more than [`OUTLIER_SIGMAS`] robust σ off the first fit.
        outliers: usize,
        /// RMS of the heights used about the profile, m.
        residual_rms_m: f64,
        /// The steepest gradient of the profile (rise per metre) and where (line chainage).
        steepest_gradient: f64,
        steepest_at_m: f64,
    },
    /// Too few fixes have an altitude: the line is flat.
    NoHeights { with_height: usize, used: usize },
    /// The fitted profile is steeper than a line can be: the line is flat.
    TooSteep { gradient: f64, at_m: f64 },
}

impl Profile {
    /// With its chainages placed as the line's are (`chainage` of the fit's arc length).
    pub fn placed(self, chainage: impl Fn(f64) -> f64) -> Profile {
        match self {
            Profile::Fitted {
                steepest_at_m,
                fixes,
                outliers,
                residual_rms_m,
                steepest_gradient,
            } => Profile::Fitted {
                steepest_at_m: chainage(steepest_at_m),
                fixes,
                outliers,
                residual_rms_m,
                steepest_gradient,
            },
            Profile::TooSteep { gradient, at_m } => Profile::TooSteep {
                gradient,
                at_m: chainage(at_m),
            },
            other => other,
        }
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        match self {
            Profile::Fitted {
                fixes,
                outliers,
                residual_rms_m,
                steepest_gradient,
                steepest_at_m,
            } => format!(
                "heights from {fixes} fixes ({outliers} left out as outliers), residual RMS \
                 {residual_rms_m:.3} m, steepest {:.1} ‰ at {steepest_at_m:.0} m",
                steepest_gradient * 1e3
            ),
            Profile::NoHeights { with_height, used } => format!(
                "no heights: {with_height} of the {used} fixes used have an altitude (the line \
                 is flat)"
            ),
            Profile::TooSteep { gradient, at_m } => format!(
                "no heights: the fixes' heights give {:.0} ‰ at {at_m:.0} m, steeper than a \
                 line is (more than {:.0} ‰): too noisy to fit; the line is flat",
                gradient * 1e3,
                MAX_GRADIENT * 1e3
            ),
        }
    }
}

/// Fits the heights of `line`'s vertices from the fixes of `runs` placed on it (`placed`,
/// `None` off the line; `aside` the fixes set aside); on success the vertices have heights.
pub fn fit(
    line: &mut Line,
    runs: &[RunFixes],
    placed: &[Vec<Option<OnLine>>],
    aside: &[Vec<bool>],
) -> Profile {
    let mut used = 0;
    let mut points = Vec::new();
    for ((run, placed), aside) in runs.iter().zip(placed).zip(aside) {
        for ((f, p), a) in run.fixes.iter().zip(placed).zip(aside) {
            let Some(p) = p.filter(|_| !a) else { continue };
            used += 1;
            if let Some(up) = f.up_m {
                let sigma = 2.0 * f.sigma_m;
                points.push((p.chainage_m, 1.0 / (sigma * sigma), up));
            }
        }
    }
    if points.len() < 4 || (points.len() as f64) < MIN_SHARE * used as f64 {
        return Profile::NoHeights {
            with_height: points.len(),
            used,
        };
    }
    let Some(RobustFit { spline, kept, rms }) =
        robust_fit(line, &points, KNOT_SPACING_M, SMOOTHING_M)
    else {
        return Profile::NoHeights {
            with_height: points.len(),
            used,
        };
    };
    let (gradient, at_m) = steepest(line, &spline);
    if gradient.abs() > MAX_GRADIENT {
        return Profile::TooSteep { gradient, at_m };
    }
    for v in &mut line.vertices {
        v.height_m = Some(spline.at(v.chainage_m));
    }
    Profile::Fitted {
        fixes: kept,
        outliers: points.len() - kept,
        residual_rms_m: rms,
        steepest_gradient: gradient,
        steepest_at_m: at_m,
    }
}

/// A smooth function of chainage fitted through `(chainage, weight, value)` points over
/// `line`, and refitted once without the points more than [`OUTLIER_SIGMAS`] robust σ off the
/// first fit.
pub(crate) struct RobustFit {
    pub spline: ProfileSpline,
    /// Points kept in the second fit.
    pub kept: usize,
    /// RMS of the kept points about it.
    pub rms: f64,
}

/// [`RobustFit`] with knots every `knot_spacing_m`, smoothed over `smoothing_m`.
pub(crate) fn robust_fit(
    line: &Line,
    points: &[(f64, f64, f64)],
    knot_spacing_m: f64,
    smoothing_m: f64,
) -> Option<RobustFit> {
    let knots = Knots::covering(line.start_m(), line.end_m(), knot_spacing_m);
    let first = ProfileSpline::fit(knots, points, smoothing_m).ok()?;
    let residual = |s: &ProfileSpline, p: &(f64, f64, f64)| p.2 - s.at(p.0);
    let robust_sigma = 1.4826 * median(points.iter().map(|p| residual(&first, p).abs()));
    let limit = OUTLIER_SIGMAS * robust_sigma.max(1e-3);
    let kept: Vec<(f64, f64, f64)> = points
        .iter()
        .copied()
        .filter(|p| residual(&first, p).abs() <= limit)
        .collect();
    let spline = ProfileSpline::fit(knots, &kept, smoothing_m).unwrap_or(first);
    let rms = (kept
        .iter()
        .map(|p| residual(&spline, p).powi(2))
        .sum::<f64>()
        / kept.len().max(1) as f64)
        .sqrt();
    Some(RobustFit {
        spline,
        kept: kept.len(),
        rms,
    })
}

/// The steepest gradient between neighbouring vertices of `line` on the profile, and where.
fn steepest(line: &Line, spline: &ProfileSpline) -> (f64, f64) {
    line.vertices
        .windows(2)
        .filter(|w| w[1].chainage_m > w[0].chainage_m)
        .map(|w| {
            let (a, b) = (w[0].chainage_m, w[1].chainage_m);
            ((spline.at(b) - spline.at(a)) / (b - a), (a + b) / 2.0)
        })
        .max_by(|x, y| x.0.abs().total_cmp(&y.0.abs()))
        .unwrap_or((0.0, 0.0))
}

fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
