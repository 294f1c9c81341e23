use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use railfuse_record::recorder::{
    record, RecordOptions, SourceSpec, SourcesFile, SpecError, Status,
};

#[derive(clap::Args)]
pub struct Args {
    /// The MCAP log to write (`<name>.partial` until it is finished).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Listen for JSON lines on this UDP port. Repeatable.
    #[arg(long, value_name = "PORT")]
    pub udp: Vec<u16>,
    /// Listen on this TCP port for streams: PORT[:json|nmea|ubx] (default json). Repeatable.
    /// Any FORMAT may be written FORMAT=/topic to send a receiver's fixes to their own channel.
    #[arg(long, value_name = "PORT[:FORMAT]")]
    pub tcp: Vec<String>,
    /// Connect to a receiver or gateway: HOST:PORT[:json|nmea|ubx]; reconnects with backoff.
    #[arg(long = "tcp-client", value_name = "HOST:PORT[:FORMAT]")]
    pub tcp_client: Vec<String>,
    /// A serial device: DEVICE:BAUD[:nmea|ubx|json] (default nmea). Repeatable.
    #[arg(long, value_name = "DEVICE:BAUD[:FORMAT]")]
    pub serial: Vec<String>,
    /// A file of NMEA, UBX or JSON lines: PATH[:FORMAT] (default by extension). Repeatable.
    #[arg(long, value_name = "PATH[:FORMAT]")]
    pub file: Vec<String>,
    /// The vehicle's CAN bus: a SocketCAN interface (`can0`), an SLCAN serial adapter
    /// (`slcan:/dev/ttyACM0[:BITRATE[:TTYBAUD]]`, 500 kbit/s unless told), a socketcand server
    /// (`socketcand:HOST:PORT[:BUS]`) or a cannelloni gateway (`cannelloni:PORT[:BUS]`). Every
    /// frame is logged on /can/<bus>/frames. Repeatable.
    #[arg(long, value_name = "ADAPTER")]
    pub can: Vec<String>,
    /// The vehicle's DBC: the CAN sources' known messages are also logged decoded, one channel
    /// each (/can/<bus>/<Message>). Read and checked before recording starts.
    #[arg(long, value_name = "VEHICLE.dbc")]
    pub dbc: Option<PathBuf>,
    /// Read standard input: FORMAT[=/TOPIC], FORMAT one of json, nmea, ubx (default json);
    /// `=/TOPIC` sends a receiver's fixes to their own channel.
    #[arg(long, value_name = "FORMAT")]
    pub stdin: Option<String>,
    /// Record the embedded simulator in real time (the default when no source is given).
    #[arg(long, value_name = "SCENARIO",
          value_parser = super::scenarios())]
    pub simulate: Option<String>,
    /// Simulator: the seed of its random streams (the same seed gives the same run).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulator: how many times faster than real time it plays (1 = real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Address the network listeners bind to (127.0.0.1 unless you open them up).
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Stop after this many seconds (default: at Ctrl-C / SIGTERM, or when every source ends).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Start a new numbered file (`run-001.mcap`, `run-002.mcap`, …) past this many MiB.
    #[arg(long, value_name = "MIB")]
    pub split_size: Option<f64>,
    /// … or every this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub split_every: Option<f64>,
    /// Sources from a TOML file of `[[source]]` tables (added to those given by flags), e.g.
    /// `udp = 5600`, or `serial = "/dev/ttyACM0"` with `baud = 115200`, `format = "ubx"`,
    /// `topic = "/gnss/rx2"`, or `can = "slcan:/dev/ttyACM0:500000"`; and `[can] dbc =
    /// "vehicle.dbc"` to decode the CAN sources (`--dbc` wins).
    #[arg(long, value_name = "FILE")]
    pub sources: Option<PathBuf>,
    /// Run metadata from a TOML file of KEY = "value" lines (flags override it).
    #[arg(long, value_name = "FILE")]
    pub meta_file: Option<PathBuf>,
    /// Close a chunk at least this often: what a crash can lose, at most.
    #[arg(long, default_value_t = 1.0)]
    pub chunk_interval: f64,
    /// Messages each source may queue before it drops (and counts) new ones.
    #[arg(long, default_value_t = 65_536)]
    pub queue: usize,
    /// Run metadata KEY=VALUE (run, train, operator, route, notes, …). Repeatable.
    #[arg(long = "meta", value_name = "KEY=VALUE")]
    pub meta: Vec<String>,
    /// Stream the incoming channels to a Rerun viewer while recording: `spawn` starts one,
    /// or a viewer URL (e.g. rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, value_name = "spawn|URL")]
    pub viz: Option<String>,
    /// Print the final report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Every source: the flags' specs, then a sources file's tables, listeners bound to `--bind`,
