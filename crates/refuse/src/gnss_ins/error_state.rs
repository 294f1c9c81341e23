//! The error-state Kalman filter of the planar INS: it estimates what the navigation got
//! wrong, `δx = x_true − x_nav = [δe, δn, δu, δw, δψ, δb_x, δb_y, δb_g, δg_e, δg_n, δk_1 … δk_3]`
//! (forward and lateral body speed, heading, the forward and lateral accelerometer biases,
//! the yaw gyro's, the GNSS receiver's slowly wandering position bias east and north, and the
//! scale factors of up to three speed sensors), from GNSS, the train's constraints and its
//! speed sensors; the correction is put into the navigation (and the [`Calibration`]) after
//! each update (the error state then starts again at zero).
//!
//! Linearised about the navigation (`ψ`, `u`, `w`, `ω` the bias-corrected rate about up):
//!
//! ```text
//! δė = sin ψ δu − cos ψ δw + (u cos ψ + w sin ψ) δψ      δu̇ = −δb_x + ω δw − w δb_g + w_a
//! δṅ = cos ψ δu + sin ψ δw + (w cos ψ − u sin ψ) δψ      δẇ = −δb_y − ω δu + u δb_g + w_a
//! δψ̇ = δb_g + w_g        δḃ = −δb / τ + w_b        δġ = −δg / τ_g + w_g'        δk̇_j = w_k
//! ```
//!
//! `w_a`, `w_g` are the sensors' white noise (velocity and angle random walk, PSD the noise
//! density squared), the biases first-order Gauss–Markov processes of stationary σ (the
//! bias instability) and correlation time τ (PSD `2σ²/τ`). Over a step
//! `Φ = I + F dt + F² dt² / 2` and `Q = ½ (Φ G Qc Gᵀ Φᵀ + G Qc Gᵀ) dt` (trapezoid), which at
//! IMU rates is exact to far below the noise.

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

use super::planar_ins::Navigation;
use crate::filter::KalmanFilter;
use crate::model::TransitionModel;

pub const E: usize = 0;
pub const N: usize = 1;
/// Forward speed (along the body's x axis).
pub const V: usize = 2;
/// Lateral speed (body y, to the left): zero for a train on its rails.
pub const W: usize = 3;
pub const PSI: usize = 4;
/// Forward accelerometer bias.
pub const BA: usize = 5;
/// Lateral accelerometer bias.
pub const BY: usize = 6;
pub const BG: usize = 7;
/// The GNSS receiver's position bias, east and north.
pub const GE: usize = 8;
pub const GN: usize = 9;
/// The first speed sensor's scale factor; sensor `j` has `K + j`.
pub const K: usize = 10;
/// Speed sensors with a scale-factor state, at most.
pub const MAX_SPEED_SENSORS: usize = 3;
/// The error state's dimension.
pub const DIM: usize = K + MAX_SPEED_SENSORS;

/// A vector or a row over the error state.
pub type ErrorVector = SVector<f64, DIM>;
pub type ErrorMatrix = SMatrix<f64, DIM, DIM>;

/// What the filter estimates about its sensors beside the navigation, the nominal values
/// the error state corrects.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Calibration {
    /// Each speed sensor's scale factor `k` (it reads `(1 + k)` times the speed).
    pub speed_scales: [f64; MAX_SPEED_SENSORS],
    /// The receiver's position bias east and north, m.
    pub receiver_bias_m: [f64; 2],
}

impl Calibration {
    /// The receiver's bias decays towards zero over `dt` (a first-order Gauss–Markov
    /// process's mean).
    pub fn decay(&mut self, dt: f64, time_constant_s: f64) {
        let phi = (-dt / time_constant_s).exp();
        for b in &mut self.receiver_bias_m {
            *b *= phi;
        }
    }
}

/// The IMU's error model (`[pipeline.gnss_ins.imu]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ImuNoise {
    /// Accelerometer white noise density, m/s²/√Hz (velocity random walk).
    pub accel_noise_density: f64,
    /// Gyro white noise density, rad/s/√Hz (angle random walk).
    pub gyro_noise_density: f64,
    /// Bias instability (stationary σ) and correlation time of the forward accelerometer's
    /// and the yaw gyro's bias.
    pub accel_bias_std_mps2: f64,
    pub accel_bias_time_s: f64,
    pub gyro_bias_std_radps: f64,
    pub gyro_bias_time_s: f64,
}

