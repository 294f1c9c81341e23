//! The run a command reads, as every command that reads logs takes it: one or more files,
//! directories of parts or ROS 2 bag directories, with each file's clock and the time basis.

use std::path::PathBuf;

use anyhow::Result;
use railfuse_catalog::run::{ClockOffset, Run, RunOptions, TimeBasis};

#[derive(clap::Args, Debug, Clone, Default)]
pub struct RunArgs {
    /// The run: an MCAP file, several files (the parts of a split recording, the files of
    /// several recorders), a directory of parts, or a ROS 2 bag directory (its metadata.yaml).
    #[arg(value_name = "LOG")]
    pub inputs: Vec<PathBuf>,
    /// A file's (or an input's) clock against the run's: FILE=SECONDS[,DRIFTppm], positive
    /// for a clock ahead (its times are moved back). May be given for each file.
    #[arg(long = "clock-offset", value_name = "FILE=SECONDS")]
    pub clock_offsets: Vec<ClockOffset>,
    /// The time that orders the merged run and is each message's time: log (when recorded)
    /// or publish (when sent).
    #[arg(long = "time", value_name = "log|publish", default_value = "log")]
    pub time: TimeBasis,
    /// Read a bag whose metadata.yaml lists a file that is not there, naming the gap.
    #[arg(long)]
    pub allow_missing_parts: bool,
}

impl RunArgs {
    /// The run, resolved and checked (one line naming the file if it cannot be read).
    pub fn open(&self) -> Result<Run> {
        if self.inputs.is_empty() {
            anyhow::bail!("name the log to read: a file, several files, a directory or a bag");
        }
        let run = Run::open(
            &self.inputs,
            &RunOptions {
                time: self.time,
                clock_offsets: self.clock_offsets.clone(),
                allow_missing_parts: self.allow_missing_parts,
            },
        )?;
        for missing in run.missing() {
            eprintln!(
                "warning: {}: listed in the bag's metadata.yaml but not there: {} messages{} left out",
                missing.path.display(),
                missing.messages.map_or("its".into(), |n| n.to_string()),
                match (missing.start_ns, missing.duration_ns) {
                    (Some(t), Some(d)) => format!(
                        " from log time {t} ns for {:.1} s",
                        d as f64 / 1e9
                    ),
                    _ => String::new(),
                }
            );
        }
        Ok(run)
    }
}
