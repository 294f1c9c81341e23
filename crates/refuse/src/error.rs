//! Errors of re-fusion, each naming the file, pipeline or channel it is about.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error("{path}: {source}")]
    ConfigRead {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A TOML syntax or type error: toml's message already names the line and column.
    #[error("{path}: {message}")]
    ConfigSyntax { path: PathBuf, message: String },
    #[error("{path}: pipeline '{pipeline}': {message}")]
    ConfigInvalid {
        path: PathBuf,
        pipeline: String,
        message: String,
    },
    #[error("{input}: pipeline '{pipeline}' reads channel {topic}, which {problem}")]
    Channel {
        input: PathBuf,
        pipeline: String,
        topic: String,
        problem: String,
    },
    /// The RTS smoother's spill file (a temporary file) could not be written or read.
    #[error("pipeline '{pipeline}': smoother temporary file: {source}")]
    Spill {
        pipeline: String,
        #[source]
        source: std::io::Error,
    },
}
