//! The recording side of railfuse: everything that produces a raw log.
//!
//! - [`simulator`]: the train-run simulator: a track with chainage, a driven speed profile
//!   with station stops, the ground truth, and every sensor of the catalogue with its own
//!   rate, noise, bias, quantisation, latency, dropouts and injected faults;
//! - [`recorder`]: live capture of sources (UDP/TCP JSON lines, NMEA and UBX over serial, TCP
//!   or files, stdin, the simulator in real time) into a crash-safe log;
//! - [`decode`]: the UBX and NMEA decoders; [`import`]: existing logs (the ETH-PBL dataset).
//!
//! This crate knows nothing of filters or Rerun: it depends only on the channel catalogue.

pub mod decode;
pub mod error;
pub mod import;
pub mod recorder;
pub mod simulator;

pub use error::{Error, Result};
pub use simulator::{simulate, simulate_recorders, Scenario, SimRecorder, SimulationReport};

/// The version written into every log's run metadata.
pub const TOOL_VERSION: &str = concat!("railfuse ", env!("CARGO_PKG_VERSION"));
