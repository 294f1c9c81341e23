//! A run written out again: one file from many (`railfuse merge`, like `mcap merge`), or parts
//! from one ([`SplitRule`]). Every channel, schema, message, metadata record and attachment is
//! kept, and the clock each file was read on is recorded as metadata.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{MergeCounts, Run};
use crate::error::{Error, Result};
use crate::log::{LogRecord, PartWriter, SplitRule, WriterOptions};

/// The metadata record a merge writes: the run's files and the clock each was read on.
pub const MERGE_METADATA: &str = "railfuse.merge";

#[derive(Debug, Clone, serde::Serialize)]
pub struct MergeReport {
    pub inputs: Vec<PathBuf>,
    pub outputs: Vec<PathBuf>,
    pub messages: u64,
    pub metadata: u64,
    pub attachments: u64,
    pub merge: MergeCounts,
}

/// Writes `run` to `output` (or to its numbered parts, by `rule`), streaming.
pub fn merge(
    run: &Run,
    output: &Path,
    rule: SplitRule,
    options: &WriterOptions,
) -> Result<MergeReport> {
    if let Some(p) = run
        .parts()
        .iter()
        .find(|p| super::same_file(&p.path, output))
    {
        return Err(Error::run(
            output,
            format!(
                "is {} of the run itself: write to another path",
                p.path.display()
            ),
        ));
    }
    let mut reader = run.reader()?;
    let mut out = PartWriter::create(output, options, rule)?;
    let (mut messages, mut metadata, mut attachments) = (0, 0, 0);
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Schema(s) => out.schema(s),
            LogRecord::Channel(c) => out.channel(c)?,
            LogRecord::Message(m) => {
                out.message(&m)?;
                messages += 1;
            }
            LogRecord::Metadata { name, metadata: m } => {
                out.metadata(&name, m)?;
                metadata += 1;
            }
            LogRecord::Attachment {
                name,
                media_type,
                log_time_ns,
                create_time_ns,
                data,
            } => {
                out.writer()
                    .attach(&name, &media_type, log_time_ns, create_time_ns, data)?;
                attachments += 1;
            }
        }
    }
    out.metadata(MERGE_METADATA, clocks(run))?;
    let merge = reader.counts().clone();
    Ok(MergeReport {
        inputs: run.inputs().to_vec(),
        outputs: out.finish()?,
        messages,
        metadata,
        attachments,
        merge,
    })
}

/// Each file's name and the clock it was read on, and the time basis.
fn clocks(run: &Run) -> BTreeMap<String, String> {
    let mut m = BTreeMap::from([(
        "time".to_owned(),
        format!("{:?}", run.time_basis()).to_lowercase(),
    )]);
    if let Some(alignment) = run.alignment() {
        m.insert("align".into(), "gnss".into());
        for (i, e) in alignment.estimates.iter().enumerate() {
            let said = match e {
                Ok(e) => format!(
                    "{} against GNSS time: clock_offset_s={:+.9} drift_ppm={:+.3} from {} pairs of {}",
                    e.input.display(),
                    e.clock.offset_s(),
                    e.clock.drift_ppm,
                    e.pairs,
                    e.source.label()
                ),
                Err(n) => format!("{}: {}", n.input.display(), n.cause),
            };
            m.insert(format!("input.{i:03}"), said);
        }
    }
    for (i, p) in run.parts().iter().enumerate() {
        let name = p.path.file_name().map_or_else(
            || p.path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        m.insert(
            format!("file.{i:03}"),
            format!(
                "{name} clock_offset_s={:+.9} drift_ppm={:+.3}",
                p.clock.offset_s(),
                p.clock.drift_ppm
            ),
        );
    }
    m
}
