use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

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
    /// Datagrams the kernel dropped before the recorder could read them (a full socket
    /// receive buffer; UDP sources).
    #[serde(default)]
    pub kernel_dropped: u64,
    pub reconnects: u64,
    pub connected: bool,
    #[serde(default)]
    pub last_error: Option<String>,
    /// Every line, frame or datagram not used, counted once under its reason.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub skipped: BTreeMap<String, u64>,
    /// The first few problems, each with where it was (line, byte offset) and its cause.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub first_problems: Vec<String>,
    /// What was recorded but looks wrong (a receiver's date 1024 weeks early), counted once
    /// under its reason: kept as it came, never changed.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub warnings: BTreeMap<String, u64>,
}

impl SourceStats {
    /// How many problems [`SourceStats::first_problems`] keeps.
    pub const FIRST_PROBLEMS: usize = 8;

    /// Counts one line, frame or datagram not used under `reason`, without listing it (a
    /// sentence type that is not used, a frame of a class not decoded).
    pub fn count(&mut self, reason: &str) {
        match self.skipped.get_mut(reason) {
            Some(n) => *n += 1,
            None => {
                self.skipped.insert(reason.to_owned(), 1);
            }
        }
    }

    /// Counts one skipped line, frame or datagram under `reason`; the first few are kept in
    /// words, with where they were (`at`, e.g. "line 12" or "byte 4096").
    pub fn skip(&mut self, reason: &str, at: &str, detail: &dyn std::fmt::Display) {
        self.count(reason);
        if self.first_problems.len() < Self::FIRST_PROBLEMS {
            self.first_problems.push(format!("{at}: {detail}"));
        }
    }

    /// Counts one message recorded as it came but under `warning`.
    pub fn warn(&mut self, warning: &str) {
        *self.warnings.entry(warning.to_owned()).or_insert(0) += 1;
    }

    /// Adds the counts of `other` (one connection's, into its listener's figures).
    pub fn absorb(&mut self, other: &SourceStats) {
        self.received += other.received;
        self.malformed += other.malformed;
        self.checksum_failures += other.checksum_failures;
        self.oversized += other.oversized;
        self.dropped += other.dropped;
        self.kernel_dropped += other.kernel_dropped;
        for (reason, n) in &other.skipped {
            *self.skipped.entry(reason.clone()).or_insert(0) += n;
        }
        for (warning, n) in &other.warnings {
            *self.warnings.entry(warning.clone()).or_insert(0) += n;
        }
        let room = Self::FIRST_PROBLEMS.saturating_sub(self.first_problems.len());
        self.first_problems
            .extend(other.first_problems.iter().take(room).cloned());
        if other.last_error.is_some() {
            self.last_error.clone_from(&other.last_error);
        }
    }
}

/// The recorder's own health, written about once a second on `/recorder/diagnostics`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RecorderDiagnostics {
    pub stamp_ns: u64,
    pub sources: Vec<SourceStats>,
    /// Bytes written to the log so far.
    pub bytes_written: u64,
}

protobuf_form!(RecorderDiagnostics {
    stamp_ns,
    sources,
    bytes_written
});
protobuf_form!(SourceStats {
    name,
    received,
    written,
    malformed,
    checksum_failures,
    oversized,
    dropped,
    kernel_dropped,
    reconnects,
    connected,
    last_error,
    skipped,
    first_problems,
    warnings,
});
