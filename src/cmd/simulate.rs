use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use railfuse_record::{simulate, Scenario, SimulationReport};

#[derive(clap::Args)]
pub struct Args {
    /// Scenario preset: `default` (a mixed line run with every sensor) or `seed000` (source
    /// 000's maglev simulation).
    #[arg(long, default_value = "default")]
    pub scenario: String,
    /// Seed of every random draw: the same seed gives the same file.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Length of the run in seconds (default: the preset's whole run).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Output MCAP file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let report = simulate_to(&a.scenario, a.seed, a.duration, &a.output)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}

/// Simulates and prints a one-paragraph summary to stderr; shared with `demo` and `bench`.
pub fn simulate_to(scenario: &str, seed: u64, duration: Option<f64>, output: &std::path::Path) -> Result<SimulationReport> {
    let Some(preset) = Scenario::preset(scenario) else {
        bail!("unknown scenario '{scenario}' (presets: {})", Scenario::NAMES.join(", "));
    };
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration must be a positive number of seconds, not {d}");
        }
    }
    let started = Instant::now();
    let report = simulate(&preset, seed, duration, output)?;
    let wall = started.elapsed().as_secs_f64();
    eprintln!(
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
