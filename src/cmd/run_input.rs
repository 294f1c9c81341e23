//! The run a command reads, as every command that reads logs takes it: one or more files,
//! directories of parts or ROS 2 bag directories, with each file's clock and the time basis.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;
use railfuse_catalog::formats::csv_table::mapping::MappingFile;
use railfuse_catalog::formats::gpx::{Elevation, GpxOptions, HdopMeaning};
use railfuse_catalog::formats::FormatOptions;
use railfuse_catalog::log::SplitRule;
use railfuse_catalog::run::{Align, ClockOffset, Run, RunOptions, TimeBasis};
use railfuse_eval::outages::{OutageSpec, Withhold};

#[derive(clap::Args, Debug, Clone, Default)]
pub struct RunArgs {
    /// The run: an MCAP file, several files (the parts of a split recording, the files of
    /// several recorders), a directory of parts, a ROS 2 bag directory (its metadata.yaml),
    /// or files of other tools' formats (a GPX track, an MDF4 bus log, a logger's CSV with
    /// --map).
    #[arg(value_name = "LOG")]
    pub inputs: Vec<PathBuf>,
    /// A file's (or an input's) clock against the run's: FILE=SECONDS[,DRIFTppm], positive
    /// for a clock ahead (its times are moved back). May be given for each file.
    #[arg(long = "clock-offset", value_name = "FILE=SECONDS")]
    pub clock_offsets: Vec<ClockOffset>,
    /// The time that orders the merged run and is each message's time: log (when recorded),
    /// publish (when sent) or stamp (when the sensor measured it, each part held back 2 s).
    #[arg(long = "time", value_name = "log|publish|stamp", default_value = "log")]
    pub time: TimeBasis,
    /// Read a bag whose metadata.yaml lists a file that is not there, naming the gap.
    #[arg(long)]
    pub allow_missing_parts: bool,
    /// Put several recorders on one clock: gnss estimates each input's offset and drift from
    /// the GNSS time it logged (time references, else GNSS fixes) and moves every input onto
    /// the first one's clock, the stamps it took included. A --clock-offset given wins.
    #[arg(long, value_name = "none|gnss")]
    pub align: Option<Align>,
    #[command(flatten)]
    pub formats: FormatArgs,
}

/// How files of other tools' formats are read, as a run or an import.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct FormatArgs {
    /// What a GPX file's hdop holds: dop (a dilution of precision, as GPX says: the
    /// pipeline's GNSS variance applies) or metres[:P] (an accuracy in metres, the radius
    /// holding P % of fixes, 68 without P, as phone apps write it: each fix's σ).
    #[arg(long, value_name = "dop|metres[:P]", default_value = "dop")]
    pub gpx_hdop: HdopMeaning,
    /// What a GPX file's ele is: msl (height above sea level, as GPX units write it) or
    /// ellipsoid (above WGS-84's ellipsoid).
    #[arg(long, value_name = "msl|ellipsoid", default_value = "msl")]
    pub gpx_ele: Elevation,
    /// The column mapping of a logger's CSV, or of an MDF 4 file's measured channels (TOML):
    /// its time (`[time]` column or columns, unit or strftime format, zone, spread of whole
    /// seconds), what its columns are in (`[columns]` scale, offset, unit), and per
    /// `[[channel]]` its `topic`, `type`, `fields = { field = "column" }` and `constants`.
    /// `railfuse import --example-map DIR` writes one for every message type;
    /// samples/loggers/ has a GNSS logger's, a phone's and an MDF 4 measurement's.
    #[arg(long, value_name = "MAPPING.toml")]
    pub map: Option<PathBuf>,
}

impl RunArgs {
    /// The run, resolved and checked (one line naming the file if it cannot be read).
    pub fn open(&self) -> Result<Run> {
        self.open_with(&[], None)
    }

