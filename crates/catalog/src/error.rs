//! Errors of the catalogue and the log reader/writer. Every variant names the file it is about,
//! so a command-line user sees one line with the file and the cause.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a readable MCAP file: {cause}")]
    Mcap { path: PathBuf, cause: String },
    #[error(
        "{path}: damaged at byte {offset}: {cause}; `railfuse recover` salvages every intact chunk"
    )]
    Damaged {
        path: PathBuf,
        offset: u64,
        cause: String,
    },
    /// A run (files, a directory, a bag) that cannot be read as one: a missing part, a bag's
    /// unreadable metadata.yaml, two sources on one topic.
    #[error("{path}: {cause}")]
    Run { path: PathBuf, cause: String },
    #[error("{path}: the file is empty")]
    Empty { path: PathBuf },
    #[error("{path}: message on {topic} at log time {log_time_ns} ns does not decode as {schema}: {source}")]
    Decode {
        path: PathBuf,
        topic: String,
        schema: String,
        log_time_ns: u64,
        #[source]
        source: serde_json::Error,
    },
    /// A payload that does not decode, for a cause other than JSON's (protobuf).
    #[error("{path}: message on {topic} at log time {log_time_ns} ns does not decode as {schema}: {cause}")]
    Undecodable {
        path: PathBuf,
        topic: String,
        schema: String,
        log_time_ns: u64,
        cause: String,
    },
    #[error("{path}: cannot write MCAP: {cause}")]
    Write { path: PathBuf, cause: String },
    #[error("{output}: this is the input {input} itself (the same file); write the salvaged log to another path")]
    OutputIsInput { input: PathBuf, output: PathBuf },
}

impl Error {
    pub(crate) fn mcap(path: &std::path::Path, e: impl std::fmt::Display) -> Self {
        Error::Mcap {
            path: path.to_owned(),
            cause: e.to_string(),
        }
    }
    /// A write error with its chain of causes ("… : No space left on device").
    pub(crate) fn write(path: &std::path::Path, e: impl std::error::Error) -> Self {
        let mut cause = e.to_string();
        let mut source = e.source();
        while let Some(s) = source {
            let text = s.to_string();
            if !cause.contains(&text) {
                cause = format!("{cause}: {text}");
            }
            source = s.source();
        }
        Error::Write {
            path: path.to_owned(),
            cause,
        }
    }
    pub(crate) fn run(path: &std::path::Path, cause: impl std::fmt::Display) -> Self {
        Error::Run {
            path: path.to_owned(),
            cause: cause.to_string(),
        }
    }
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_owned(),
            source,
        }
    }
}
