//! Errors of re-fusion, each naming the file, pipeline or channel it is about.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    /// A track map that cannot be used (the message names the file and the cause).
    #[error("{0}")]
    Map(String),
    /// A withholding request that cannot be met in this run (the message names the run,
    /// the topic and the cause).
    #[error("{input}: {problem}")]
    Withhold { input: PathBuf, problem: String },
    /// A log given no configuration in which no topic feeds a sensor model.
    #[error("{0}")]
    NoDefaultPipeline(String),
    #[error("{path}: {source}")]
    ConfigRead {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A TOML syntax or type error: toml's message already names the line and column.
    #[error("{path}: {message}")]
    ConfigSyntax { path: PathBuf, message: String },
    /// A value or combination the file's syntax allows but railfuse cannot run; the line and
    /// column are those of the table it is about.
    #[error("{path}: line {line}, column {column}: pipeline '{pipeline}': {message}")]
    ConfigInvalid {
        path: PathBuf,
        line: usize,
        column: usize,
        pipeline: String,
        message: String,
    },
    /// A sensor and the log's channel do not fit; `declared` is where the sensor's table is.
    #[error("{input}: pipeline '{pipeline}' reads channel {topic} ({declared}), which {problem}")]
    Channel {
        input: PathBuf,
        pipeline: String,
        topic: String,
        declared: String,
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
