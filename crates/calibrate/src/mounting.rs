//! The IMU's mounting from what it read against what the train did: a Kalman filter over
//! one-second means of the IMU's specific force and rate, with the mounting's three small
//! angles constant and the accelerometer and gyro biases random walks, relinearised about
//! each pass's mounting until it settles (Gauss–Newton). No I/O: the bins come in, the
//! angles with their σ go out.
//!
//! The model: the IMU's axes are turned in the body by `M = M̂ exp([δθ×])` (the drawing's or
//! the last pass's `M̂`, a small correction `δθ` in the IMU's axes). What the train did gives
//! the specific force `f_b` and rate `ω_b` in the body ([`railfuse_catalog::train_motion`]);
//! the IMU reads `f = Mᵀ f_b + b_a` and `ω = Mᵀ ω_b + b_g`, so to first order
//!
//! ```text
//! f − M̂ᵀ f_b = [u×] δθ + b_a,   u = M̂ᵀ f_b
//! ω − M̂ᵀ ω_b = [w×] δθ + b_g,   w = M̂ᵀ ω_b
//! ```
//!
//! What makes each angle observable: gravity (u ≈ g ẑ) ties roll and pitch to the x and y
//! biases, so those come from what changes: the along-track acceleration and the gradient's
//! gravity leaking into z (pitch) and y (yaw), the unbalanced lateral acceleration of the
//! curves leaking into z (roll), and the curves' yaw rate leaking into the x and y gyros
//! (pitch and roll). A run without those cannot tell the angle from a bias; the filter's σ
//! then stays near its prior and the angle is reported as not observable.
//!
//! A tenth state is the reference's chainage error (the motion comes from a filter whose
//! chainage may be a few decimetres off, drifting as a loop's survey does): shifted along
//! the track the gradient, the vertical curves and the transitions come too early or late,
//! and in a vertical curve that reads exactly as pitch (a 0.4 m shift moved pitch by 0.1° in
//! the simulated railway before this state was added). Its column is `Mᵀ ∂(f_b, ω_b)/∂s`.
//!
//! The noise of a bin is found from the data: each pass takes the residuals' mean square per
//! axis, inflated by their integrated autocorrelation (ride vibration and the motion
//! reference's errors are not white over one-second bins), so the σ it reports is the spread
//! the residuals actually have, not an assumed one.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector3};

/// One second of IMU readings beside what the train did in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bin {
    /// Mid time, s from the run's first bin (for the biases' random walk).
    pub time_s: f64,
    /// Which run it comes from: the biases start afresh with each (a new turn-on bias).
    pub run: usize,
    /// Mean specific force and angular rate the IMU read, in its own axes.
    pub specific_force: Vector3<f64>,
    pub angular_rate: Vector3<f64>,
    /// What the train's motion gives in the body's axes at the IMU's place.
    pub body_force: Vector3<f64>,
    pub body_rate: Vector3<f64>,
    /// Their change per metre the reference's chainage is off, per m.
    pub body_force_per_m: Vector3<f64>,
    pub body_rate_per_m: Vector3<f64>,
}

/// How the IMU's biases may wander, and how far the mounting and biases may be at the start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountingPriors {
    /// σ of each angle's correction to the drawing, rad.
    pub angle_rad: f64,
    pub accel_bias_mps2: f64,
    pub gyro_bias_radps: f64,
    /// Random walks, per √s.
    pub accel_bias_walk: f64,
    pub gyro_bias_walk: f64,
    /// The reference's chainage error, m, and how fast it may wander, m per √s.
    pub chainage_m: f64,
    pub chainage_walk: f64,
}

impl Default for MountingPriors {
    fn default() -> Self {
        MountingPriors {
            angle_rad: 5f64.to_radians(),
            accel_bias_mps2: 0.1,
            gyro_bias_radps: 0.01,
            // Above a tactical IMU's (and the simulator's): the filter must not trust the
            // biases to hold still longer than they do.
            accel_bias_walk: 3e-4,
            gyro_bias_walk: 3e-5,
            chainage_m: 1.0,
            // A loop's survey drifts centimetres per kilometre; a GNSS fix pulls it back.
            chainage_walk: 0.02,
        }
    }
}

