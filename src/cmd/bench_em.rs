//! `railfuse bench --em`: railfuse's EM against pykalman's `KalmanFilter.em` on the same
//! linear-Gaussian data (a constant-acceleration run with position and speed measured), from
//! the same start, the same number of iterations, Q and R estimated: both estimates, their
//! difference and both run times, in one run.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, SMatrix, SVector};
use railfuse_refuse::filter::em::LinearGaussian;
use railfuse_refuse::model::{ConstantAcceleration, ProcessNoise, TransitionModel};
use serde::Serialize;

const SCRIPT: &str = include_str!("../../bench/pykalman_em.py");

/// The comparison's settings: the CA model at 10 Hz, white jerk of PSD 0.2 m²/s⁵ (the
/// default pipeline's), position and speed variances 0.01 (source 000's loop and radar).
const DT_S: f64 = 0.1;
const TRUE_JERK_PSD: f64 = 0.2;
const TRUE_R: [f64; 2] = [0.01, 0.01];
/// EM starts 10x off in Q and R.
const START_JERK_PSD: f64 = 2.0;
const START_R: [f64; 2] = [0.1, 0.1];

#[derive(Debug, Serialize)]
pub struct EmComparison {
    pub steps: usize,
    pub iterations: usize,
    pub railfuse_q: Vec<Vec<f64>>,
    pub railfuse_r: Vec<Vec<f64>>,
    pub pykalman_q: Vec<Vec<f64>>,
    pub pykalman_r: Vec<Vec<f64>>,
    /// ‖Q_railfuse − Q_pykalman‖_F / ‖Q_pykalman‖_F, and the same for R.
    pub q_relative_difference: f64,
    pub r_relative_difference: f64,
    /// Median of the runs, EM alone (no data generation, no interpreter start).
    pub railfuse_s: f64,
    pub pykalman_s: f64,
    pub speedup: f64,
}

fn model(jerk_psd: f64, r: [f64; 2]) -> LinearGaussian<3, 2> {
    let ca = ConstantAcceleration {
        noise: ProcessNoise::WhiteJerkPsd(jerk_psd),
    };
    LinearGaussian {
        transition: ca.transition(DT_S),
        observation: SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
        process_noise: ca.process_noise(DT_S),
        measurement_noise: SMatrix::<f64, 2, 2>::new(r[0], 0.0, 0.0, r[1]),
        initial_mean: SVector::<f64, 3>::new(0.0, 20.0, 0.0),
        initial_covariance: SMatrix::<f64, 3, 3>::identity(),
    }
}

fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Vec<Vec<f64>> {
    (0..R)
        .map(|i| (0..C).map(|j| m[(i, j)]).collect())
        .collect()
}

fn relative(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let m = |x: &[Vec<f64>]| {
        DMatrix::from_row_iterator(x.len(), x[0].len(), x.iter().flatten().copied())
    };
    (m(a) - m(b)).norm() / m(b).norm()
}

/// Runs both and compares. `repeat` runs of railfuse's EM (the median is reported); one of
/// pykalman's (it takes minutes at full size).
pub fn compare(
    python: &Path,
    dir: &Path,
    steps: usize,
    iterations: usize,
    repeat: usize,
) -> Result<EmComparison> {
    let truth = model(TRUE_JERK_PSD, TRUE_R);
    let z = truth.sample(steps, 12, SVector::<f64, 3>::new(0.0, 20.0, 0.0));
    let start = model(START_JERK_PSD, START_R);
    let mut times = Vec::new();
    let mut ours = start.clone();
    for _ in 0..repeat.max(1) {
        ours = start.clone();
        let t = Instant::now();
        ours.em(&z, iterations, true, true);
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let railfuse_s = times[times.len() / 2];

    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let script = dir.join("pykalman_em.py");
    std::fs::write(&script, SCRIPT)?;
    let data = dir.join("em-data.json");
    let json = serde_json::json!({
        "transition": rows(&start.transition),
        "observation": rows(&start.observation),
        "process_noise": rows(&start.process_noise),
        "measurement_noise": rows(&start.measurement_noise),
        "initial_mean": start.initial_mean.iter().collect::<Vec<_>>(),
        "initial_covariance": rows(&start.initial_covariance),
        "measurements": z.iter().map(|v| v.iter().copied().collect::<Vec<_>>()).collect::<Vec<_>>(),
        "iterations": iterations,
    });
    std::fs::write(&data, serde_json::to_vec(&json)?)?;
    let out = Command::new(python)
        .arg(&script)
        .arg(&data)
        .output()
        .with_context(|| format!("{}: cannot run", python.display()))?;
    if !out.status.success() {
        bail!(
            "pykalman's EM failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    #[derive(serde::Deserialize)]
    struct Theirs {
        q: Vec<Vec<f64>>,
        r: Vec<Vec<f64>>,
        seconds: f64,
    }
    let theirs: Theirs = serde_json::from_slice(&out.stdout).context("pykalman's EM output")?;
    let (railfuse_q, railfuse_r) = (rows(&ours.process_noise), rows(&ours.measurement_noise));
    Ok(EmComparison {
        steps,
        iterations,
        q_relative_difference: relative(&railfuse_q, &theirs.q),
        r_relative_difference: relative(&railfuse_r, &theirs.r),
        railfuse_q,
        railfuse_r,
        pykalman_q: theirs.q,
        pykalman_r: theirs.r,
        railfuse_s,
        pykalman_s: theirs.seconds,
        speedup: theirs.seconds / railfuse_s,
    })
}

pub fn run(
    python: Option<PathBuf>,
    dir: &Path,
    steps: usize,
    iterations: usize,
    json: bool,
) -> Result<()> {
    let Some(python) = python else {
        bail!("bench --em: no Python with pykalman (run tests/run once, or give --python)");
    };
    let c = compare(&python, dir, steps, iterations, 5)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&c)?);
        return Ok(());
    }
    print_comparison(&c);
    Ok(())
}

pub fn print_comparison(c: &EmComparison) {
    println!(
        "EM on a constant-acceleration run: {} steps, {} iterations, Q (3x3) and R (2x2) estimated from the same start",
        c.steps, c.iterations
    );
    let show = |m: &[Vec<f64>]| {
        m.iter()
            .map(|r| {
                r.iter()
                    .map(|x| format!("{x:.6e}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    println!("  railfuse  Q = [{}]", show(&c.railfuse_q));
    println!("  pykalman  Q = [{}]", show(&c.pykalman_q));
    println!("  railfuse  R = [{}]", show(&c.railfuse_r));
    println!("  pykalman  R = [{}]", show(&c.pykalman_r));
    println!(
        "  relative difference (Frobenius): Q {:.2e}, R {:.2e}",
        c.q_relative_difference, c.r_relative_difference
    );
    println!(
        "  time: railfuse {:.4} s, pykalman {:.2} s: {:.0}x",
        c.railfuse_s, c.pykalman_s, c.speedup
    );
}