impl Default for ImuNoise {
    /// The source's MEMS IMU (its table 1): bias stability 0.2 mg and 0.007 °/s, velocity
    /// random walk 0.2 m/s/√h and angle random walk 2.4 °/√h (densities of 1/60 of those per
    /// √s); an hour for the biases to wander through their range.
    fn default() -> Self {
        Self {
            accel_noise_density: 0.2 / 60.0,
            gyro_noise_density: (2.4f64 / 60.0).to_radians(),
            accel_bias_std_mps2: 0.2e-3 * 9.80665,
            accel_bias_time_s: 3600.0,
            gyro_bias_std_radps: 0.007f64.to_radians(),
            gyro_bias_time_s: 3600.0,
        }
    }
}

impl ImuNoise {
    pub fn check(&self) -> Result<(), String> {
        for (what, x) in [
            ("accel_noise_density", self.accel_noise_density),
            ("gyro_noise_density", self.gyro_noise_density),
            ("accel_bias_std_mps2", self.accel_bias_std_mps2),
            ("accel_bias_time_s", self.accel_bias_time_s),
            ("gyro_bias_std_radps", self.gyro_bias_std_radps),
            ("gyro_bias_time_s", self.gyro_bias_time_s),
        ] {
            if !(x > 0.0 && x.is_finite()) {
                return Err(format!("imu.{what} = {x}: must be positive"));
            }
        }
        Ok(())
    }
}

/// The error dynamics at one navigation state: a [`TransitionModel`] for one IMU step.
pub struct ErrorDynamics<'a> {
    pub navigation: &'a Navigation,
    pub noise: &'a ImuNoise,
    /// The bias-corrected rate about the up axis, rad/s (counter-clockwise).
    pub rate_radps: f64,
    /// Each speed sensor's scale-factor random-walk PSD, 1/s (0: constant).
    pub scale_walk: &'a [f64; MAX_SPEED_SENSORS],
    /// The receiver bias's correlation time, s, and its driving PSD per axis, m²/s (0: no
    /// bias states).
    pub receiver_bias: (f64, f64),
}

impl ErrorDynamics<'_> {
    fn f(&self) -> ErrorMatrix {
        let nav = self.navigation;
        let (s, c) = nav.heading_rad.sin_cos();
        let (u, w, omega) = (nav.speed_mps, nav.lateral_mps, self.rate_radps);
        let mut f = ErrorMatrix::zeros();
        f[(E, V)] = s;
        f[(E, W)] = -c;
        f[(E, PSI)] = u * c + w * s;
        f[(N, V)] = c;
        f[(N, W)] = s;
        f[(N, PSI)] = w * c - u * s;
        f[(V, W)] = omega;
        f[(V, BA)] = -1.0;
        f[(V, BG)] = -w;
        f[(W, V)] = -omega;
        f[(W, BY)] = -1.0;
        f[(W, BG)] = u;
        f[(PSI, BG)] = 1.0;
        f[(BA, BA)] = -1.0 / self.noise.accel_bias_time_s;
        f[(BY, BY)] = -1.0 / self.noise.accel_bias_time_s;
        f[(BG, BG)] = -1.0 / self.noise.gyro_bias_time_s;
        f[(GE, GE)] = -1.0 / self.receiver_bias.0;
        f[(GN, GN)] = -1.0 / self.receiver_bias.0;
        f
    }
}

impl TransitionModel<DIM> for ErrorDynamics<'_> {
    fn transition(&self, dt: f64) -> ErrorMatrix {
        let fdt = self.f() * dt;
        ErrorMatrix::identity() + fdt + fdt * fdt * 0.5
    }

    fn process_noise(&self, dt: f64) -> ErrorMatrix {
        self.process_noise_with(&self.transition(dt), dt)
    }
}

impl ErrorDynamics<'_> {
    /// `Q` over a step whose `Φ` is `phi`. `G Qc Gᵀ` is diagonal, so `Φ G Qc Gᵀ` is `Φ` with
    /// its columns scaled: one matrix product, not two (the filter runs at the IMU's rate).
    pub fn process_noise_with(&self, phi: &ErrorMatrix, dt: f64) -> ErrorMatrix {
        let n = self.noise;
        let mut gqg = ErrorVector::zeros();
        gqg[V] = n.accel_noise_density.powi(2);
        gqg[W] = n.accel_noise_density.powi(2);
        gqg[PSI] = n.gyro_noise_density.powi(2);
        gqg[BA] = 2.0 * n.accel_bias_std_mps2.powi(2) / n.accel_bias_time_s;
        gqg[BY] = gqg[BA];
        gqg[BG] = 2.0 * n.gyro_bias_std_radps.powi(2) / n.gyro_bias_time_s;
        gqg[GE] = self.receiver_bias.1;
        gqg[GN] = self.receiver_bias.1;
        for (j, q) in self.scale_walk.iter().enumerate() {
            gqg[K + j] = *q;
        }
        let mut scaled = *phi;
        for (j, mut column) in scaled.column_iter_mut().enumerate() {
            column *= gqg[j];
        }
        (scaled * phi.transpose() + ErrorMatrix::from_diagonal(&gqg)) * (0.5 * dt)
    }
}

