use std::path::PathBuf;

use anyhow::Result;
use railfuse_viz::{visualize, Sink};

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("sink").required(true).args(["save", "connect", "spawn"])))]
pub struct Args {
    /// The MCAP log (raw or fused).
    pub input: PathBuf,
    /// Write a Rerun recording (.rrd).
    #[arg(long, value_name = "OUT.rrd")]
    pub save: Option<PathBuf>,
    /// Stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Start a Rerun viewer and stream to it.
    #[arg(long)]
    pub spawn: bool,
}

pub fn run(a: Args) -> Result<()> {
    let sink = match (a.save, a.connect) {
        (Some(p), _) => Sink::Save(p),
        (None, Some(url)) => Sink::Connect(url),
        (None, None) => Sink::Spawn,
    };
    let size = std::fs::metadata(&a.input).map_or(0, |m| m.len());
    let bar = crate::progress::Progress::bytes("viz", size);
    let report = visualize(&a.input, &sink, &|done| bar.set(done))?;
    bar.finish();
    let target = match &sink {
        Sink::Save(p) => p.display().to_string(),
        Sink::Connect(u) => u.clone(),
        Sink::Spawn => "a spawned viewer".into(),
    };
    eprintln!(
        "read {} messages, logged {} records on {} entities -> {target}",
        report.messages,
        report.logged,
        report.entities.len()
    );
    Ok(())
}
