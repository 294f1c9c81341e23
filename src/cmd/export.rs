//! `railfuse export`: a fused run's positions as GPX, KML, GeoJSON or CSV, for people who
//! do not run railfuse (the writers are the catalogue's `export` module).

use std::path::{Path, PathBuf};

use anyhow::Result;
use railfuse_catalog::export::{ExportFormat, ExportPoint, ExportWriter};
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::{FusedState, TrackMap};
use railfuse_catalog::run::Run;
use railfuse_catalog::topics::{self, FusedChannel};

use super::run_input::RunArgs;

#[derive(clap::Args)]
pub struct Args {
    /// A fused log (the output of `railfuse refuse`), or every file of a fused run.
    #[command(flatten)]
    pub run: RunArgs,
    /// The file to write; its ending says the format: .gpx (a track per pipeline), .kml
    /// (Google Earth), .geojson (QGIS; a Point feature per state) or .csv.
    #[arg(short, long, value_name = "OUT.gpx|.kml|.geojson|.csv")]
    pub output: PathBuf,
    /// The pipelines to write (repeat for several); every fused pipeline without it.
    #[arg(long, value_name = "NAME")]
    pub pipeline: Vec<String>,
    /// Write the RTS-smoothed states (`/fused/<p>/smoothed`) instead of the filtered ones.
    #[arg(long)]
    pub smoothed: bool,
    /// At most one state per this many seconds (a lighter file for a long run); every state
    /// without it.
    #[arg(long, value_name = "SECONDS")]
    pub every: Option<f64>,
}

pub fn run(a: Args) -> Result<()> {
    let Some(format) = ExportFormat::of_name(&a.output) else {
        anyhow::bail!(
            "{}: name the output .gpx, .kml, .geojson or .csv (its ending says the format)",
            a.output.display()
        );
    };
    let every_ns = match a.every {
        Some(s) if !(s.is_finite() && s > 0.0) => {
            anyhow::bail!("--every {s}: expected seconds > 0")
        }
        Some(s) => (s * 1e9).round() as u64,
        None => 0,
    };
    let run = a.run.open()?;
    let channel = match a.smoothed {
        true => FusedChannel::Smoothed,
        false => FusedChannel::State,
    };
    let pipelines = chosen_pipelines(&run, &a.pipeline, channel)?;
    super::check_writable(&a.output)?;
    // Written beside the output and renamed when whole: a failed export leaves no half file.
    let partial = PathBuf::from(format!("{}.partial", a.output.display()));
    let file = std::fs::File::create(&partial)
        .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", partial.display()))?;
    let result = (|| -> Result<Vec<(String, u64)>> {
        let mut writer = format.writer(Box::new(std::io::BufWriter::new(file)));
        let mut written = Vec::new();
        for p in &pipelines {
            let n = export_pipeline(&run, p, channel, every_ns, writer.as_mut())?;
            written.push((p.clone(), n));
        }
        writer
            .finish()
            .map_err(|e| anyhow::anyhow!("{}: {e}", partial.display()))?;
        Ok(written)
    })();
    let written = match result {
        Ok(w) => w,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(e);
        }
    };
    std::fs::rename(&partial, &a.output)
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.output.display()))?;
    let counts: Vec<String> = written.iter().map(|(p, n)| format!("{p} {n}")).collect();
    println!(
        "exported {} of {} -> {} ({})",
        channel_name(channel),
        run.display(),
        a.output.display(),
        counts.join(", ")
    );
    Ok(())
}

fn channel_name(c: FusedChannel) -> &'static str {
    match c {
        FusedChannel::Smoothed => "smoothed states",
        _ => "fused states",
    }
}

/// The pipelines asked for, each checked to be in the run; every fused one without a choice.
fn chosen_pipelines(run: &Run, asked: &[String], channel: FusedChannel) -> Result<Vec<String>> {
    let mut present = Vec::new();
    let mut reader = run.reader()?;
    let listed = reader.summary().is_some_and(|s| s.channels.is_some());
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                if let Some((p, ch)) = topics::parse_fused(&c.topic) {
                    if ch == channel && !present.iter().any(|q| q == p) {
                        present.push(p.to_owned());
                    }
                }
            }
            // Channels come before their messages: the first message ends the search only
            // where the summary listed them all; else read on (a file without a summary).
            LogRecord::Message(_) if listed => break,
            _ => {}
        }
    }
    if present.is_empty() {
        anyhow::bail!(
            "{}: no /fused/<pipeline>/{} channel: export writes a fused log's positions (railfuse \
             refuse {} -o FUSED.mcap first){}",
            run.display(),
            if channel == FusedChannel::Smoothed {
                "smoothed"
            } else {
                "state"
            },
            run.name().display(),
            if channel == FusedChannel::Smoothed {
                "; or leave out --smoothed"
            } else {
                ""
            }
        );
    }
    if asked.is_empty() {
        return Ok(present);
    }
    for p in asked {
        if !present.contains(p) {
            anyhow::bail!(
                "--pipeline {p}: not in {} (it has {})",
                run.display(),
                present.join(", ")
            );
        }
    }
    Ok(asked.to_vec())
}

/// One pipeline's states, placed on the globe through the run's track map where they are
/// along-track, written in time order; how many were written.
fn export_pipeline(
    run: &Run,
    pipeline: &str,
    channel: FusedChannel,
    every_ns: u64,
    writer: &mut dyn ExportWriter,
) -> Result<u64> {
    let topic = match channel {
        FusedChannel::Smoothed => topics::fused_smoothed(pipeline),
        _ => topics::fused_state(pipeline),
    };
    let mut map: Option<TrackMap> = None;
    let (mut written, mut unplaced, mut last) = (0u64, 0u64, None::<u64>);
    let io = |e: std::io::Error| anyhow::anyhow!("writing {pipeline}: {e}");
    writer.begin(pipeline).map_err(io)?;
    let mut reader = run.reader()?;
    while let Some(record) = reader.next() {
        let LogRecord::Message(m) = record? else {
            continue;
        };
        let path: &Path = run.name();
        if m.channel.topic == topics::TRACK_MAP {
            map = Some(m.decode(path)?);
            continue;
        }
        if m.channel.topic != topic {
            continue;
        }
        let state: FusedState = m.decode(path)?;
        if last.is_some_and(|t| state.stamp_ns < t + every_ns) {
            continue;
        }
        let Some(geo) = state.geodetic(map.as_ref()) else {
            unplaced += 1;
            continue;
        };
        last = Some(state.stamp_ns);
        let point = ExportPoint {
            stamp_ns: state.stamp_ns,
            geo,
            chainage_m: state.chainage_m,
            speed_mps: state.speed_mps,
            speed_sigma_mps: state.covariance[4].max(0.0).sqrt(),
        };
        writer.point(&point).map_err(io)?;
        written += 1;
    }
    writer.end().map_err(io)?;
    if written == 0 && unplaced > 0 {
        anyhow::bail!(
            "{}: {pipeline}'s {unplaced} states are along the track and the log has no track map \
             ({}) to place them on: re-fuse with --track LINE.geojson",
            run.display(),
            topics::TRACK_MAP
        );
    }
    if unplaced > 0 {
        eprintln!(
            "warning: {pipeline}: {unplaced} states not placed (before the track map, or not finite)"
        );
    }
    Ok(written)
}
