//! Importers: existing logs of other tools into railfuse channels.
//!
//! - [`eth`]: the ETH-PBL railway dataset (on-board node CSV: raw IMU, UBX frames as hex,
//!   NMEA sentences, correction-link and station events);
//! - [`gnss_file`]: NMEA and UBX captures of a receiver;
//! - [`converted`]: ROS 2 sqlite3 bags, GPX tracks, MDF4 bus logs and CSV tables with a
//!   column mapping, to MCAP (the run reader's conversion);
//! - [`can_log`]: CAN bus logs (candump, Vector ASC), decoded with the vehicle's DBC.

pub mod can_log;
pub mod converted;
pub mod eth;
pub mod gnss_file;

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::PathBuf;

use serde::Serialize;

/// What an import read, wrote and could not use.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ImportReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub format: String,
    pub lines: u64,
    /// Bytes read (binary formats, where there are no lines).
    pub bytes: u64,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    /// Input that was not used, by reason (bad checksum, unknown line type, …).
    pub skipped: BTreeMap<String, u64>,
    /// The first few problems, each naming its line.
    pub first_problems: Vec<String>,
    /// How sensor time was established.
    pub time_base: String,
    /// What was imported but looks wrong (a receiver's date 1024 weeks early), by reason.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub warnings: BTreeMap<String, u64>,
    /// Where the sensor frames sit, as a bag's `/tf_static` says.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<railfuse_catalog::foreign::FrameTransform>,
}

impl ImportReport {
    pub(crate) fn skip(&mut self, line: u64, reason: &str, detail: impl std::fmt::Display) {
        *self.skipped.entry(reason.to_owned()).or_insert(0) += 1;
        if self.first_problems.len() < 10 {
            self.first_problems
                .push(format!("line {line}: {reason}: {detail}"));
        }
    }
}

/// Longest input line accepted; longer ones are skipped and counted (untrusted input).
pub const MAX_LINE: usize = 4096;

/// Reads one line of at most [`MAX_LINE`] bytes into `buf` (without the newline); returns
/// None at the end, Some(false) for an oversized line (its rest discarded).
fn read_line_bounded(r: &mut impl BufRead, buf: &mut Vec<u8>) -> std::io::Result<Option<bool>> {
    buf.clear();
    let mut oversized = false;
    loop {
        let available = r.fill_buf()?;
        if available.is_empty() {
            return Ok(if buf.is_empty() && !oversized {
                None
            } else {
                Some(!oversized)
            });
        }
        let (chunk, done) = match available.iter().position(|&b| b == b'\n') {
            Some(i) => (&available[..i], Some(i + 1)),
            None => (available, None),
        };
        if !oversized {
            if buf.len() + chunk.len() > MAX_LINE {
                oversized = true;
                buf.clear();
            } else {
                buf.extend_from_slice(chunk);
            }
        }
        let used = done.unwrap_or(available.len());
        r.consume(used);
        if done.is_some() {
            if buf.last() == Some(&b'\r') {
                buf.pop();
            }
            return Ok(Some(!oversized));
        }
    }
}