/// The filter: the error state (zero between updates) and its covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorStateFilter {
    pub kf: KalmanFilter<DIM>,
}

/// The rows of `h(δx)` for east/north velocity at the navigation state.
pub fn velocity_rows(nav: &Navigation) -> [ErrorVector; 2] {
    let (s, c) = nav.heading_rad.sin_cos();
    let (u, w) = (nav.speed_mps, nav.lateral_mps);
    let mut east = ErrorVector::zeros();
    east[V] = s;
    east[W] = -c;
    east[PSI] = u * c + w * s;
    let mut north = ErrorVector::zeros();
    north[V] = c;
    north[W] = s;
    north[PSI] = w * c - u * s;
    [east, north]
}

/// The rows for a GNSS fix's east/north position: the place and the receiver's bias.
pub fn position_rows() -> [ErrorVector; 2] {
    [unit(E) + unit(GE), unit(N) + unit(GN)]
}

/// The row that picks state `i`.
pub fn unit(i: usize) -> ErrorVector {
    let mut r = ErrorVector::zeros();
    r[i] = 1.0;
    r
}

/// One scalar or a correlated pair of measurements of the error state.
pub struct ErrorMeasurement {
    /// `z − h(x_nav)` per row.
    pub residual: SVector<f64, 2>,
    pub rows: [ErrorVector; 2],
    pub covariance: SMatrix<f64, 2, 2>,
}

impl ErrorStateFilter {
    pub fn new(covariance: ErrorMatrix) -> Self {
        Self {
            kf: KalmanFilter::new(SVector::zeros(), covariance),
        }
    }

    pub fn predict(&mut self, dynamics: &ErrorDynamics<'_>, dt: f64) {
        let phi = dynamics.transition(dt);
        let q = dynamics.process_noise_with(&phi, dt);
        self.kf.predict_matrices(phi, q);
    }

    /// The innovations of a pair of measurements with correlated noise, whitened: with
    /// `R = L Lᵀ`, `L⁻¹ z = L⁻¹ H δx + L⁻¹ v` has independent unit noise, so two scalar
    /// Joseph updates are exactly the vector update. Returns the whitened innovations (their
    /// squares sum to the pair's NIS) or None when `R` is not positive definite.
    pub fn update_pair(&mut self, m: &ErrorMeasurement) -> Option<[crate::filter::Innovation; 2]> {
        let l = m.covariance.cholesky()?.l();
        let l_inv = l.try_inverse()?;
        let z = l_inv * m.residual;
        let h_rows =
            SMatrix::<f64, 2, DIM>::from_rows(&[m.rows[0].transpose(), m.rows[1].transpose()]);
        let hw = l_inv * h_rows;
        let a = self.kf.update(&hw.row(0).into_owned(), 1.0, z[0]);
        let b = self.kf.update(&hw.row(1).into_owned(), 1.0, z[1]);
        Some([a, b])
    }

    /// The projection `H P Hᵀ` of the covariance on the pair's rows.
    pub fn projected(&self, rows: &[ErrorVector; 2]) -> SMatrix<f64, 2, 2> {
        let h = SMatrix::<f64, 2, DIM>::from_rows(&[rows[0].transpose(), rows[1].transpose()]);
        h * self.kf.estimate.covariance * h.transpose()
    }

