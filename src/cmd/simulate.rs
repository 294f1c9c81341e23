use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use railfuse_record::simulator::{FaultSpec, MAX_RECORDERS};
use railfuse_record::{simulate, simulate_recorders, Scenario, SimRecorder, SimulationReport};

#[derive(clap::Args)]
pub struct Args {
    /// Scenario preset.
    #[arg(long, default_value = "default",
          value_parser = super::scenarios())]
    pub scenario: String,
    /// Seed of every random draw: the same seed gives the same file.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Length of the run in seconds (default: the preset's whole run).
    #[arg(long)]
    pub duration: Option<f64>,
    #[arg(long = "fault", value_name = "DEVICE:MODE:START:END[:reported]", help = fault_help())]
    pub faults: Vec<FaultSpec>,
    /// Write the run as several recorders on a train write it, each its own file on its own
    /// clock with a PPS time reference: NAME[=SECONDS[,DRIFTppm]], one to three times. The
    /// first logs GNSS, IMU, map, events and truth; the second the odometry (and the radar,
    /// without a third); the third the radar. OUTPUT is then a folder of NAME.mcap files.
    #[arg(long = "recorder", value_name = "NAME[=SECONDS[,DRIFTppm]]")]
    pub recorders: Vec<SimRecorder>,
    /// Put the odometers and the radar on the vehicle's CAN bus, as samples/vehicle.dbc
    /// describes it: their readings are logged as raw frames on /can/can0/frames (WheelSpeed,
    /// AxlePulses, RadarSpeed) instead of on /odometer/N and /radar/speed. Re-fuse with a
    /// configuration that maps them back (samples/can.toml). Line scenarios only.
    #[arg(long)]
    pub can_bus: bool,
    /// Output MCAP file (a folder with --recorder).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let report = match a.recorders.is_empty() {
        true => simulate_to(
            &a.scenario,
            a.seed,
            a.duration,
            &a.faults,
            a.can_bus,
            &a.output,
        )?,
        false => simulate_recorders_to(&a)?,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}

/// A run written by several recorders, one file each in the output folder.
fn simulate_recorders_to(a: &Args) -> Result<SimulationReport> {
    let preset = preset(&a.scenario, a.duration, &a.faults, a.can_bus)?;
    if a.recorders.len() > MAX_RECORDERS {
        bail!("--recorder: at most {MAX_RECORDERS} recorders (GNSS/INS box, odometry rack, radar)");
    }
    let report = simulate_recorders(
        &preset,
        a.seed,
        a.duration,
        &a.faults,
        &a.recorders,
        &a.output,
    )?;
    if let Err(e) = Scenario::faults_within(report.duration_s, &a.faults) {
        report
            .files
            .iter()
            .for_each(|f| drop(std::fs::remove_file(f)));
        bail!("--{e}");
    }
    crate::say!(
        "simulated '{}' seed {}: {:.1} s of run, {} messages by {} recorders -> {}",
        report.scenario,
        a.seed,
        report.duration_s,
        report.messages,
        a.recorders.len(),
        report.files.join(", ")
    );
    Ok(report)
}

/// The scenario preset, checked against the duration and faults asked for.
fn preset(
    scenario: &str,
    duration: Option<f64>,
    faults: &[FaultSpec],
    can_bus: bool,
) -> Result<Scenario> {
    let Some(mut preset) = Scenario::preset(scenario) else {
        bail!(
            "unknown scenario '{scenario}' (presets: {})",
            Scenario::NAMES.join(", ")
        );
    };
    preset
        .check(duration, faults)
        .map_err(|e| anyhow::anyhow!("--{e}"))?;
    if can_bus {
        match preset.line_mut() {
            Some(p) => p.can_bus = true,
            None => bail!(
                "--can-bus: scenario '{scenario}' has no odometers or radar to put on a bus \
                 (line scenarios have)"
            ),
        }
    }
    Ok(preset)
}

/// Simulates and prints a one-paragraph summary to stderr; shared with `demo` and `bench`.
pub fn simulate_to(
    scenario: &str,
    seed: u64,
    duration: Option<f64>,
    faults: &[FaultSpec],
    can_bus: bool,
    output: &std::path::Path,
) -> Result<SimulationReport> {
    let preset = preset(scenario, duration, faults, can_bus)?;
    let started = Instant::now();
    let report = simulate(&preset, seed, duration, faults, output)?;
    // A preset's whole run is known only once driven: a fault after its end is said now.
    if let Err(e) = Scenario::faults_within(report.duration_s, faults) {
        let _ = std::fs::remove_file(output);
        bail!("--{e}");
    }
    let wall = started.elapsed().as_secs_f64();
    crate::say!(
        "simulated '{}' seed {}: {:.1} s of run, {:.2} km of track, {} messages in {:.2} s ({:.0} msg/s) -> {}",
        report.scenario,
        seed,
        report.duration_s,
        report.track_length_m / 1000.0,
        report.messages,
        wall,
        report.messages as f64 / wall,
        output.display()
    );
    Ok(report)
}

/// The `--fault` help, from the devices and modes the parser takes.
fn fault_help() -> String {
    format!(
        "Make a device fail for a window: DEVICE:MODE:START:END with DEVICE one of {}; MODE \
         dropout, stuck, bias=VALUE (SI units: a GNSS position jump along the track in m, a \
         speed in m/s, a specific force in m/s², a loop position in m), late=SECONDS (its \
         stamps that much late: a driver stamping on arrival), or for the map \
         offset=D (a stretch published D m to the left), for corrections only dropout (the \
         RTK correction link lost: single point, then float and fixed once it is back); START \
         and END in seconds from the start; `:reported` adds the device's own fault and recovery events. Repeatable.",
        railfuse_record::simulator::faults::DEVICES.join(", ")
    )
}
