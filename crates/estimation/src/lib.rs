//! Estimation along a track, free of logs and configuration files: the filters, the motion and
//! sensor-state models they predict with, and the pre-filters of one channel. What the
//! re-fusion engine (`railfuse-refuse`) builds its pipelines from, and usable on its own the
//! way filterpy or adskalman are: measurements in, states and covariances out.
//!
//! - [`filter`]: Kalman filter (Joseph form) and RTS smoother, EM, particle filter with its
//!   resampling, federated filters with information-sharing coefficients β and a
//!   working-state detector per device;
//! - [`model`]: motion (transition) models (constant velocity, constant acceleration,
//!   Singer, a measured acceleration as input) and sensor states (biases, scale factors);
//! - [`prefilter`]: source 003's RLS, adaptive RLS and PU-RLS pre-filters of one channel;
//! - [`quantity`]: what a measurement measures, and its row of the observation matrix.
//!
//! `cargo run -p railfuse-estimation --example train_along_track` filters and RTS-smooths a
//! simulated train with this crate alone.
//!
//! Dependencies: nalgebra and rand for the maths, tempfile for the RTS smoother's spill.
//! Optional features: `serde`, so that settings can be read from a configuration by the
//! crates above; `schema`, their JSON schema (schemars).

pub mod filter;
pub mod model;
pub mod prefilter;
pub mod quantity;