/// A pass's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct MountingEstimate {
    /// The IMU's axes in the body.
    pub mounting: Rotation3<f64>,
    /// σ of roll, pitch and yaw (about body x, y, z; small angles), rad.
    pub sigma_rad: [f64; 3],
    /// Each angle's σ as a share of its prior's: near 1, the runs could not tell it.
    pub sigma_share: [f64; 3],
    /// The biases at the end of the last run (accelerometer, m/s²; gyro, rad/s).
    pub accel_bias: [f64; 3],
    pub gyro_bias: [f64; 3],
    /// RMS of the residuals after the fit per axis (force x, y, z in m/s²; rate in rad/s).
    pub residual_rms: [f64; 6],
    /// The residuals' autocorrelation inflation per axis (1: white).
    pub correlation: [f64; 6],
    pub bins: usize,
    pub passes: usize,
}

impl MountingEstimate {
    /// Roll, pitch, yaw in degrees, as `[vehicle.sensor]`'s `mounting_deg` takes them.
    pub fn mounting_deg(&self) -> [f64; 3] {
        let (r, p, y) = self.mounting.euler_angles();
        [r.to_degrees(), p.to_degrees(), y.to_degrees()]
    }

    pub fn sigma_deg(&self) -> [f64; 3] {
        self.sigma_rad.map(f64::to_degrees)
    }
}

/// Above this share of the prior's σ an angle counts as not seen by the runs.
pub const UNOBSERVABLE_SHARE: f64 = 0.5;

/// `[δθ (3), b_a (3), b_g (3), δs]`.
const N: usize = 10;
type VectorN = SVector<f64, N>;
type MatrixN = SMatrix<f64, N, N>;
type Matrix6N = SMatrix<f64, 6, N>;
type Vector6 = SVector<f64, 6>;

/// Gauss–Newton passes at most, and the correction below which the mounting has settled.
const MAX_PASSES: usize = 8;
const SETTLED_RAD: f64 = 1e-6;
/// Lags over which the residuals' autocorrelation is summed, bins.
const MAX_LAG: usize = 60;

/// Fits the mounting to `bins` (in time order within each run) from the drawing's `drawing`.
pub fn fit_mounting(
    bins: &[Bin],
    drawing: Rotation3<f64>,
    priors: &MountingPriors,
) -> Option<MountingEstimate> {
    if bins.len() < 10 {
        return None;
    }
    let mut mounting = drawing;
    // First pass: the IMU's own white noise does not matter beside the bin's motion error.
    let mut noise = Vector6::new(0.05, 0.05, 0.05, 3e-3, 3e-3, 3e-3).map(|s| s * s);
    let mut passes = 0;
    loop {
        passes += 1;
        let pass = filter_pass(bins, mounting, noise, priors);
        let step = Vector3::new(pass.x[0], pass.x[1], pass.x[2]);
        mounting *= Rotation3::new(step);
        let (rms, correlation) = residual_spread(&pass.residuals);
        noise = Vector6::from_fn(|i, _| rms[i] * rms[i] * correlation[i]);
        if passes >= 2 && step.norm() < SETTLED_RAD || passes == MAX_PASSES {
            // One more pass at the settled mounting and noise gives the σ and biases.
            let last = filter_pass(bins, mounting, noise, priors);
            let (rms, correlation) = residual_spread(&last.residuals);
            let prior = priors.angle_rad;
            let sigma_rad = [0, 1, 2].map(|i| last.p[(i, i)].max(0.0).sqrt());
            return Some(MountingEstimate {
                mounting: mounting * Rotation3::new(Vector3::new(last.x[0], last.x[1], last.x[2])),
                sigma_rad,
                sigma_share: sigma_rad.map(|s| s / prior),
                accel_bias: [last.x[3], last.x[4], last.x[5]],
                gyro_bias: [last.x[6], last.x[7], last.x[8]],
                residual_rms: rms,
                correlation,
                bins: bins.len(),
                passes: passes + 1,
            });
        }
    }
}

