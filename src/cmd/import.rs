use std::path::PathBuf;

use anyhow::Result;
use railfuse_record::import::{csv_map, eth, gnss_file, ImportReport};
use railfuse_record::recorder::StreamFormat;

#[derive(clap::Args)]
pub struct Args {
    /// The log to convert.
    pub input: PathBuf,
    /// The railfuse MCAP log to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Input format.
    #[arg(long, value_enum, default_value_t = Format::Eth)]
    pub format: Format,
    /// UTC date (YYYY-MM-DD) of NMEA fixes that come before any RMC or ZDA sentence. Without
    /// it they wait for the first such sentence, and any that never get a date are dropped
    /// and counted (never stamped 1970).
    #[arg(long, value_parser = parse_date)]
    pub date: Option<(i64, u32, u32)>,
    /// The column mapping of a CSV import (TOML; see `railfuse import --help` and the README).
    #[arg(long, value_name = "MAPPING.toml")]
    pub map: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Format {
    /// ETH-PBL railway node CSV: raw IMU, UBX frames as hex, NMEA, correction-link and
    /// station events.
    Eth,
    /// A GNSS receiver's NMEA 0183 capture.
    Nmea,
    /// A GNSS receiver's u-blox UBX capture.
    Ubx,
    /// Any table, with `--map`.
    Csv,
    /// A ROS 2 bag in the sqlite3 storage (a directory of .db3 files), to MCAP.
    Rosbag2,
}

fn parse_date(s: &str) -> Result<(i64, u32, u32), String> {
    let bad = || format!("'{s}' is not a date YYYY-MM-DD");
    let mut parts = s.splitn(3, '-');
    let mut next = || {
        parts
            .next()
            .and_then(|p| p.parse::<i64>().ok())
            .ok_or_else(bad)
    };
    let (y, m, d) = (next()?, next()?, next()?);
    let on_calendar =
        (1..=12).contains(&m) && railfuse_record::decode::time::is_date(y, m as u32, d as u32);
    if !(1970..=9999).contains(&y) || !on_calendar {
        return Err(bad());
    }
    Ok((y, m as u32, d as u32))
}

pub fn run(a: Args) -> Result<()> {
    let report: ImportReport = match a.format {
        Format::Eth => {
            let size = std::fs::metadata(&a.input).map_or(0, |m| m.len());
            let bar = crate::progress::Progress::bytes("import", size);
            let report = eth::import_with_progress(&a.input, &a.output, &|done| bar.set(done))?;
            bar.finish();
            report
        }
        Format::Nmea => gnss_file::import(&a.input, &a.output, StreamFormat::Nmea, a.date)?,
        Format::Ubx => gnss_file::import(&a.input, &a.output, StreamFormat::Ubx, a.date)?,
        Format::Rosbag2 => railfuse_record::import::rosbag2::import(&a.input, &a.output)?,
        Format::Csv => {
            let Some(map) = &a.map else {
                anyhow::bail!(
                    "--format csv needs --map MAPPING.toml (the column of each message field)"
                )
            };
            csv_map::import(&a.input, map, &a.output)?
        }
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    let read = if report.lines > 0 || report.bytes == 0 {
        format!("{} lines", report.lines)
    } else {
        format!("{} bytes", report.bytes)
    };
    println!(
        "imported {read} of {} as {} messages -> {}",
        report.input.display(),
        report.messages,
        report.output.display()
    );
    for (topic, n) in &report.per_topic {
        println!("  {topic:<14} {n}");
    }
    println!("time base: {}", report.time_base);
    for (why, n) in &report.skipped {
        println!("not used: {n} × {why}");
    }
    for p in &report.first_problems {
        println!("  {p}");
    }
    Ok(())
}
