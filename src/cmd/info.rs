use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::inspect::summarise;

use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The MCAP file.
    pub file: PathBuf,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let s = summarise(&a.file)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(());
    }
    println!(
        "{}: {} messages over {:.1} s, {:.1} MiB",
        s.file,
        s.messages,
        s.duration_s,
        s.file_bytes as f64 / (1 << 20) as f64
    );
    let mut t = Table::new(&[
        "topic",
        "schema",
        "messages",
        "rate Hz",
        "first s",
        "last s",
        "largest gap s",
    ]);
    let t0 = s.first_log_time_ns.unwrap_or(0);
    let rel = |t: Option<u64>| t.map_or("-".into(), |t| format!("{:.3}", (t - t0) as f64 / 1e9));
    for c in &s.channels {
        t.row(vec![
            c.topic.clone(),
            c.schema.clone(),
            c.messages.to_string(),
            c.mean_rate_hz.map_or("-".into(), |r| format!("{r:.2}")),
            rel(c.first_log_time_ns),
            rel(c.last_log_time_ns),
            c.largest_gap_s.map_or("-".into(), |g| format!("{g:.3}")),
        ]);
    }
    print!("{t}");
    for (name, m) in &s.metadata {
        println!("metadata {name}:");
        for (k, v) in m {
            let v = if v.len() > 100 {
                format!("{}… ({} bytes)", &v[..v.floor_char_boundary(100)], v.len())
            } else {
                v.clone()
            };
            println!("  {k} = {}", v.replace('\n', " "));
        }
    }
    for at in &s.attachments {
        println!(
            "attachment {} ({}, {} bytes)",
            at.name, at.media_type, at.bytes
        );
    }
    if s.fused_pipelines.is_empty() {
        println!("fused pipelines: none");
    } else {
        println!("fused pipelines: {}", s.fused_pipelines.join(", "));
    }
    Ok(())
}
