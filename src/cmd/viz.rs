use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::run::Run;

use super::run_input::RunArgs;
use railfuse_viz::{visualize, Sink, VizOptions};

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("sink").args(["save", "connect", "spawn"])))]
pub struct Args {
    /// The log (raw or fused): a file, or every file of the run.
    #[command(flatten)]
    pub run: RunArgs,
    /// Write a Rerun recording (.rrd), its layout included.
    #[arg(long, value_name = "OUT.rrd")]
    pub save: Option<PathBuf>,
    /// Stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Start a Rerun viewer (the `rerun` on PATH) and stream to it: what viz does without
    /// --save or --connect.
    #[arg(long)]
    pub spawn: bool,
    #[command(flatten)]
    pub show: ShowArgs,
    /// Print the report as JSON (with wall time and peak memory).
    #[arg(long)]
    pub json: bool,
}

/// What to show: shared by `viz` and the live views of `record` and `refuse`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ShowArgs {
    /// Show from this many seconds after the log's first message.
    #[arg(long, value_name = "SECONDS")]
    pub from: Option<f64>,
    /// Show up to this many seconds after the log's first message.
    #[arg(long, value_name = "SECONDS")]
    pub to: Option<f64>,
    /// Raw topics to show, comma-separated (default: all; the track map and the truth are
    /// always read, the errors are measured against them). Naming /imu shows the IMU in a
    /// fused run too.
    #[arg(long, value_delimiter = ',', value_name = "TOPIC,…")]
    pub topics: Vec<String>,
    /// Pipelines to show, comma-separated (default: all).
    #[arg(long, value_delimiter = ',', value_name = "NAME,…")]
    pub pipelines: Vec<String>,
    /// Keep every sample: runs longer than 30 minutes are otherwise decimated to min/max
    /// envelopes of 4096 bins, which look the same on a screen.
    #[arg(long)]
    pub full_rate: bool,
}

impl ShowArgs {
    pub fn options(&self) -> Result<VizOptions> {
        if let (Some(from), Some(to)) = (self.from, self.to) {
            anyhow::ensure!(from < to, "--from {from} must be before --to {to}");
        }
        for (flag, v) in [("--from", self.from), ("--to", self.to)] {
            if let Some(v) = v {
                anyhow::ensure!(
                    v.is_finite() && v >= 0.0,
                    "{flag} {v}: expected seconds ≥ 0"
                );
            }
        }
        Ok(VizOptions {
            from_s: self.from,
            to_s: self.to,
            topics: self.topics.clone(),
            pipelines: self.pipelines.clone(),
            full_rate: self.full_rate,
        })
    }
}

/// What `--pipelines`, `--topics`, `--from` and `--to` name is in the log: said before any
/// work, where the log's summary lists its channels and span.
fn check_selection(input: &Run, show: &ShowArgs) -> Result<()> {
    let reader = input.reader()?;
    let Some(summary) = reader.summary() else {
        return Ok(());
    };
    if let Some(channels) = &summary.channels {
        let fused: Vec<&str> = channels
            .iter()
            .filter_map(|c| match railfuse_catalog::topics::parse_fused(&c.topic) {
                Some((p, railfuse_catalog::topics::FusedChannel::State)) => Some(p),
                _ => None,
            })
            .collect();
        for p in &show.pipelines {
            if !fused.contains(&p.as_str()) {
                let have = match fused.is_empty() {
                    true => "none: re-fuse it first".to_owned(),
                    false => fused.join(", "),
                };
                anyhow::bail!(
                    "{}: no pipeline '{p}' in it (it has {have})",
                    input.display()
                );
            }
        }
        for t in &show.topics {
            if !channels.iter().any(|c| &c.topic == t) {
                let have: Vec<&str> = channels.iter().map(|c| c.topic.as_str()).collect();
                anyhow::bail!(
                    "{}: no topic {t} in it (it has {})",
                    input.display(),
                    have.join(", ")
                );
            }
        }
    }
    if let Some((first, last)) = summary.message_span_ns {
        let span_s = last.saturating_sub(first) as f64 / 1e9;
        if let Some(from) = show.from.filter(|f| *f > span_s) {
            anyhow::bail!(
                "--from {from}: past the end of {}, which spans {span_s:.1} s",
                input.display()
            );
        }
    }
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    let options = a.show.options()?;
    let run = a.run.open()?;
    check_selection(&run, &a.show)?;
    let sink = match (a.save, a.connect) {
        (Some(p), _) => Sink::Save(p),
        (None, Some(url)) => Sink::Connect(url),
        (None, None) => Sink::Spawn,
    };
    let started = std::time::Instant::now();
    let bar = crate::progress::Progress::bytes("viz", run.total_bytes());
    let report = visualize(&run, &sink, &options, &|done| bar.set(done))?;
    bar.finish();
    // What could not be shown is said, one line each, and nothing shown is never silent.
    for (topic, why) in &report.not_shown {
        eprintln!("not shown: {topic}: {why}");
    }
    for line in report.undecodable.lines() {
        eprintln!("warning: {line}");
    }
    if report.logged == 0 {
        eprintln!(
            "warning: {}: nothing to show: none of its {} messages is of a type railfuse draws",
            run.display(),
            report.messages
        );
    }
    if a.json {
        let recording_bytes = match &sink {
            Sink::Save(p) => std::fs::metadata(p).ok().map(|m| m.len()),
            _ => None,
        };
        let v = serde_json::json!({
            "messages": report.messages,
            "rows": report.logged,
            "entities": report.entities,
            "bin_s": report.bin_s,
            "not_shown": report.not_shown,
            "undecodable": report.undecodable.total,
            "recording_bytes": recording_bytes,
            "run": {
                "elapsed_s": started.elapsed().as_secs_f64(),
                "peak_rss_kib": super::measure::peak_rss_kib(),
            },
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let target = match &sink {
        Sink::Save(p) => p.display().to_string(),
        Sink::Connect(u) => u.clone(),
        Sink::Spawn => "a spawned viewer".into(),
    };
    let density = match report.bin_s {
        Some(bin) => {
            format!(", plots decimated to {bin:.2} s min/max bins (--full-rate keeps every sample)")
        }
        None => String::new(),
    };
    crate::say!(
        "read {} messages, logged {} rows on {} entities{density} -> {target}",
        report.messages,
        report.logged,
        report.entities.len()
    );
    Ok(())
}
