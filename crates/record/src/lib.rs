//! The recording side of railfuse: everything that produces a raw log.
//!
//! Today that is the train-run [`simulator`]: a track with chainage, a driven speed profile
//! with station stops, the ground truth, and every sensor of the catalogue with its own rate,
//! noise, bias, quantisation, latency and dropouts, written as a railfuse MCAP log. Live
//! sources (serial NMEA/UBX, UDP/TCP JSON lines) and importers belong here too.
//!
//! This crate knows nothing of filters or Rerun: it depends only on the channel catalogue.

pub mod decode;
pub mod import;
pub mod simulator;

pub use simulator::{simulate, Scenario, SimulationReport};

/// The version written into every log's run metadata.
pub const TOOL_VERSION: &str = concat!("railfuse ", env!("CARGO_PKG_VERSION"));