/// the simulator (also when nothing else is given) with `--seed` and `--speed`.
fn sources(a: &Args) -> Result<Vec<SourceSpec>> {
    let flags = a
        .udp
        .iter()
        .map(|p| ("udp", p.to_string()))
        .chain(a.tcp.iter().map(|t| ("tcp", t.clone())))
        .chain(a.tcp_client.iter().map(|t| ("tcp-client", t.clone())))
        .chain(a.serial.iter().map(|t| ("serial", t.clone())))
        .chain(a.file.iter().map(|t| ("file", t.clone())))
        .chain(a.can.iter().map(|t| ("can", t.clone())))
        .chain(a.stdin.iter().map(|t| ("stdin", t.clone())));
    let mut out = Vec::new();
    for (kind, args) in flags {
        out.push(SourceSpec::from_flag(kind, &args).map_err(|e| match e {
            SpecError::Bad { what, .. } => anyhow::anyhow!("--{kind} {args}: {what}"),
            other => anyhow::anyhow!("--{kind} {args}: {other}"),
        })?);
    }
    if let Some(path) = &a.sources {
        let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
        // toml's message names the line and column and the table's own error.
        let file: SourcesFile = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.to_string().trim()))?;
        out.extend(file.source);
        if let Some(can) = file.can.filter(|_| a.dbc.is_none()) {
            let dbc = path
                .parent()
                .unwrap_or(std::path::Path::new(""))
                .join(can.dbc);
            out = with_dbc(out, &dbc)?;
        }
    }
    if let Some(dbc) = &a.dbc {
        out = with_dbc(out, dbc)?;
    }
    if let Some(scenario) = &a.simulate {
        out.push(SourceSpec::from_flag("simulate", scenario)?);
    }
    if out.is_empty() {
        out.push(SourceSpec::from_flag("simulate", "")?);
    }
    if !(a.speed.is_finite() && a.speed > 0.0) {
        bail!("--speed must be positive, not {}", a.speed);
    }
    for spec in &mut out {
        if let SourceSpec::Simulated {
            scenario,
            seed,
            speed,
            ..
        } = spec
        {
            if railfuse_record::Scenario::preset(scenario).is_none() {
                bail!(
                    "--simulate {scenario}: unknown scenario (presets: {})",
                    railfuse_record::Scenario::NAMES.join(", ")
                );
            }
            (*seed, *speed) = (a.seed, a.speed);
        }
    }
    Ok(out.into_iter().map(|s| s.bind(a.bind)).collect())
}

/// The CAN sources decoding with the DBC at `path`, read and checked now: a broken DBC is
/// said before anything is recorded.
fn with_dbc(specs: Vec<SourceSpec>, path: &std::path::Path) -> Result<Vec<SourceSpec>> {
    if !specs.iter().any(|s| matches!(s, SourceSpec::Can { .. })) {
        bail!(
            "--dbc {}: no CAN source to decode (give one with --can)",
            path.display()
        );
    }
    let db = Arc::new(railfuse_can::dbc::Database::open(path)?);
    Ok(specs.into_iter().map(|s| s.with_dbc(&db)).collect())
}

