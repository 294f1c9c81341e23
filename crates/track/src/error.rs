//! Why no line was fitted.

use crate::banded::NotPositiveDefinite;

/// Why no line was fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("no run has fixes to fit")]
    NoRuns,
    #[error("{run}: the train moves {moved_m:.0} m over its fixes, too little to fit a line (at least {MIN_TRAVEL_M:.0} m)")]
    TooShort { run: String, moved_m: f64 },
    #[error("{run}: {on_line} of its {fixes} fixes lie on the line fitted to {seed}: not the same line (no overlap)")]
    NoOverlap {
        run: String,
        seed: String,
        fixes: usize,
        on_line: usize,
    },
    #[error("the fit leaves {rms_m:.3} m RMS across the track between chainage {from_m:.0} and {to_m:.0} m, more than the {tolerance_m} m promised (--tolerance): fixes of a worse quality there, or runs on different tracks{leaning}")]
    Tolerance {
        from_m: f64,
        to_m: f64,
        rms_m: f64,
        tolerance_m: f64,
        /// The runs whose fixes keep their roof antenna's lean (no IMU), said as a cause.
        leaning: String,
    },
    #[error("the spline cannot be solved: {0}")]
    Solve(#[from] NotPositiveDefinite),
}

/// The least travel a seed run needs, m.
pub const MIN_TRAVEL_M: f64 = 50.0;
