//! Errors of the recording side, each naming the source, file, spec or field it is about.

use std::io;
use std::path::PathBuf;

pub use crate::simulator::faults::FaultSpecError;

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Any error of this crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Source(#[from] SourceError),
}

/// Why a source stopped for good, or one connection attempt failed.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("cannot bind {addr}: {source}")]
    Bind {
        addr: std::net::SocketAddr,
        #[source]
        source: io::Error,
    },
    #[error("cannot connect to {addr}: {source}")]
    Connect {
        addr: String,
        #[source]
        source: io::Error,
    },
    /// A file or serial device.
    #[error("{}: {source}", path.display())]
    Path {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// A CAN adapter that could not be opened, or went away (the source's name says which).
    #[error("{cause}")]
    Can { adapter: String, cause: String },
    #[error("standard input: {0}")]
    Stdin(#[source] io::Error),
    #[error("unknown scenario '{0}'")]
    UnknownScenario(String),
    #[error("simulated source: {0}")]
    Simulation(#[from] railfuse_catalog::Error),
    #[error("simulated source: temporary file: {0}")]
    TempFile(#[source] io::Error),
    #[error("ended by an internal error (a bug in railfuse; please report it): {0}")]
    Panicked(String),
}

/// What is wrong with one JSON line (or one CSV row made into a message).
#[derive(Debug, thiserror::Error)]
pub enum JsonLineError {
    #[error("not a JSON object: {0}")]
    NotAnObject(#[source] serde_json::Error),
    #[error("no \"topic\"")]
    NoTopic,
    #[error("\"topic\" must be a string starting with '/'")]
    BadTopic,
    #[error("\"type\" must be a string")]
    TypeNotAString,
    #[error("unknown type {0}")]
    UnknownType(String),
    #[error("{0} is not a standard topic: name its \"type\"")]
    NotAStandardTopic(String),
    #[error("{topic}: not a valid {type_name}: {source}")]
    Invalid {
        topic: String,
        type_name: &'static str,
        #[source]
        source: serde_json::Error,
    },
}

/// A stream format name that is not json, nmea or ubx.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown stream format '{0}' (json, nmea, ubx)")]
pub struct UnknownStreamFormat(pub String);

/// A simulation the scenario cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    #[error("duration must be a positive number of seconds, not {0}")]
    Duration(f64),
    #[error(
        "fault: scenario '{0}' is source 000's bare simulation with no device models to break; \
         use default, seed001 or seed002"
    )]
    NoDevices(String),
    #[error("fault: scenario '{scenario}' has no {device} to fail")]
    NoSuchDevice { scenario: String, device: String },
    #[error(
        "fault {device}: its window starts at {start_s} s, after the run's end at {duration_s} s"
    )]
    AfterTheRun {
        device: String,
        start_s: f64,
        duration_s: f64,
    },
}
