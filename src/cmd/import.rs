use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Result;
use railfuse_can::dbc::{BusDbcs, Database};
use railfuse_catalog::formats::csv_table;
use railfuse_catalog::formats::Storage;
use railfuse_record::decode::nmea;
use railfuse_record::import::can_log::{self, CanLog};
use railfuse_record::import::{converted, eth, gnss_file, ImportReport};
use railfuse_record::recorder::StreamFormat;

#[derive(clap::Args)]
pub struct Args {
    /// The log to convert.
    #[arg(required_unless_present = "example_map")]
    pub input: Option<PathBuf>,
    /// The railfuse MCAP log to write.
    #[arg(short, long, required_unless_present = "example_map")]
    pub output: Option<PathBuf>,
    /// Input format. Without it, it is told from the input: a directory with metadata.yaml
    /// is a ROS 2 bag, `#ROSBAG V2.0` a ROS 1 bag, a `<gpx` document GPX, bytes B5 62 UBX, a line that checks as an NMEA sentence NMEA, `HH:MM:SS.ffffff,X,hex`
    /// lines an ETH node log, a `(stamp) can0 123#…` line a candump log, a `date` or `base`
    /// line an ASC log, bytes `LOGG` a BLF log, and `--map` a CSV table.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// UTC date (YYYY-MM-DD) of NMEA fixes that come before any RMC or ZDA sentence. Without
    /// it they wait for the first such sentence, and any that never get a date are dropped
    /// and counted (never stamped 1970).
    #[arg(long, value_parser = parse_date)]
    pub date: Option<(i64, u32, u32)>,
    /// Write DIR/mapping.toml, a CSV mapping with a channel of every message type and the
    /// fields each requires, and DIR/example.csv, a table it imports; then stop.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["input", "output", "format", "map"])]
    pub example_map: Option<PathBuf>,
    /// The vehicle's DBC: a CAN log's known messages are also written decoded, one channel
    /// per message (`/can/<bus>/<Message>`), beside every frame raw (`/can/<bus>/frames`).
    /// Only with a CAN log (candump, asc, blf, mdf4).
    /// A bus's own DBC is `BUS=FILE` (`--dbc CAN2=gnss.dbc --dbc CAN1=obd2.dbc`: each bus
    /// decoded with its own); a plain FILE decodes every bus no other names.
    #[arg(long, value_name = "[BUS=]VEHICLE.dbc")]
    pub dbc: Vec<String>,
    #[command(flatten)]
    pub formats: super::run_input::FormatArgs,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
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
    /// A CAN bus log of can-utils' `candump -l`: `(1700000000.123456) can0 123#DEADBEEF`.
    Candump,
    /// A CAN bus log in Vector's ASC (CANalyzer, CANoe).
    Asc,
    /// A CAN bus log in Vector's BLF (binary; CANalyzer, CANoe, python-can).
    Blf,
    /// A GPX 1.0 or 1.1 track (phones, Garmin units, handheld loggers) into /gnss/fix.
    Gpx,
    /// ASAM MDF 4 CAN bus logging (CANedge, Vector): frames, and with --dbc their signals.
    Mdf4,
    /// A ROS 1 bag (format 2.0; uncompressed, bz2 or lz4 chunks; with or without its index),
    /// its channels kept as `ros1msg`.
    Rosbag1,
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

/// `--dbc [BUS=]FILE`, each read and checked; one for a bus at most.
pub fn bus_dbcs(args: &[String]) -> Result<BusDbcs> {
    let mut out = BusDbcs::default();
    for arg in args {
        let (bus, path) = BusDbcs::parse_arg(arg);
        if out.0.iter().any(|(b, _)| *b == bus) {
            anyhow::bail!(
                "--dbc {arg}: a second DBC for {}: one a bus",
                bus.as_deref()
                    .map_or("every bus".into(), |b| format!("bus {b}"))
            );
        }
        out.0.push((bus, Arc::new(Database::open(&path)?)));
    }
    Ok(out)
}

/// The first line of a Vector ASC log: `date …` or `base hex …`.
fn asc_header(line: &str) -> bool {
    let l = line.trim_start().to_ascii_lowercase();
    l.starts_with("date ") || l.starts_with("base hex") || l.starts_with("base dec")
}

/// The format of `input`, told from its first bytes (or `--map`), or why it cannot be.
fn detect(input: &std::path::Path, map: bool) -> Result<Format> {
    use std::io::Read;
    if input.is_dir() {
        return match input.join("metadata.yaml").exists() {
            true => Ok(Format::Rosbag2),
            false => anyhow::bail!(
                "{}: a directory without metadata.yaml is not a ROS 2 bag",
                input.display()
            ),
        };
    }
    let mut head = Vec::with_capacity(512);
    std::fs::File::open(input)
        .and_then(|f| f.take(512).read_to_end(&mut head))
        .map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?;
    let text = String::from_utf8_lossy(&head);
    let first_line = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    let eth_line = |l: &str| {
        let mut fields = l.split(',');
        let time = fields.next().unwrap_or("");
        let kind = fields.next().unwrap_or("");
        time.len() >= 8
            && time.as_bytes()[2] == b':'
            && time.as_bytes()[5] == b':'
            && kind.len() == 1
            && fields.next().is_some()
    };
    match () {
        _ if head.starts_with(b"\x89MCAP") => anyhow::bail!(
            "{} is already an MCAP log: nothing to import (railfuse info shows what it holds)",
            input.display()
        ),
        _ if head.starts_with(&[0xb5, 0x62]) => Ok(Format::Ubx),
        _ if head.starts_with(b"LOGG") => Ok(Format::Blf),
        _ if railfuse_catalog::formats::looks_like_gpx(&head) => Ok(Format::Gpx),
        _ if railfuse_catalog::formats::looks_like_mdf4(&head) => Ok(Format::Mdf4),
        _ if head.starts_with(b"#ROSBAG V") => Ok(Format::Rosbag1),
        // A mapping names a table's columns (or an MDF file's measured channels, above).
        _ if map => Ok(Format::Csv),
        _ if railfuse_can::candump::parse_line(first_line).is_ok() => Ok(Format::Candump),
        _ if asc_header(first_line) => Ok(Format::Asc),
        _ if first_line.starts_with('$') => Ok(Format::Nmea),
        _ if eth_line(first_line) => Ok(Format::Eth),
        // A line that checks as a sentence (from its last `$`: a capture that starts
        // mid-sentence or under a comment header).
        _ if text.lines().any(|l| nmea::parse(l).is_ok()) => Ok(Format::Nmea),
        _ => anyhow::bail!(
            "{}: cannot tell its format from its first line; name it with --format \
             (eth, nmea, ubx, csv with --map, rosbag2, rosbag1, candump, asc, blf, gpx, mdf4)",
            input.display()
        ),
    }
}

pub fn run(a: Args) -> Result<()> {
    if let Some(dir) = &a.example_map {
        return write_example(dir);
    }
    let (Some(input), Some(output)) = (a.input.clone(), a.output.clone()) else {
        anyhow::bail!("import needs an input and -o OUTPUT");
    };
    let format = match a.format {
        Some(f) => f,
        None => {
            let f = detect(&input, a.formats.map.is_some())?;
            crate::say!("format: {} (told from the input)", format_name(f));
            f
        }
    };
    if a.formats.map.is_some() && !matches!(format, Format::Csv | Format::Mdf4) {
        anyhow::bail!(
            "--map is the column mapping of --format csv (or mdf4), not of --format {}",
            format_name(format)
        );
    }
    let can = matches!(
        format,
        Format::Candump | Format::Asc | Format::Blf | Format::Mdf4
    );
    if !a.dbc.is_empty() && !can {
        anyhow::bail!(
            "--dbc decodes a CAN log (--format candump, asc, blf or mdf4), not --format {}",
            format_name(format)
        );
    }
    let report: ImportReport = match format {
        Format::Eth => {
            let size = std::fs::metadata(&input).map_or(0, |m| m.len());
            let bar = crate::progress::Progress::bytes("import", size);
            let report = eth::import_with_progress(&input, &output, &|done| bar.set(done))?;
            bar.finish();
            report
        }
        Format::Nmea => gnss_file::import(&input, &output, StreamFormat::Nmea, a.date)?,
        Format::Ubx => gnss_file::import(&input, &output, StreamFormat::Ubx, a.date)?,
        Format::Rosbag2 => {
            converted::import(Storage::Sqlite3, &input, &output, &a.formats.options()?)?
        }
        Format::Gpx => converted::import(Storage::Gpx, &input, &output, &a.formats.options()?)?,
        Format::Rosbag1 => {
            converted::import(Storage::Rosbag1, &input, &output, &a.formats.options()?)?
        }
        Format::Csv => converted::import(Storage::Csv, &input, &output, &a.formats.options()?)?,
        Format::Mdf4 if a.formats.map.is_some() => {
            converted::import(Storage::Mdf4, &input, &output, &a.formats.options()?)?
        }
        Format::Candump | Format::Asc | Format::Blf | Format::Mdf4 => {
            let dbc = bus_dbcs(&a.dbc)?;
            let log = match format {
                Format::Asc => CanLog::Asc,
                Format::Blf => CanLog::Blf,
                Format::Mdf4 => CanLog::Mdf4,
                _ => CanLog::Candump,
            };
            can_log::import(&input, &output, log, dbc)?
        }
    };
    // An import that found nothing is wrong input, not an empty log.
    if report.messages == 0 {
        let _ = std::fs::remove_file(&output);
        anyhow::bail!(nothing_imported(&input, format, &report));
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_report(&report);
    Ok(())
}

/// `--example-map DIR`: a mapping and a CSV it reads, to start from.
fn write_example(dir: &Path) -> Result<()> {
    let (mapping, table) = csv_table::example::example();
    std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
    for (name, text) in [("mapping.toml", mapping), ("example.csv", table)] {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    println!(
        "wrote {0}/mapping.toml and {0}/example.csv: railfuse import {0}/example.csv --map {0}/mapping.toml -o example.mcap",
        dir.display()
    );
    Ok(())
}

/// Why an import found no message: the reasons lines were not used, else the first problem.
fn nothing_imported(input: &Path, format: Format, report: &ImportReport) -> String {
    // Why: the reasons lines were not used, else the first problem.
    let reasons: Vec<String> = report
        .skipped
        .iter()
        .map(|(why, n)| format!("{n} × {why}"))
        .collect();
    let first = match (reasons.is_empty(), report.first_problems.first()) {
        (false, _) => format!(" ({})", reasons.join("; ")),
        (true, Some(p)) => format!(" (the first problem: {p})"),
        (true, None) => String::new(),
    };
    format!(
        "{}: no {} message in it{first}: is it a {} file? Name its format with --format",
        input.display(),
        format_name(format),
        format_name(format)
    )
}

/// What was imported, per topic, and what was not used.
fn print_report(report: &ImportReport) {
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
    for (warning, n) in &report.warnings {
        println!("warning: {n} × {warning}");
    }
    for f in &report.frames {
        println!("frame: {f}");
    }
}

fn format_name(f: Format) -> String {
    use clap::ValueEnum;
    f.to_possible_value()
        .map_or_else(|| format!("{f:?}"), |v| v.get_name().to_owned())
}
