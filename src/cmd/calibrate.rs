//! `railfuse calibrate`: the IMU's mounting angles from runs over a mapped line, written as a
//! `[vehicle]` table that `refuse --vehicle` (or a configuration) takes.

use std::path::PathBuf;

use anyhow::Result;
use railfuse_calibrate::mounting::MountingPriors;
use railfuse_calibrate::{calibrate, Calibration};
use railfuse_catalog::messages::Vehicle;
use railfuse_catalog::run::{Run, RunOptions};
use railfuse_refuse::config::VehicleConfig;
use railfuse_refuse::spec::Pipelines;

use super::run_input::FormatArgs;
use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The runs: each an MCAP file, a directory of parts or a bag, over a line its track map
    /// covers (with heights and cant where the line has them).
    #[arg(value_name = "RUN", required = true)]
    pub runs: Vec<PathBuf>,
    /// The configuration whose first Kalman pipeline, without the IMU, gives the train's
    /// motion (and whose `[vehicle]` and track win over the log's). Without one, each run's
    /// default pipeline.
    #[arg(short, long)]
    pub config: Option<PathBuf>,
    /// The track map for runs without one, when no configuration is given.
    #[arg(long, conflicts_with = "config")]
    pub track: Option<PathBuf>,
    /// The IMU's topic (needed when a run has several).
    #[arg(long, value_name = "TOPIC")]
    pub imu: Option<String>,
    /// How fast the accelerometer's bias may wander, m/s² per √s.
    #[arg(long, value_name = "M/S²/√S", default_value_t = MountingPriors::default().accel_bias_walk)]
    pub accel_bias_walk: f64,
    /// How fast the gyro's bias may wander, rad/s per √s.
    #[arg(long, value_name = "RAD/S/√S", default_value_t = MountingPriors::default().gyro_bias_walk)]
    pub gyro_bias_walk: f64,
    /// Where to write the train with the calibrated mounting (a TOML `[vehicle]` table).
    #[arg(short, long, value_name = "vehicle.toml")]
    pub output: PathBuf,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub formats: FormatArgs,
}

pub fn run(a: Args) -> Result<()> {
    super::check_writable(&a.output)?;
    let priors = MountingPriors {
        accel_bias_walk: a.accel_bias_walk,
        gyro_bias_walk: a.gyro_bias_walk,
        ..Default::default()
    };
    for (name, v) in [
        ("--accel-bias-walk", priors.accel_bias_walk),
        ("--gyro-bias-walk", priors.gyro_bias_walk),
    ] {
        if !(v.is_finite() && v > 0.0) {
            anyhow::bail!("{name} {v}: must be a positive number");
        }
    }
    let options = RunOptions {
        formats: a.formats.options()?,
        ..Default::default()
    };
    let loaded = a.config.as_deref().map(Pipelines::load).transpose()?;
    let mut runs = Vec::new();
    for path in &a.runs {
        let run = Run::open(std::slice::from_ref(path), &options)?;
        let config = match &loaded {
            Some(c) => c.clone(),
            None => {
                let default =
                    railfuse_refuse::default_config::default_config(&run, a.track.as_deref())?;
                default.pipelines(&PathBuf::from(format!(
                    "{} (default pipeline)",
                    run.display()
                )))?
            }
        };
        runs.push((run, config));
    }
    crate::say!(
        "replaying {} run(s) without the IMU for the train's motion ({})",
        runs.len(),
        match &a.config {
            Some(c) => format!("the first Kalman pipeline of {}", c.display()),
            None => "each run's default pipeline, as refuse picks it".into(),
        }
    );
    let c = calibrate(&runs, a.imu.as_deref(), &priors)?;
    let read_by = &runs[0].1;
    let vehicle = only_read(c.vehicle(), read_by, &c.imu);
    std::fs::write(&a.output, vehicle_toml(&c, &vehicle, &a.runs)?)
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.output.display()))?;
    let truth = simulated_truth(&a.runs[0], &c.imu);
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json(&c, truth.as_ref()))?
        );
    } else {
        print!("{}", table(&c, truth.as_ref()));
        print_notes(&c);
    }
    crate::say!(
        "the train with the calibrated mounting -> {}",
        a.output.display()
    );
    Ok(())
}

/// The sensors of `v` a pipeline of `config` reads (what `[vehicle]` may name), the IMU
/// always.
fn only_read(mut v: Vehicle, config: &Pipelines, imu: &str) -> Vehicle {
    v.sensors.retain(|s| {
        s.topic == imu
            || config
                .pipeline
                .iter()
                .any(|p| p.sensor_for(&s.topic).is_some())
    });
    v
}

