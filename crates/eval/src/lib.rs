//! Evaluation of a log's fused channels against a reference: for every pipeline's states (and
//! its RTS-smoothed states), position and speed error RMSE, maximum and 95th percentile over
//! the whole run and over each marked window (injected faults, tunnels, correction outages,
//! reported device faults, from the `/events` channel; and, in a log with balises, the run
//! after the first balise, where an absolute fix has been available); NEES of `[s, v]` and NIS of the
//! innovations as the share of epochs inside the 95 % χ² interval.
//!
//! The reference is the ground-truth channel or any channel the user names: another
//! pipeline's state, or a GNSS fix channel (an RTK receiver), matched on the track map.
//!
//! Streaming with bounded memory. Fused states lag the reference by at most a reorder window
//! and are scored in file order; smoothed states sit at the end of the file (they exist only
//! once the whole run is filtered), so they are scored in a second pass that walks the
//! reference with a second reader in step with them.
//!
//! Layout:
//! - [`error_stats`]: one error's RMSE, maximum and 95th percentile in bounded memory;
//! - [`accuracy`]: errors and consistency (NEES, NIS) against a reference trajectory;
//! - [`fix_match`]: fused states against a GNSS reference, interpolated to each fix;
//! - [`outages`]: the withholding protocol's windows and each outage's errors;
//! - [`safety`]: source 002's safety summary (S7): per check how often and how long it fired,
//!   availability, containment of the reference by U_safe, injected faults caught;
//! - the evaluator (this crate's root): the accuracy table of a fused log, whole run and marked
//!   windows, read from the log in one streaming pass (two when it holds smoothed states).
//!
//! It reads logs through `railfuse-catalog` only and knows nothing of the pipelines: the
//! replay (`railfuse-refuse`) feeds it while it writes, `railfuse eval` and tuning read
//! finished logs with it.

pub mod accuracy;
pub mod error_stats;
mod evaluator;
pub mod fix_match;
pub mod outages;
pub mod safety;

pub use evaluator::{
    evaluate, fix_sample, lag_allowance_s, reference_kind, reference_sample, EvalReport, Evaluator,
    PipelineEval, ReferenceKind, SpanReport, WindowEval, AFTER_FIRST_BALISE,
};
pub use fix_match::{FixQuality, Reference};
