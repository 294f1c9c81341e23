use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What one recorder source has done so far (counters since the start of the recording).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SourceStats {
    /// The source as given on the command line, e.g. `udp 127.0.0.1:5600`.
    pub name: String,
    /// Messages decoded and queued.
    pub received: u64,
    /// Messages written to the log.
    pub written: u64,
    /// Lines or frames that did not decode (bad JSON, unknown channel, bad field).
    pub malformed: u64,
    /// NMEA or UBX checksum failures.
    pub checksum_failures: u64,
    /// Lines or datagrams over the size limit.
    pub oversized: u64,
    /// Messages dropped because the source's queue was full (the writer fell behind).
    pub dropped: u64,
    pub reconnects: u64,
    pub connected: bool,
    #[serde(default)]
    pub last_error: Option<String>,
}

/// The recorder's own health, written about once a second on `/recorder/diagnostics`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RecorderDiagnostics {
    pub stamp_ns: u64,
    pub sources: Vec<SourceStats>,
    /// Bytes written to the log so far.
    pub bytes_written: u64,
}