fn vehicle_toml(c: &Calibration, v: &Vehicle, runs: &[PathBuf]) -> Result<String> {
    #[derive(serde::Serialize)]
    struct File {
        vehicle: VehicleConfig,
    }
    let e = &c.estimate;
    let [sr, sp, sy] = e.sigma_deg();
    let seen = c.observable();
    let names = ["roll", "pitch", "yaw"];
    let unseen: Vec<&str> = (0..3).filter(|i| !seen[*i]).map(|i| names[i]).collect();
    let mut head = format!(
        "# The train, with {}'s mounting calibrated by `railfuse calibrate` from {}\n\
         # ({} one-second bins): σ roll {sr:.3}°, pitch {sp:.3}°, yaw {sy:.3}°.\n",
        c.imu,
        runs.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        e.bins
    );
    if !unseen.is_empty() {
        head += &format!(
            "# Not seen by these runs, so the drawing's value is kept: {}.\n",
            unseen.join(", ")
        );
    }
    head += "# Use it with `railfuse refuse RUN --vehicle THIS_FILE`, or copy it into a configuration.\n\n";
    let body = toml::to_string(&File {
        vehicle: VehicleConfig::of(v),
    })?;
    Ok(head + &body)
}

/// A simulated run's true mounting of `imu` (its `vehicle_installed` metadata), to show the
/// error beside the σ.
fn simulated_truth(run: &std::path::Path, imu: &str) -> Option<[f64; 3]> {
    let meta = railfuse_catalog::log::read_metadata(run, "railfuse.run").ok()??;
    let installed: Vehicle = serde_json::from_str(meta.get("vehicle_installed")?).ok()?;
    installed.mount(imu).map(|m| m.mounting_deg)
}

fn table(c: &Calibration, truth: Option<&[f64; 3]>) -> String {
    let drawn = c.drawn_mount().mounting_deg;
    let fitted = c.estimate.mounting_deg();
    let sigma = c.estimate.sigma_deg();
    let seen = c.observable();
    let mut header = vec!["angle", "drawing °", "calibrated °", "σ °", "seen"];
    if truth.is_some() {
        header.extend(["simulated truth °", "error °", "error/σ"]);
    }
    let mut t = Table::new(&header);
    for (i, name) in ["roll", "pitch", "yaw"].iter().enumerate() {
        let mut row = vec![
            name.to_string(),
            format!("{:.3}", drawn[i]),
            format!("{:.3}", fitted[i]),
            format!("{:.3}", sigma[i]),
            (if seen[i] { "yes" } else { "no" }).to_string(),
        ];
        if let Some(t) = truth {
            let error = fitted[i] - t[i];
            row.extend([
                format!("{:.3}", t[i]),
                format!("{error:+.3}"),
                format!("{:.1}", error.abs() / sigma[i]),
            ]);
        }
        t.row(row);
    }
    format!(
        "{} mounting from {} run(s), {} one-second bins:\n{t}",
        c.imu,
        c.runs.len(),
        c.estimate.bins
    )
}

fn print_notes(c: &Calibration) {
    let e = &c.estimate;
    let [ax, ay, az] = e.accel_bias;
    let [gx, gy, gz] = e.gyro_bias.map(|b| b.to_degrees() * 3600.0);
    println!("biases at the end: accelerometer [{ax:.4}, {ay:.4}, {az:.4}] m/s², gyro [{gx:.1}, {gy:.1}, {gz:.1}] °/h");
    let r = e.residual_rms;
    println!(
        "residual RMS (low-passed, 0.1 Hz): force [{:.3}, {:.3}, {:.3}] m/s², rate [{:.4}, {:.4}, {:.4}] rad/s ({} passes)",
        r[0], r[1], r[2], r[3], r[4], r[5], e.passes
    );
    for u in &c.runs {
        if u.left_out > 0 {
            println!(
                "{}: {} bins left out (gaps, or no reference state near them)",
                u.input, u.left_out
            );
        }
    }
    let names = ["roll", "pitch", "yaw"];
    for (i, seen) in c.observable().iter().enumerate() {
        if !seen {
            println!(
                "{} is not seen by these runs (σ {:.0} % of its prior's): the drawing's value is kept; \
                 a run with {} shows it",
                names[i],
                100.0 * e.sigma_share[i],
                ["curves (cant deficiency, yaw rate)", "acceleration and braking, or curves", "acceleration and braking, or gradients"][i]
            );
        }
    }
}

fn json(c: &Calibration, truth: Option<&[f64; 3]>) -> serde_json::Value {
    let e = &c.estimate;
    serde_json::json!({
        "imu": c.imu,
        "drawing_deg": c.drawn_mount().mounting_deg,
        "mounting_deg": e.mounting_deg(),
        "sigma_deg": e.sigma_deg(),
        "observable": c.observable(),
        "sigma_share": e.sigma_share,
        "accel_bias_mps2": e.accel_bias,
        "gyro_bias_radps": e.gyro_bias,
        "residual_rms": e.residual_rms,
        "residual_correlation": e.correlation,
        "bins": e.bins,
        "passes": e.passes,
        "runs": c.runs,
        "simulated_truth_deg": truth,
    })
}