struct Pass {
    x: VectorN,
    p: MatrixN,
    /// Per bin, the measurement less the fitted model (with the end's angles and each bin's
    /// own bias estimate before its update: the one-step innovations).
    residuals: Vec<[f64; 6]>,
}

fn prior_covariance(p: &MountingPriors, angles: bool) -> MatrixN {
    let mut d = VectorN::zeros();
    for i in 0..3 {
        d[i] = if angles {
            p.angle_rad * p.angle_rad
        } else {
            0.0
        };
        d[3 + i] = p.accel_bias_mps2 * p.accel_bias_mps2;
        d[6 + i] = p.gyro_bias_radps * p.gyro_bias_radps;
    }
    d[9] = p.chainage_m * p.chainage_m;
    MatrixN::from_diagonal(&d)
}

/// One forward pass of the filter at the mounting `m`.
fn filter_pass(bins: &[Bin], m: Rotation3<f64>, noise: Vector6, priors: &MountingPriors) -> Pass {
    let mut x = VectorN::zeros();
    let mut p = prior_covariance(priors, true);
    let r = SMatrix::<f64, 6, 6>::from_diagonal(&noise);
    let mut residuals = Vec::with_capacity(bins.len());
    let mut last: Option<&Bin> = None;
    for b in bins {
        match last {
            Some(l) if l.run == b.run => {
                let dt = (b.time_s - l.time_s).max(0.0);
                for i in 0..3 {
                    p[(3 + i, 3 + i)] += priors.accel_bias_walk.powi(2) * dt;
                    p[(6 + i, 6 + i)] += priors.gyro_bias_walk.powi(2) * dt;
                }
                p[(9, 9)] += priors.chainage_walk.powi(2) * dt;
            }
            Some(_) => {
                // A new run: the biases and the reference start again, the angles carry over.
                for i in 3..N {
                    x[i] = 0.0;
                }
                let fresh = prior_covariance(priors, false);
                let mut q = p;
                for i in 0..N {
                    for j in 0..N {
                        if i >= 3 || j >= 3 {
                            q[(i, j)] = fresh[(i, j)];
                        }
                    }
                }
                p = q;
            }
            None => {}
        }
        last = Some(b);
        let (z, h) = linearised(b, m);
        let innovation = z - h * x;
        residuals.push(std::array::from_fn(|i| innovation[i]));
        let s = h * p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            continue;
        };
        let k = p * h.transpose() * s_inv;
        x += k * innovation;
        // Joseph form: P stays symmetric and positive whatever the rounding.
        let ikh = MatrixN::identity() - k * h;
        p = ikh * p * ikh.transpose() + k * r * k.transpose();
        p = 0.5 * (p + p.transpose());
    }
    Pass { x, p, residuals }
}

/// The bin's measurement less the model at mounting `m`, and its Jacobian in
/// `[δθ, b_a, b_g, δs]`.
fn linearised(b: &Bin, m: Rotation3<f64>) -> (Vector6, Matrix6N) {
    let u = m.inverse() * b.body_force;
    let w = m.inverse() * b.body_rate;
    let zf = b.specific_force - u;
    let zw = b.angular_rate - w;
    let z = Vector6::new(zf.x, zf.y, zf.z, zw.x, zw.y, zw.z);
    let mut h = Matrix6N::zeros();
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&u.cross_matrix());
    h.fixed_view_mut::<3, 3>(3, 0).copy_from(&w.cross_matrix());
    h.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(3, 6)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 1>(0, 9)
        .copy_from(&(m.inverse() * b.body_force_per_m));
    h.fixed_view_mut::<3, 1>(3, 9)
        .copy_from(&(m.inverse() * b.body_rate_per_m));
    (z, h)
}

