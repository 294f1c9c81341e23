//! Offline re-fusion: replay a railfuse log through filter pipelines, write the fused channels
//! back beside an unchanged copy of every input record, and measure accuracy against a
//! reference.
//!
//! Layout:
//! - [`model`]: motion (transition) models: constant velocity, constant acceleration, Singer;
//! - [`filter`]: the estimators: Kalman filter (Joseph form) and RTS smoother, particle
//!   filter, federated filters with information-sharing coefficients β and a working-state
//!   detector per device;
//! - [`measurement`]: sensor models, how each channel's messages become measurements;
//! - [`config`]: the pipeline TOML as written;
//! - [`config_reference`]: the configuration's JSON schema and reference page, from its types;
//! - [`spec`]: the pipelines validated, and each sensor bound to its channel;
//! - [`default_config`]: the pipeline a log given no configuration is re-fused with;
//! - [`kinds`]: what a pipeline kind that reads whole messages gives the spec and the replay;
//!   [`registry`]: the kinds by name, one line each;
//! - [`pipeline`]: one configured estimator fed in sensor-time order ([`reorder`]: the
//!   reorder window);
//! - [`prefilter`]: source 003's RLS, adaptive RLS and PU-RLS pre-filters of one channel;
//! - [`gnss_ins`]: source 003's GNSS/MEMS-IMU error-state filter in the plane, its GNSS
//!   gate, pre-filters, AKF and IMU error learning;
//! - [`eddy_current`]: source 004's eddy-current speed and distance: filtering, correlation,
//!   warping;
//! - [`tilt`]: the level an IMU's readings are turned into, the map's looked up where the
//!   gyro's roll puts the cant ramps through a GNSS loss;
//! - [`safety`]: source 002's EKF in the plane with its safety checks and safe interval;
//! - [`replay`]: the `refuse` run, streaming input to output.
//!
//! Tuning (`railfuse tune`) is the `railfuse-tune` crate, above this one.

pub mod base;
pub mod checks;
pub mod config;
pub mod config_reference;
pub mod default_config;
pub mod eddy_current;
pub mod error;
pub mod fused;
pub mod gnss_ins;
pub mod kinds;
pub mod measurement;
pub mod noise;
pub mod pipeline;
pub mod registry;
pub mod reorder;
pub mod replay;
pub mod safety;
pub mod spec;
pub mod tilt;

pub use error::{Error, Result};
// The estimation maths, under the paths the pipelines have always used.
pub use railfuse_estimation::{filter, model, prefilter};