    /// [`open`](Self::open) with a configuration's `[run]` clocks and alignment, which the
    /// command line's win over.
    pub fn open_with(&self, clock_offsets: &[ClockOffset], align: Option<Align>) -> Result<Run> {
        if self.inputs.is_empty() {
            anyhow::bail!("name the log to read: a file, several files, a directory or a bag");
        }
        // Applied in order: a file the command line names again takes the command line's.
        let mut clocks = clock_offsets.to_vec();
        clocks.extend(self.clock_offsets.iter().cloned());
        let run = Run::open(
            &self.inputs,
            &RunOptions {
                time: self.time,
                clock_offsets: clocks,
                allow_missing_parts: self.allow_missing_parts,
                align: self.align.or(align).unwrap_or_default(),
                formats: self.formats.options()?,
            },
        )?;
        say_conversions(&run);
        if let Some(alignment) = run.alignment() {
            for e in alignment.estimates.iter().flatten() {
                crate::say!(
                    "{}",
                    format!(
                    "{}: clock {:+.6} s, {:+.2} ppm against GNSS time (from {} pairs of {}, residual rms {:.3} ms)",
                    e.input.display(),
                    e.clock.offset_s(),
                    e.clock.drift_ppm,
                    e.pairs,
                    e.source.label(),
                    e.residual_rms_ns / 1e6
                    )
                );
            }
            for n in alignment.unaligned() {
                eprintln!(
                    "warning: {}: left on its own clock: {}; give --clock-offset {}=SECONDS",
                    n.input.display(),
                    n.cause,
                    n.input.display()
                );
            }
        }
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

impl FormatArgs {
    /// How files of other tools' formats are read (the mapping file read and checked).
    pub fn options(&self) -> Result<FormatOptions> {
        let csv = match &self.map {
            Some(path) => Some(Arc::new(MappingFile::read(path)?)),
            None => None,
        };
        Ok(FormatOptions {
            gpx: GpxOptions {
                hdop: self.gpx_hdop,
                elevation: self.gpx_ele,
            },
            csv,
        })
    }
}

/// What each converted part read, and where it was damaged.
fn say_conversions(run: &Run) {
    for (path, c) in run.conversions() {
        let skipped = match c.skipped.is_empty() {
            true => String::new(),
            false => format!("; not used: {}", c.reasons()),
        };
        let gaps = match c.gaps {
            0 => String::new(),
            n => format!(", {n} segment breaks"),
        };
        crate::say!(
            "{}: {} records read, {} messages{gaps}{skipped}",
            path.display(),
            c.rows,
            c.messages
        );
        for w in &c.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        for f in &c.frames {
            crate::say!("{}: frame {f}", path.display());
        }
        if let Some(d) = &c.damage {
            eprintln!(
                "warning: {}: {d}; the {} messages before it are read",
                path.display(),
                c.messages
            );
        }
    }
}

/// How a command that writes a run writes it in parts (merge, refuse).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SplitArgs {
    /// Write parts of about this many MiB each: OUT-001.mcap, OUT-002.mcap, …
    #[arg(long, value_name = "MIB")]
    pub split_size: Option<f64>,
    /// Write parts spanning this many seconds each.
    #[arg(long, value_name = "SECONDS")]
    pub split_every: Option<f64>,
    /// Begin a new part at each of these times (seconds from the run's first message).
    #[arg(long, value_delimiter = ',', value_name = "SECONDS,…")]
    pub split_at: Vec<f64>,
    /// Begin a new part where each file of the input begins: fused parts beside raw parts.
    #[arg(long)]
    pub split_as_input: bool,
}

/// Where a part begins after every part before it has ended (within 1 s: a split boundary's
/// messages may straddle it), from the run's first message: a split run's boundaries, none
/// for recorders that run side by side.
fn sequential_starts(spans: &[Option<(u64, u64)>]) -> Vec<u64> {
    const STRADDLE_NS: u64 = 1_000_000_000;
    let mut spans: Vec<(u64, u64)> = spans.iter().flatten().copied().collect();
    spans.sort_unstable();
    let Some(&(first, end)) = spans.first() else {
        return Vec::new();
    };
    let mut ended = end;
    let mut starts = Vec::new();
    for &(a, b) in &spans[1..] {
        if a + STRADDLE_NS >= ended && a > first {
            starts.push(a - first);
        }
        ended = ended.max(b);
    }
    starts
}

/// Seconds as given on the command line, checked, in ns.
fn seconds_ns(flag: &str, s: f64) -> Result<u64> {
    anyhow::ensure!(s.is_finite() && s > 0.0, "{flag} {s}: expected seconds > 0");
    Ok((s * 1e9).round() as u64)
}

impl SplitArgs {
    /// The rule, checked; the input's part starts for --split-as-input.
    pub fn rule(&self, run: &Run) -> Result<SplitRule> {
        let mut at_ns = self
            .split_at
            .iter()
            .map(|&s| seconds_ns("--split-at", s))
            .collect::<Result<Vec<_>>>()?;
        if self.split_as_input {
            let splits = sequential_starts(&run.part_spans()?);
            if splits.is_empty() {
                eprintln!(
                    "warning: --split-as-input: {}'s files run side by side (several \
                     recorders), not one after another: the output is one file",
                    run.display()
                );
            }
            at_ns.extend(splits);
        }
        at_ns.sort_unstable();
        at_ns.dedup();
        let bytes = match self.split_size {
            Some(mib) => {
                anyhow::ensure!(
                    mib.is_finite() && mib > 0.0,
                    "--split-size {mib}: expected MiB > 0"
                );
                Some((mib * (1 << 20) as f64) as u64)
            }
            None => None,
        };
        Ok(SplitRule {
            bytes,
            every_ns: self
                .split_every
                .map(|s| seconds_ns("--split-every", s))
                .transpose()?,
            at_ns,
        })
    }
}

/// A sensor withheld from the pipelines in outages (the withholding protocol), as `refuse`,
/// `eval` and `tune` take it.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct WithholdArgs {
    /// Withhold a sensor (an RTK receiver) inside the --outages windows (the whole run
    /// without them) and score against it, the reference unless --reference names another:
    /// refuse hides it from every pipeline that fuses it, tune tunes by cross-validation
    /// against it, eval scores a log fused elsewhere as if it had been hidden.
    #[arg(long, value_name = "TOPIC")]
    pub withhold: Option<String>,
    /// The outages of --withhold: LEN[:every=PERIOD][:from=T] in s (the first starts 60 s
    /// into the run unless from= says otherwise), or standard (30, 60 and 120 s in turn, one
    /// every 180 s).
    #[arg(long, value_name = "SPEC", requires = "withhold")]
    pub outages: Option<OutageSpec>,
}

impl WithholdArgs {
    /// What was asked for, if anything.
    pub fn request(&self) -> Option<Withhold> {
        self.withhold.as_ref().map(|topic| Withhold {
            topic: topic.clone(),
            outages: self.outages.clone(),
        })
    }
}
