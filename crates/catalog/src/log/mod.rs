//! Reading and writing railfuse logs (MCAP, JSON messages, jsonschema schemas).
//!
//! Both sides stream: the reader pulls bytes from the file as it needs them, so memory scales
//! with the largest chunk, never with the file; the writer emits zstd-compressed, indexed
//! chunks with a summary, into a temporary file that only becomes the output once it is
//! complete.

mod reader;
mod writer;

pub use reader::{read_channels, ChannelInfo, LogMessage, LogReader, LogRecord, SchemaInfo};
pub use writer::{ChannelId, LogWriter, WriterOptions};

/// MCAP profile name railfuse writes (no ROS semantics: plain JSON channels).
pub const PROFILE: &str = "railfuse";
/// Message encoding of every railfuse channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every railfuse channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Largest record the reader accepts (a bound on untrusted input), 256 MiB.
pub const RECORD_LENGTH_LIMIT: usize = 256 << 20;
