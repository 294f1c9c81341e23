//! The viewer bridge: reads a railfuse log (raw or fused) in one streaming pass, or messages
//! as they are recorded or re-fused, and logs them to Rerun on the `log_time` timeline with a
//! layout that reads without a click.
//!
//! - [`entities`]: every entity path.
//! - [`blueprint`]: the layout sent with every recording.
//! - [`map`]: the plan view's track, chainage marks, balises, stations, tunnels and legend.
//! - [`series`]: columnar logging and decimation of long runs.
//! - [`palette`]: one colour per pipeline everywhere.
//! - `logger`: messages to entities ([`visualize`] for files, [`LiveViz`] for live streams).

pub mod blueprint;
pub mod entities;
mod logger;
pub mod map;
pub mod palette;
pub mod series;

pub use logger::{visualize, LiveViz, Sink, VizOptions, VizReport, DECIMATE_AFTER_S, SCREEN_BINS};

/// The Rerun application id of every railfuse recording (the blueprint is tied to it).
pub const APPLICATION_ID: &str = "railfuse";

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error("Rerun: {0}")]
    Rerun(String),
    #[error("{path}: {source}")]
    Output {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}
