//! `railfuse`: the command-line front end. A thin layer over the workspace crates: parse the
//! arguments, call the library, print tables or JSON, and turn every error into one line on
//! stderr with a non-zero exit.

mod cmd;
mod progress;
mod table;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "railfuse",
    version,
    about = "MCAP log recorder and offline re-fusion toolkit for train speed and position testing"
)]
struct Cli {
    /// No progress output (bars on a terminal, periodic lines otherwise) and no informational
    /// lines; results, warnings and errors are still printed.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Do not add Foxglove twins (foxglove.LocationFix of GNSS fixes and fused positions,
    /// foxglove.GeoJSON of the track, foxglove.Log of events, on /foxglove/…) to the logs this
    /// command writes.
    #[arg(long, global = true)]
    no_foxglove: bool,
    /// How the logs this command writes encode railfuse's channels (and their Foxglove
    /// twins): `protobuf` (the default; schemas embedded as a FileDescriptorSet) or `json`
    /// (railfuse's first encoding). Every command reads both.
    #[arg(long, global = true, value_name = "json|protobuf")]
    encoding: Option<railfuse_catalog::protobuf::Encoding>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a test run (truth and every sensor) and write it as an MCAP log.
    Simulate(cmd::simulate::Args),
    /// Show what a log holds: channels, rates, gaps, metadata, attachments, fused pipelines.
    Info(cmd::info::Args),
    /// Replay a log through the pipelines of a config file and write the fused log.
    Refuse(cmd::refuse::Args),
    /// Record live sources (UDP/TCP JSON lines, NMEA/UBX serial, files, stdin, the simulator)
    /// into a crash-safe MCAP log.
    Record(Box<cmd::record::Args>),
    /// Convert an existing log (ETH-PBL node, NMEA/UBX, CSV, ROS 2 bag, CAN logs, GPX) into
    /// railfuse channels.
    Import(cmd::import::Args),
    /// Write a run's files (split parts, several recorders' files, a bag) as one log, merged
    /// by time, or as parts of a chosen size or span.
    Merge(cmd::merge::Args),
    /// Salvage every intact record of a damaged log (crash, power cut) into a complete log.
    Recover(cmd::recover::Args),
    /// Tune a pipeline's noise values (process noise, sensor variances, sensor states, gates)
    /// over one or many logs, and write the tuned configuration.
    Tune(cmd::tune::Args),
    /// Find the IMU's mounting angles from runs over a mapped line (with σ, and which angles
    /// the runs cannot show), and write the train with them for `refuse --vehicle`.
    Calibrate(cmd::calibrate::Args),
    /// Accuracy of a fused log's pipelines against a reference, whole run and marked windows.
    Eval(cmd::eval::Args),
    /// Fit the track's centre line and chainage to the GNSS fixes of runs over it, and write
    /// it as the GeoJSON (or CSV) that `--track` reads.
    Track(cmd::track::Args),
    /// Write a fused run's positions, with their time and uncertainty, as GPX, KML, GeoJSON or
    /// CSV (for GIS tools and people who do not run railfuse).
    Export(cmd::export::Args),
    /// Log a (raw or fused) log to the Rerun viewer or an .rrd file.
    Viz(cmd::viz::Args),
    /// The whole path in one go: simulate, re-fuse, print accuracy, write a Rerun recording.
    Demo(cmd::demo::Args),
    /// Re-run sources 000 and 001's experiments over several seeds and write the results table.
    Results(cmd::results::Args),
    /// Measure simulate, write and refuse throughput and refuse's peak memory.
    Bench(cmd::bench::Args),
}

fn main() -> ExitCode {
    // Like any Unix filter: when the reader of our output goes away (`railfuse info … | head`),
    // end quietly instead of failing on the write.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // A bug must not greet a field engineer with a backtrace: one line that says what and
    // where, and that it is railfuse's fault. (Recorder sources catch theirs and go on.)
    std::panic::set_hook(Box::new(|info| {
        let what = railfuse_record::recorder::sources::panic_text(info.payload());
        let at = info
            .location()
            .map_or(String::new(), |l| format!(" at {l}"));
        let thread = std::thread::current();
        eprintln!(
            "railfuse: internal error in thread '{}' (a bug; please report it): {what}{at}",
            thread.name().unwrap_or("unnamed")
        );
    }));
    let cli = Cli::parse();
    progress::set_quiet(cli.quiet);
    railfuse_catalog::foxglove::set_twins_by_default(!cli.no_foxglove);
    if let Some(e) = cli.encoding {
        railfuse_catalog::protobuf::set_encoding_by_default(e);
    }
    let result = match cli.command {
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Info(a) => cmd::info::run(a),
        Command::Refuse(a) => cmd::refuse::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Track(a) => cmd::track::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Tune(a) => cmd::tune::run(a),
        Command::Calibrate(a) => cmd::calibrate::run(a),
        Command::Recover(a) => cmd::recover::run(a),
        Command::Merge(a) => cmd::merge::run(a),
        Command::Import(a) => cmd::import::run(a),
        Command::Record(a) => cmd::record::run(*a),
        Command::Viz(a) => cmd::viz::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Results(a) => cmd::results::run(a),
        Command::Bench(a) => cmd::bench::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("railfuse: error: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// One line: the chain of causes joined by ": ", the file named at its head; a cause an outer
/// message already quotes (`{path}: {source}`) is not said twice.
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}
