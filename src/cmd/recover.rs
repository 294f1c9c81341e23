use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::log::recover;

#[derive(clap::Args)]
pub struct Args {
    /// The damaged log (a recording cut off by a crash or power loss, e.g. `run.mcap.partial`,
    /// or a file with corrupt chunks anywhere).
    pub input: PathBuf,
    /// Where to write the salvaged, complete log.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let r = recover(&a.input, &a.output)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    println!(
        "recovered {} messages ({} intact chunks copied as they were) on {} channels, {} metadata \
         records, {} attachments from {} ({:.1} MiB) -> {}",
        r.messages,
        r.chunks,
        r.channels,
        r.metadata,
        r.attachments,
        r.input.display(),
        mib(r.input_bytes),
        r.output.display()
    );
    for (topic, n) in &r.messages_per_topic {
        println!("  {topic:<28} {n}");
    }
    if r.skipped.is_empty() {
        println!("the file was complete: nothing lost");
    }
    for d in &r.skipped {
        println!(
            "skipped bytes {}..{} ({:.1} KiB): {}",
            d.offset,
            d.offset + d.length,
            d.length as f64 / 1024.0,
            d.cause
        );
    }
    if r.orphan_messages > 0 {
        println!(
            "skipped {} messages whose channel record was lost",
            r.orphan_messages
        );
    }
    Ok(())
}
