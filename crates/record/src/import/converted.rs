//! Files the run reader also reads directly (ROS 2 sqlite3 bags, GPX tracks, MDF4, CSV
//! tables through their mapping) imported as
//! MCAP: the conversion is the catalogue's ([`railfuse_catalog::formats`]), so an imported
//! file holds exactly what a command reading the original sees.

use std::path::Path;

use railfuse_catalog::formats::{self, FormatOptions, Storage};
use railfuse_catalog::Result;

use super::ImportReport;

/// Converts `input` (of a converted storage) to MCAP at `output`.
pub fn import(
    storage: Storage,
    input: &Path,
    output: &Path,
    options: &FormatOptions,
) -> Result<ImportReport> {
    let c = formats::convert(storage, input, output, options, &Default::default())?;
    let time_base = match storage {
        Storage::Gpx => "each point's <time> (UTC; zone offsets applied)",
        Storage::Csv => "the mapping's time columns (its unit, format and zone)",
        Storage::Rosbag1 => "each message record's time (the recorder's receive time); header.stamp is the sensor time",
        _ => "rosbag2 receive time (log and publish time)",
    };
    let mut warnings = std::collections::BTreeMap::new();
    for w in &c.warnings {
        warnings.insert(w.clone(), 1);
    }
    if c.gaps > 0 {
        warnings.insert("segment breaks (gaps in the track)".to_owned(), c.gaps);
    }
    if let Some(d) = &c.damage {
        warnings.insert(format!("damaged, read up to it: {d}"), 1);
    }
    Ok(ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: storage.name().into(),
        time_base: time_base.into(),
        lines: c.rows,
        messages: c.messages,
        per_topic: c.per_topic,
        skipped: c.skipped,
        first_problems: c.first_problems,
        warnings,
        frames: c.frames,
        ..Default::default()
    })
}