fn status_line(s: &Status) -> String {
    let dropped: u64 = s.sources.iter().map(|x| x.dropped + x.kernel_dropped).sum();
    let bad: u64 = s
        .sources
        .iter()
        .map(|x| x.malformed + x.checksum_failures + x.oversized)
        .sum();
    let rates: Vec<String> = s
        .per_topic
        .iter()
        .map(|(t, n)| format!("{t} {:.0}/s", *n as f64 / s.elapsed_s.max(1e-9)))
        .collect();
    format!(
        "{:>7.1} s  {} msgs  {:.1} MiB  dropped {dropped}  bad {bad}  {}",
        s.elapsed_s,
        s.messages,
        s.bytes_written as f64 / (1 << 20) as f64,
        rates.join("  ")
    )
}

pub fn run(a: Args) -> Result<()> {
    let specs = sources(&a)?;
    check_serial_devices(&specs)?;
    let metadata = metadata(&a)?;
    check_sizes(&a)?;
    // Ctrl-C or SIGTERM finishes the file (summary, indexes) instead of killing the run.
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, stop.clone())
            .context("cannot install the Ctrl-C / SIGTERM handler")?;
    }
    let terminal = std::io::stderr().is_terminal();
    for s in &specs {
        crate::say!("recording {s}");
    }
    let opts = RecordOptions {
        output: a.output.clone(),
        sources: specs,
        chunk_interval: Duration::from_secs_f64(a.chunk_interval),
        duration: a.duration.map(Duration::from_secs_f64),
        split_bytes: a.split_size.map(|m| (m * (1 << 20) as f64) as u64),
        split_every: a.split_every.map(Duration::from_secs_f64),
        queue: a.queue,
        metadata,
        status: Some(status_printer(terminal)),
        tap: live_view(a.viz.as_deref())?,
    };
    let report = record(opts, stop)?;
    if terminal {
        eprintln!();
    }
    let files: Vec<String> = report
        .files
        .iter()
        .map(|f| f.display().to_string())
        .collect();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report, &files);
    }
    if let Some(e) = &report.write_error {
        let file = report.failed_file.as_ref().unwrap_or(&report.output);
        let partial = railfuse_catalog::log::partial_path(file);
        bail!(
            "recording stopped by a write error: {e}; every closed chunk is kept in {} \
             (`railfuse recover {} -o {}` salvages them)",
            partial.display(),
            partial.display(),
            file.display()
        );
    }
    if !report.failed_sources.is_empty() {
        bail!(
            "{} of {} sources failed: {}; everything received is in {}",
            report.failed_sources.len(),
            report.sources.len(),
            report.failed_sources.join("; "),
            files.join(", ")
        );
    }
    Ok(())
}

/// A serial device missing at the start is a wrong name far more often than a receiver about
/// to be plugged in: said now, not after a run of nothing. One that goes away during the run
/// is reconnected to.
fn check_serial_devices(specs: &[SourceSpec]) -> Result<()> {
    for s in specs {
        if let SourceSpec::Serial { path, .. } = s {
            if let Err(e) = std::fs::metadata(path) {
                bail!(
                    "serial {}: {e} (is the receiver plugged in? ls /dev/serial/by-id lists them)",
                    path.display()
                );
            }
        }
    }
    Ok(())
}

/// The run's metadata: `--meta-file`'s table, then each `--meta KEY=VALUE`.
fn metadata(a: &Args) -> Result<BTreeMap<String, String>> {
    let mut metadata = BTreeMap::new();
    if let Some(f) = &a.meta_file {
        let text = std::fs::read_to_string(f).with_context(|| format!("{}", f.display()))?;
        let table: toml::Table = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: {}", f.display(), e.message()))?;
        for (k, v) in table {
            metadata.insert(k, v.as_str().map_or_else(|| v.to_string(), str::to_owned));
        }
    }
    for m in &a.meta {
        let (k, v) = m
            .split_once('=')
            .with_context(|| format!("--meta {m}: KEY=VALUE"))?;
        metadata.insert(k.trim().to_owned(), v.to_owned());
    }
    Ok(metadata)
}

