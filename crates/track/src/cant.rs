//! The track's cant from the runs' IMUs: each fix's cant (the body's roll the IMU measured,
//! less its lean, [`crate::lean`]) turned to the line's sense (a run travelling towards
//! decreasing chainage sees the other rail on its left), fitted as a smooth function of
//! chainage as the heights are ([`crate::profile::robust_fit`]), and written on the vertices
//! in metres over the standard 1 500 mm base.
//!
//! A cant ramp runs along a transition curve of 40–100 m, so the fit is smoothed over
//! [`SMOOTHING_M`] only, with knots every [`KNOT_SPACING_M`]. A line fitted from runs without
//! an IMU (or a vehicle to mount it by) has no cant.

use railfuse_catalog::track_profile::{MAX_CANT_M, STANDARD_CANT_BASE_M};
use serde::Serialize;

use crate::fixes::RunFixes;
use crate::line::{Line, OnLine};
use crate::profile::{robust_fit, RobustFit};

/// Knot spacing of the cant spline, m.
const KNOT_SPACING_M: f64 = 5.0;
/// How far the cant is smoothed, m.
const SMOOTHING_M: f64 = 10.0;
/// Fewer fixes with a cant than this say nothing of the line's.
const MIN_FIXES: usize = 100;

/// What the cant fit found.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Cant {
    /// The vertices have cant.
    Fitted {
        fixes: usize,
        /// RMS of the fixes' cant about the fit, m.
        residual_rms_m: f64,
        /// The largest cant on the line, m, and where (line chainage).
        largest_m: f64,
        largest_at_m: f64,
    },
    /// Too few fixes have a cant (no IMU, or no vehicle to mount it by).
    NoCant { with_cant: usize },
}

impl Cant {
    /// With its chainages placed as the line's are.
    pub fn placed(mut self, chainage: impl Fn(f64) -> f64) -> Cant {
        if let Cant::Fitted { largest_at_m, .. } = &mut self {
            *largest_at_m = chainage(*largest_at_m);
        }
        self
    }

    pub fn describe(&self) -> String {
        match self {
            Cant::Fitted {
                fixes,
                residual_rms_m,
                largest_m,
                largest_at_m,
            } => format!(
                "cant from {fixes} fixes' IMU roll, residual RMS {:.0} mm, largest {:+.0} mm at {:.0} m",
                residual_rms_m * 1e3,
                largest_m * 1e3,
                largest_at_m
            ),
            Cant::NoCant { with_cant } => format!(
                "no cant: {with_cant} fixes have an IMU roll (the runs need an IMU and a /vehicle)"
            ),
        }
    }
}

/// Fits the cant of `line`'s vertices from the fixes of `runs` placed on it (`placed`; `aside`
/// the fixes set aside); on success the vertices have cant.
pub fn fit(
    line: &mut Line,
    runs: &[RunFixes],
    placed: &[Vec<Option<OnLine>>],
    aside: &[Vec<bool>],
) -> Cant {
    let mut points = Vec::new();
    for ((run, placed), aside) in runs.iter().zip(placed).zip(aside) {
        let sense = match crate::line::increasing(placed) {
            true => 1.0,
            false => -1.0,
        };
        for ((c, p), a) in run.cant_rad.iter().zip(placed).zip(aside) {
            if let (Some(c), Some(p), false) = (c, p, a) {
                points.push((p.chainage_m, 1.0, sense * STANDARD_CANT_BASE_M * c.sin()));
            }
        }
    }
    if points.len() < MIN_FIXES {
        return Cant::NoCant {
            with_cant: points.len(),
        };
    }
    let Some(RobustFit { spline, kept, rms }) =
        robust_fit(line, &points, KNOT_SPACING_M, SMOOTHING_M)
    else {
        return Cant::NoCant {
            with_cant: points.len(),
        };
    };
    let (mut largest_m, mut largest_at_m) = (0.0f64, 0.0);
    for v in &mut line.vertices {
        // To the millimetre, as a cant is given; never more than a line can have.
        let cant = (spline.at(v.chainage_m) * 1e3).round() / 1e3;
        let cant = cant.clamp(-MAX_CANT_M, MAX_CANT_M);
        if cant.abs() > largest_m.abs() {
            (largest_m, largest_at_m) = (cant, v.chainage_m);
        }
        v.cant_m = Some(cant);
    }
    Cant::Fitted {
        fixes: kept,
        residual_rms_m: rms,
        largest_m,
        largest_at_m,
    }
}
