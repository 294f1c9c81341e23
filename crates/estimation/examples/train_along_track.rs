//! A train along its track, filtered and smoothed with nothing but this crate: a
//! constant-acceleration Kalman filter fed a loop's chainage every second and a radar's speed
//! ten times a second, then an RTS pass backwards. Run it with
//!
//!     cargo run -p railfuse-estimation --example train_along_track
//!
//! It prints the filtered and smoothed position errors against the simulated truth: the
//! smoothed ones, using the measurements after each epoch as well, are smaller.

use nalgebra::{Matrix3, RowVector3, Vector3};
use railfuse_estimation::filter::rts::rts_step;
use railfuse_estimation::filter::{KalmanFilter, StateAndCovariance};
use railfuse_estimation::model::{ConstantAcceleration, ProcessNoise, TransitionModel};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

fn main() {
    let model = ConstantAcceleration {
        noise: ProcessNoise::WhiteJerkPsd(0.02),
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let (loop_noise, radar_noise) = (
        Normal::new(0.0, 0.3).unwrap(),
        Normal::new(0.0, 0.1).unwrap(),
    );
    let chainage = RowVector3::new(1.0, 0.0, 0.0);
    let speed = RowVector3::new(0.0, 1.0, 0.0);
    let dt = 0.1;

    // Starts 20 m/s, accelerates at 0.5 m/s² for 30 s, then brakes at 0.8 m/s².
    let truth = |t: f64| -> Vector3<f64> {
        let a = if t < 30.0 { 0.5 } else { -0.8 };
        let (t1, v1) = (t.min(30.0), 20.0 + 0.5 * t.min(30.0));
        let s1 = 20.0 * t1 + 0.25 * t1 * t1;
        let t2 = (t - 30.0).max(0.0);
        Vector3::new(s1 + v1 * t2 - 0.4 * t2 * t2, v1 - 0.8 * t2, a)
    };

    let mut kf = KalmanFilter::new(
        Vector3::new(0.0, 20.0, 0.0),
        Matrix3::from_diagonal(&Vector3::new(1.0, 4.0, 1.0)),
    );
    let (mut filtered, mut priors) = (Vec::new(), Vec::new());
    for k in 1..=600 {
        let t = k as f64 * dt;
        kf.predict(&model, dt);
        priors.push(kf.estimate.clone());
        let x = truth(t);
        kf.update(&speed, 0.01, x[1] + radar_noise.sample(&mut rng));
        if k % 10 == 0 {
            kf.update(&chainage, 0.09, x[0] + loop_noise.sample(&mut rng));
        }
        filtered.push(kf.estimate.clone());
    }

    // Rauch–Tung–Striebel, backwards: each epoch's smoothed estimate from the next one's.
    let f = model.transition(dt);
    let mut smoothed: Vec<StateAndCovariance<3>> = vec![filtered.last().unwrap().clone()];
    for k in (0..filtered.len() - 1).rev() {
        let next = smoothed.last().unwrap().clone();
        smoothed.push(rts_step(&filtered[k], &priors[k + 1], &f, &next));
    }
    smoothed.reverse();

    let rms = |estimates: &[StateAndCovariance<3>]| {
        let sum: f64 = estimates
            .iter()
            .enumerate()
            .map(|(k, e)| (e.state[0] - truth((k + 1) as f64 * dt)[0]).powi(2))
            .sum();
        (sum / estimates.len() as f64).sqrt()
    };
    println!(
        "position RMS error over 60 s: filtered {:.3} m, smoothed {:.3} m",
        rms(&filtered),
        rms(&smoothed)
    );
    assert!(rms(&smoothed) < rms(&filtered));
}
