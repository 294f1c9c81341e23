//! Errors of tuning: a request that cannot run, a log that cannot be tuned on, and the two
//! ways a search ends early with its best result so far.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The configuration, a log or a pipeline failed as it would in `refuse`.
    #[error(transparent)]
    Refuse(#[from] railfuse_refuse::Error),
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    /// A tuning request that cannot run: an unknown parameter, bounds that do not hold the
    /// start, a search that cannot be made.
    #[error("{path}: pipeline '{pipeline}': tune: {message}")]
    Request {
        path: PathBuf,
        pipeline: String,
        message: String,
    },
    /// A log that cannot be tuned on: no reference channel, no samples of it.
    #[error("{input}: {message}")]
    Recording { input: PathBuf, message: String },
    /// Ctrl-C during a search: the best result so far is kept.
    #[error("interrupted")]
    Interrupted,
    /// A search used its evaluations up: the best result so far is kept.
    #[error("the evaluation budget is used up")]
    Budget,
    /// The optimiser itself failed.
    #[error("tune: the optimiser failed: {0}")]
    Search(String),
}
