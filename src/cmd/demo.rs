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
    // The default pipeline with sensor states (honest about its covariance) and without,
    // side by side, as one config.
    let (text, config) = railfuse_experiments::long_runs::side_by_side()?;
    std::fs::write(&config_path, &text)
        .with_context(|| format!("{}: cannot write", config_path.display()))?;
    let source = "embedded samples/sensor-states.toml + samples/kalman.toml".into();
    let truth = railfuse_eval::Reference::topic(railfuse_catalog::topics::GROUND_TRUTH);
    let (_, eval) = refuse_and_evaluate(&raw, &fused, &config, source, &truth)?;
    let on_bus = can_bus(dir, a.seed, &truth, &eval)?;
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
        (&on_bus, "the run on the CAN bus, re-fused from its frames"),
    ] {
        println!("  {:<40} {what}", p.display());
    }
    println!("open the recording with: rerun {}", rrd.display());
    Ok(())
}

/// The kalman pipeline's position RMSE in an evaluation, m.
fn kalman_rmse(eval: &railfuse_eval::EvalReport) -> Option<f64> {
    let p = eval.pipelines.iter().find(|p| p.name == "kalman")?;
    Some(p.position_error_m.as_ref()?.rmse)
}

/// The same run with its odometers and radar on the vehicle's CAN bus (samples/vehicle.dbc),
/// re-fused from the frames alone with samples/can.toml: its fused log.
fn can_bus(
    dir: &std::path::Path,
    seed: u64,
    truth: &railfuse_eval::Reference,
    own: &railfuse_eval::EvalReport,
) -> Result<PathBuf> {
    let (raw, fused) = (dir.join("run-can.mcap"), dir.join("run-can.fused.mcap"));
    let (dbc, config_path) = (dir.join("vehicle.dbc"), dir.join("can.toml"));
    super::simulate::simulate_to("default", seed, None, &[], true, &raw)?;
    std::fs::write(&dbc, railfuse_record::simulator::can_bus::VEHICLE_DBC)
        .with_context(|| format!("{}: cannot write", dbc.display()))?;
    std::fs::write(&config_path, include_str!("../../samples/can.toml"))
        .with_context(|| format!("{}: cannot write", config_path.display()))?;
    let config = railfuse_refuse::spec::Pipelines::load(&config_path)?;
    let source = "embedded samples/can.toml".into();
    let run = railfuse_catalog::run::Run::file(&raw);
    let (_, eval, _) =
        super::refuse::refuse_with(&run, &fused, &config, source, (truth, None), None)?;
    if let (Some(bus), Some(channels)) = (kalman_rmse(&eval), kalman_rmse(own)) {
        println!(
            "\nthe same run with its odometers and radar on the vehicle's CAN bus, re-fused from \
             the frames alone (samples/can.toml): kalman position RMSE {bus:.3} m ({channels:.3} m \
             from their own channels)"
        );
    }
    Ok(fused)
}
