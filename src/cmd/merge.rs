//! `railfuse merge`: a run's files as one file (or as parts of a chosen size or span).

use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::log::{SplitRule, WriterOptions};

use super::run_input::RunArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub run: RunArgs,
    /// The merged log. With a --split-* option, its parts: OUT-001.mcap, OUT-002.mcap, …
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write parts of about this many MiB each.
    #[arg(long, value_name = "MIB")]
    pub split_size: Option<f64>,
    /// Write parts spanning this many seconds each.
    #[arg(long, value_name = "SECONDS")]
    pub split_every: Option<f64>,
    /// Begin a new part at each of these times (seconds from the run's first message).
    #[arg(long, value_delimiter = ',', value_name = "SECONDS,…")]
    pub split_at: Vec<f64>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Seconds as given on the command line, checked, in ns.
fn seconds_ns(flag: &str, s: f64) -> Result<u64> {
    anyhow::ensure!(s.is_finite() && s > 0.0, "{flag} {s}: expected seconds > 0");
    Ok((s * 1e9).round() as u64)
}

pub fn run(a: Args) -> Result<()> {
    let mut at_ns = a
        .split_at
        .iter()
        .map(|&s| seconds_ns("--split-at", s))
        .collect::<Result<Vec<_>>>()?;
    at_ns.sort_unstable();
    let rule = SplitRule {
        bytes: match a.split_size {
            Some(mib) => {
                anyhow::ensure!(
                    mib.is_finite() && mib > 0.0,
                    "--split-size {mib}: expected MiB > 0"
                );
                Some((mib * (1 << 20) as f64) as u64)
            }
            None => None,
        },
        every_ns: a
            .split_every
            .map(|s| seconds_ns("--split-every", s))
            .transpose()?,
        at_ns,
    };
    let run = a.run.open()?;
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