    /// Puts the estimated error into the navigation and the calibration and starts the error
    /// state again at zero.
    pub fn inject(&mut self, nav: &mut Navigation, calibration: &mut Calibration) {
        let dx = self.kf.estimate.state;
        nav.east_m += dx[E];
        nav.north_m += dx[N];
        nav.speed_mps += dx[V];
        nav.lateral_mps += dx[W];
        nav.heading_rad = (nav.heading_rad + dx[PSI]).rem_euclid(std::f64::consts::TAU);
        nav.accel_bias_mps2 += dx[BA];
        nav.lateral_bias_mps2 += dx[BY];
        nav.gyro_bias_radps += dx[BG];
        calibration.receiver_bias_m[0] += dx[GE];
        calibration.receiver_bias_m[1] += dx[GN];
        for (j, k) in calibration.speed_scales.iter_mut().enumerate() {
            *k += dx[K + j];
        }
        self.kf.estimate.state = ErrorVector::zeros();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nav(heading: f64, speed: f64) -> Navigation {
        Navigation {
            speed_mps: speed,
            heading_rad: heading,
            ..Navigation::default()
        }
    }

    #[test]
    fn the_linearisation_matches_the_navigation_it_linearises() {
        // Perturb the start by δx, dead-reckon both for 1 s through a turn, compare with Φ δx.
        let noise = ImuNoise::default();
        let mut base = nav(0.7, 15.0);
        base.lateral_mps = 0.05;
        let dx: [f64; 8] = [0.3, -0.2, 0.1, -0.04, 0.002, 0.01, -0.008, 1e-4];
        let mut a = base;
        let mut b = Navigation {
            east_m: base.east_m + dx[E],
            north_m: base.north_m + dx[N],
            speed_mps: base.speed_mps + dx[V],
            lateral_mps: base.lateral_mps + dx[W],
            heading_rad: base.heading_rad + dx[PSI],
            // The error state is truth − nav: the truth has the biases the nav lacks, and
            // `f − b` makes the truth's acceleration smaller.
            accel_bias_mps2: dx[BA],
            lateral_bias_mps2: dx[BY],
            gyro_bias_radps: dx[BG],
        };
        let (dt, yaw_rate, lateral_force) = (0.01, 0.01, 0.15);
        let mut phi = ErrorMatrix::identity();
        for _ in 0..100 {
            let model = ErrorDynamics {
                navigation: &a,
                noise: &noise,
                rate_radps: yaw_rate - a.gyro_bias_radps,
                scale_walk: &[0.0; MAX_SPEED_SENSORS],
                receiver_bias: (60.0, 0.0),
            };
            phi = model.transition(dt) * phi;
            a.propagate([0.2, lateral_force], yaw_rate, dt);
            // The truth integrates the same raw readings with its own biases.
            b.propagate([0.2, lateral_force], yaw_rate, dt);
        }
        let mut x = ErrorVector::zeros();
        x.fixed_rows_mut::<8>(0).copy_from_slice(&dx);
        let predicted = phi * x;
        let actual = [
            b.east_m - a.east_m,
            b.north_m - a.north_m,
            b.speed_mps - a.speed_mps,
            b.lateral_mps - a.lateral_mps,
            b.heading_rad - a.heading_rad,
        ];
        for (i, x) in actual.iter().enumerate() {
            // Second-order terms of δψ·δv are below a millimetre here; the bias decay (τ =
            // 1 h) a part in 3600.
            assert!(
                (predicted[i] - x).abs() < 2e-3,
                "state {i}: {} vs {x}",
                predicted[i]
            );
        }
    }

    #[test]
    fn the_process_noise_is_the_trapezoid_of_the_dense_form() {
        let noise = ImuNoise::default();
        let mut n = nav(0.9, 22.0);
        n.lateral_mps = 0.03;
        let model = ErrorDynamics {
            navigation: &n,
            noise: &noise,
            rate_radps: 0.02,
            scale_walk: &[1e-8, 0.0, 2e-8],
            receiver_bias: (60.0, 0.05),
        };
        let dt = 0.005;
        let phi = model.transition(dt);
        let mut diagonal = ErrorVector::zeros();
        let q = model.process_noise_with(&ErrorMatrix::identity(), 1.0) * 2.0;
        for i in 0..DIM {
            diagonal[i] = q[(i, i)] / 2.0;
        }
        let gqg = ErrorMatrix::from_diagonal(&diagonal);
        let dense = (phi * gqg * phi.transpose() + gqg) * (0.5 * dt);
        let fast = model.process_noise(dt);
        assert!((dense - fast).norm() <= 1e-15 * dense.norm().max(1.0));
        // Symmetric to rounding (the filter symmetrises P after every step).
        assert!((fast - fast.transpose()).norm() <= 1e-15 * fast.norm());
    }

    #[test]
    fn a_whitened_pair_equals_the_vector_update() {
        let mut diag = ErrorVector::from_element(1e-4);
        diag.fixed_rows_mut::<5>(0)
            .copy_from_slice(&[4.0, 4.0, 1.0, 0.04, 0.01]);
        let p = ErrorMatrix::from_diagonal(&diag);
        let mut f = ErrorStateFilter::new(p);
        let n = nav(0.4, 10.0);
        let m = ErrorMeasurement {
            residual: SVector::<f64, 2>::new(0.5, -0.3),
            rows: velocity_rows(&n),
            covariance: SMatrix::<f64, 2, 2>::new(0.04, 0.01, 0.01, 0.09),
        };
        let h = SMatrix::<f64, 2, DIM>::from_rows(&[m.rows[0].transpose(), m.rows[1].transpose()]);
        let s = h * p * h.transpose() + m.covariance;
        let k = p * h.transpose() * s.try_inverse().unwrap();
        let x = k * m.residual;
        let pk = (ErrorMatrix::identity() - k * h) * p;
        f.update_pair(&m).unwrap();
        assert!((f.kf.estimate.state - x).norm() < 1e-10);
        assert!((f.kf.estimate.covariance - pk).norm() < 1e-10);
    }
}