/// Per axis: the residuals' RMS, and `1 + 2 Σ ρ_k` over the lags until the autocorrelation
/// first drops to zero (the factor by which correlated residuals carry less information than
/// as many white ones).
fn residual_spread(residuals: &[[f64; 6]]) -> ([f64; 6], [f64; 6]) {
    let n = residuals.len().max(1) as f64;
    let mut rms = [0.0; 6];
    let mut correlation = [1.0; 6];
    for axis in 0..6 {
        let series: Vec<f64> = residuals.iter().map(|r| r[axis]).collect();
        let mean = series.iter().sum::<f64>() / n;
        let var = series.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        rms[axis] = (series.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        if var <= 0.0 {
            continue;
        }
        let mut tau = 1.0;
        for lag in 1..MAX_LAG.min(series.len()) {
            let c = series
                .iter()
                .zip(&series[lag..])
                .map(|(a, b)| (a - mean) * (b - mean))
                .sum::<f64>()
                / (n * var);
            if c <= 0.0 {
                break;
            }
            tau += 2.0 * c;
        }
        correlation[axis] = tau;
    }
    (rms, correlation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    const G: f64 = 9.81;

    /// A train accelerating, coasting and braking through curves, read by an IMU turned by
    /// `truth` with constant biases and white noise.
    fn bins(truth: Rotation3<f64>, seed: u64, moving: bool) -> Vec<Bin> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut gauss = |s: f64| -> f64 {
            let z: f64 = StandardNormal.sample(&mut rng);
            z * s
        };
        let (ba, bg) = (
            Vector3::new(0.02, -0.01, 0.015),
            Vector3::new(4e-4, -3e-4, 2e-4),
        );
        (0..1200)
            .map(|k| {
                let t = k as f64;
                let (a, lateral, yaw_rate) = if moving {
                    let phase = (t / 100.0) as usize % 4;
                    let a = [0.6, 0.0, -0.7, 0.1][phase];
                    let curve = ((t / 37.0).sin() > 0.3) as u8 as f64;
                    (a, 0.5 * curve, 0.02 * curve)
                } else {
                    (0.0, 0.0, 0.0)
                };
                let body_force = Vector3::new(a, lateral, G);
                let body_rate = Vector3::new(0.0, 0.0, yaw_rate);
                let f = truth.inverse() * body_force + ba;
                let w = truth.inverse() * body_rate + bg;
                Bin {
                    time_s: t,
                    run: 0,
                    specific_force: f + Vector3::new(gauss(0.01), gauss(0.01), gauss(0.01)),
                    angular_rate: w + Vector3::new(gauss(1e-4), gauss(1e-4), gauss(1e-4)),
                    body_force,
                    body_rate,
                    body_force_per_m: Vector3::zeros(),
                    body_rate_per_m: Vector3::zeros(),
                }
            })
            .collect()
    }

    fn truth() -> Rotation3<f64> {
        Rotation3::from_euler_angles(
            0.8f64.to_radians(),
            -1.9f64.to_radians(),
            2.4f64.to_radians(),
        )
    }

    #[test]
    fn a_run_with_acceleration_and_curves_gives_every_angle_within_its_sigma() {
        let e = fit_mounting(
            &bins(truth(), 1, true),
            Rotation3::identity(),
            &Default::default(),
        )
        .unwrap();
        let error = (truth().inverse() * e.mounting).scaled_axis();
        for i in 0..3 {
            assert!(
                error[i].abs() < 3.0 * e.sigma_rad[i],
                "{i}: {error} vs {:?}",
                e.sigma_rad
            );
            assert!(e.sigma_rad[i] < 0.1f64.to_radians(), "{:?}", e.sigma_deg());
            assert!(e.sigma_share[i] < UNOBSERVABLE_SHARE);
        }
        assert!(
            (e.accel_bias[2] - 0.015).abs() < 0.005,
            "{:?}",
            e.accel_bias
        );
    }

    #[test]
    fn standing_still_the_angles_hide_in_the_biases_and_say_so() {
        let e = fit_mounting(
            &bins(truth(), 2, false),
            Rotation3::identity(),
            &Default::default(),
        )
        .unwrap();
        // Gravity alone: roll and pitch only as well as the x and y biases are known before
        // (0.1 m/s² of bias is 0.58° of tilt), yaw not at all.
        let sigma = e.sigma_deg();
        assert!(sigma[0] > 0.4 && sigma[1] > 0.4, "{sigma:?}");
        assert!(e.sigma_share[2] > UNOBSERVABLE_SHARE, "{:?}", e.sigma_share);
    }
}
