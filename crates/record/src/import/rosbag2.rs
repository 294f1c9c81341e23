//! rosbag2's sqlite3 storage imported as MCAP: the conversion is the catalogue's
//! ([`railfuse_catalog::foreign::rosbag2_sqlite`]), which the run reader uses too.

use std::path::Path;

use railfuse_catalog::foreign::rosbag2_sqlite;
use railfuse_catalog::Result;

use super::ImportReport;

/// Converts the bag at `input` (a directory, or one `.db3` file) to MCAP at `output`.
pub fn import(input: &Path, output: &Path) -> Result<ImportReport> {
    let c = rosbag2_sqlite::convert(input, output)?;
    Ok(ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: "rosbag2 sqlite3".into(),
        time_base: "rosbag2 receive time (log and publish time)".into(),
        lines: c.rows,
        messages: c.messages,
        per_topic: c.per_topic,
        skipped: c.skipped,
        ..Default::default()
    })
}
