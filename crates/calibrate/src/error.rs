//! Errors of calibration, each naming the run or file it is about.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error(transparent)]
    Refuse(#[from] railfuse_refuse::error::Error),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A run that cannot be calibrated from (the message says why).
    #[error("{input}: {message}")]
    Run { input: String, message: String },
    /// A configuration that gives no reference to calibrate against.
    #[error("{0}")]
    Config(String),
}
