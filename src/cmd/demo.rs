use std::path::PathBuf;

use anyhow::{Context, Result};
use railfuse_viz::{visualize, Sink};

use super::refuse::refuse_and_evaluate;

#[derive(clap::Args)]
pub struct Args {
    /// Folder for the outputs (created if missing).
    #[arg(short, long, default_value = "railfuse-demo")]
    pub output_dir: PathBuf,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

pub fn run(a: Args) -> Result<()> {
    let dir = &a.output_dir;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the output folder", dir.display()))?;
    let (raw, fused, rrd, config_path) = (
        dir.join("run.mcap"),
        dir.join("run.fused.mcap"),
        dir.join("run.rrd"),
        dir.join("pipelines.toml"),
    );
    super::simulate::simulate_to("default", a.seed, None, &[], false, &raw)?;
    // The default pipeline and the same with sensor states, side by side, as one config.
    let (text, config) = railfuse_experiments::long_runs::side_by_side()?;
    std::fs::write(&config_path, &text)
        .with_context(|| format!("{}: cannot write", config_path.display()))?;
    let source = "embedded samples/kalman.toml + samples/sensor-states.toml".into();
    refuse_and_evaluate(
        &raw,
        &fused,
        &config,
        source,
        &railfuse_eval::Reference::topic(railfuse_catalog::topics::GROUND_TRUTH),
    )?;
    let viz = visualize(
        &railfuse_catalog::run::Run::file(&fused),
        &Sink::Save(rrd.clone()),
        &Default::default(),
        &|_| {},
    )?;
    crate::say!(
        "logged {} rows on {} Rerun entities -> {}",
        viz.logged,
        viz.entities.len(),
        rrd.display()
    );
    println!("\noutputs in {}:", dir.display());
    for (p, what) in [
        (&raw, "simulated raw log"),
        (&config_path, "pipeline config used"),
        (&fused, "raw log + fused channels"),
        (&rrd, "Rerun recording"),
    ] {
        println!("  {:<40} {what}", p.display());
    }
    println!("open the recording with: rerun {}", rrd.display());
    Ok(())
}