/// Split sizes and the chunk interval are positive.
fn check_sizes(a: &Args) -> Result<()> {
    for (what, v) in [
        ("--split-size", a.split_size),
        ("--split-every", a.split_every),
    ] {
        if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            bail!("{what} must be positive");
        }
    }
    if !(a.chunk_interval.is_finite() && a.chunk_interval > 0.0) {
        bail!(
            "--chunk-interval must be positive, not {}",
            a.chunk_interval
        );
    }
    Ok(())
}

/// What the recorder says while it runs: every notice and failed source at once, on its own
/// line; the status line redrawn on a terminal, else a plain line every 10 s (none with -q).
fn status_printer(terminal: bool) -> Box<dyn FnMut(&Status)> {
    let mut since_plain = 0u32;
    let (mut warned, mut said) = (0, 0);
    let clear = if terminal { "\r\x1b[2K" } else { "" };
    Box::new(move |s: &Status| {
        for n in &s.notices[said..] {
            eprintln!("{clear}warning: {n}");
        }
        said = s.notices.len();
        // A source that fails for good is said at once: the run goes on with the others, but
        // the engineer should not find out at the end of a three-hour run.
        for f in &s.failed_sources[warned..] {
            eprintln!("{clear}warning: source failed: {f}");
        }
        warned = s.failed_sources.len();
        if crate::progress::is_quiet() {
            return;
        }
        if terminal {
            eprint!("\r\x1b[2K{}", status_line(s));
        } else {
            since_plain += 1;
            if since_plain >= 10 {
                since_plain = 0;
                eprintln!("{}", status_line(s));
            }
        }
    })
}

/// The live viewer `--viz` names, fed every recorded message; one that goes away is said
/// once and the recording goes on.
fn live_view(target: Option<&str>) -> Result<Option<railfuse_record::recorder::TapHook>> {
    let Some(target) = target else {
        return Ok(None);
    };
    let sink = railfuse_viz::Sink::live(target);
    let mut live = railfuse_viz::LiveViz::open(&sink, &Default::default())?;
    let mut failed = false;
    Ok(Some(Box::new(
        move |item: &railfuse_record::recorder::message::Item| {
            if failed {
                return;
            }
            let (schema, json) = (item.message.kind().schema_name(), item.message.to_json());
            if let Err(e) = live.message(&item.topic, schema, item.log_time_ns, &json) {
                eprintln!("\nviewer: {e}; recording continues without it");
                failed = true;
            }
        },
    )))
}

/// The report in words: messages, files, and per source what came, went and why.
fn print_report(report: &railfuse_record::recorder::RecordReport, files: &[String]) {
    println!(
        "recorded {} messages in {:.1} s -> {} (stopped: {})",
        report.messages,
        report.duration_s,
        files.join(", "),
        report.stopped_by
    );
    for s in &report.sources {
        println!(
            "  {}: {} received, {} written, {} dropped by the recorder, {} by the kernel, {} malformed, {} checksum failures, {} oversized, {} reconnects{}",
            s.name,
            s.received,
            s.written,
            s.dropped,
            s.kernel_dropped,
            s.malformed,
            s.checksum_failures,
            s.oversized,
            s.reconnects,
            s.last_error.as_ref().map_or(String::new(), |e| format!(" (last error: {e})"))
        );
        for (reason, n) in &s.skipped {
            println!("    skipped {n:>8}  {reason}");
        }
        for p in &s.first_problems {
            println!("    {p}");
        }
        for (warning, n) in &s.warnings {
            println!("    warning {n:>8}  {warning}");
        }
    }
    if report.lost_to_write_error > 0 {
        println!(
            "  {} messages taken from the sources did not reach the disk before the write error",
            report.lost_to_write_error
        );
    }
}
