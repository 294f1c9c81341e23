//! `railfuse merge`: a run's files as one file (or as parts of a chosen size or span).

use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::log::WriterOptions;

use super::run_input::{RunArgs, SplitArgs};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub run: RunArgs,
    /// The merged log. With a --split-* option, its parts: OUT-001.mcap, OUT-002.mcap, …
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub split: SplitArgs,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let run = a.run.open()?;
    let rule = a.split.rule(&run)?;
    super::check_writable(&a.output)?;
    let r = railfuse_catalog::run::merge(&run, &a.output, rule, &WriterOptions::default())?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    crate::say!(
        "merged {} messages, {} metadata records and {} attachments of {} file(s) -> {}",
        r.messages,
        r.metadata,
        r.attachments,
        run.parts().len(),
        r.outputs
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if r.merge.duplicates_dropped > 0 {
        eprintln!(
            "note: {} messages were in two files (a split boundary): written once",
            r.merge.duplicates_dropped
        );
    }
    Ok(())
}
