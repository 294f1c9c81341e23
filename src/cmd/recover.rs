use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::log::recover;

#[derive(clap::Args)]
pub struct Args {
    /// The damaged log (a recording cut off by a crash or power loss, e.g. `run.mcap.partial`).
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
    println!(
        "recovered {} messages on {} channels, {} metadata records, {} attachments from {} ({:.1} of {:.1} MiB read) -> {}",
        r.messages,
        r.channels,
        r.metadata,
        r.attachments,
        r.input.display(),
        r.bytes_read as f64 / (1 << 20) as f64,
        r.input_bytes as f64 / (1 << 20) as f64,
        r.output.display()
    );
    for (topic, n) in &r.messages_per_topic {
        println!("  {topic:<28} {n}");
    }
    match &r.stopped_by {
        Some(why) => {
            println!("lost: everything after the last complete chunk; reading stopped at: {why}")
        }
        None => println!("the file was complete: nothing lost"),
    }
    if r.orphan_messages > 0 {
        println!(
            "skipped {} messages whose channel record was lost",
            r.orphan_messages
        );
    }
    Ok(())
}
