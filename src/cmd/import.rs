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
    /// Input format: `eth` (ETH-PBL railway node CSV: raw IMU, UBX frames as hex, NMEA,
    /// correction-link and station events), `nmea` or `ubx` (a GNSS receiver's capture), `csv`
    /// (any table, with `--map`).
    #[arg(long, default_value = "eth")]
    pub format: String,
    /// The column mapping of a CSV import (TOML; see `railfuse import --help` and the README).
    #[arg(long, value_name = "MAPPING.toml")]
    pub map: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let report: ImportReport = match a.format.as_str() {
        "eth" => eth::import(&a.input, &a.output)?,
        "nmea" => gnss_file::import(&a.input, &a.output, StreamFormat::Nmea)?,
        "ubx" => gnss_file::import(&a.input, &a.output, StreamFormat::Ubx)?,
        "csv" => {
            let Some(map) = &a.map else {
                anyhow::bail!(
                    "--format csv needs --map MAPPING.toml (the column of each message field)"
                )
            };
            csv_map::import(&a.input, map, &a.output)?
        }
        other => anyhow::bail!("--format {other}: unknown (formats: eth, nmea, ubx, csv)"),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "imported {} lines of {} as {} messages -> {}",
        report.lines,
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
