//! railfuse-track: the track's centre line and chainage fitted from the runs themselves —
//! what `railfuse track` does.
//!
//! A field log has no track map, but every run over the line logs RTK fixes. This crate
//! reads them from any number of runs ([`fixes`]), fits one smooth centre line through all of
//! them ([`fit`]: a penalised cubic B-spline of chainage, [`spline`], solved as a banded
//! system, [`banded`]), gives it a chainage ([`chainage`]) and writes it as the GeoJSON or CSV
//! the other commands read as `--track` ([`output`]), with what the fit says about itself:
//! the runs, the fixes used, the residual across the track, the stretches bridged without
//! fixes, where runs disagree and where a run leaves the line. Where a run has no fix, or
//! its fixes bend where its gyro says the train did not (a steady multipath pull,
//! [`multipath`]), its own motion crosses ([`bridge`], tied to its fixes, course and
//! standstills by [`tie`]). A roof antenna's lean in canted curves is taken out of its fixes
//! first, with the roll the run's IMU measured ([`lean`]); the same roll, less the body's
//! lean, gives the line's cant ([`cant`]), as the fixes' heights give its profile
//! ([`profile`]).
//!
//! Why a spline and not clothoids: a railway's alignment is straights, transition curves and
//! arcs, and fitting those segments needs the segmentation right first (where each begins is
//! what the noisy fixes hide). A cubic spline with a penalty on its bending
//! follows all three without knowing where they join, bridges gaps smoothly, and solves in
//! linear time; at knots every 5 m its shape error on a 300 m radius is well under a
//! millimetre, far below RTK's noise.

pub mod banded;
pub mod bridge;
pub mod cant;
pub mod chainage;
pub mod error;
pub mod fit;
pub mod fixes;
pub mod lean;
pub mod line;
pub mod motion;
pub mod multipath;
pub mod osm;
pub mod output;
pub mod profile;
pub mod report;
pub mod spline;
pub mod tie;
