//! The viewer bridge: reads a railfuse log (raw or fused) in one streaming pass and logs it to
//! Rerun on the `log_time` timeline: the track map, the true and measured positions on it, the
//! speeds of every sensor, and each fused pipeline's chainage and speed errors with their ±3σ
//! bands.
//!
//! Entity layout (see [`entities`]): `map/…` is the 2-D plan view (east right, north up),
//! `speed/…`, `chainage_error/…` and `speed_error/…` are time series (fused ones carry three
//! series: the value and its ±3σ bounds), `events` is a text log.

pub mod entities;
mod logger;

pub use logger::{visualize, LiveViz, Sink, VizReport};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error("Rerun: {0}")]
    Rerun(String),
}
