//! The error-state Kalman filter of the planar INS: it estimates what the navigation got
//! wrong, `δx = x_true − x_nav = [δe, δn, δv, δψ, δb_a, δb_g]`, from GNSS, and the correction
//! is put into the navigation after each update (the error state then starts again at zero).
//!
//! Linearised about the navigation (`ψ`, `v`):
//!
//! ```text
//! δė = sin ψ δv + v cos ψ δψ          δv̇ = −δb_a + w_a          δḃ_a = −δb_a / τ_a + w_ba
//! δṅ = cos ψ δv − v sin ψ δψ          δψ̇ =  δb_g + w_g          δḃ_g = −δb_g / τ_g + w_bg
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
pub const V: usize = 2;
pub const PSI: usize = 3;
pub const BA: usize = 4;
pub const BG: usize = 5;

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
}

impl ErrorDynamics<'_> {
    fn f(&self) -> SMatrix<f64, 6, 6> {
        let (s, c) = self.navigation.heading_rad.sin_cos();
        let v = self.navigation.speed_mps;
        let mut f = SMatrix::<f64, 6, 6>::zeros();
        f[(E, V)] = s;
        f[(E, PSI)] = v * c;
        f[(N, V)] = c;
        f[(N, PSI)] = -v * s;
        f[(V, BA)] = -1.0;
        f[(PSI, BG)] = 1.0;
        f[(BA, BA)] = -1.0 / self.noise.accel_bias_time_s;
        f[(BG, BG)] = -1.0 / self.noise.gyro_bias_time_s;
        f
    }
}

impl TransitionModel<6> for ErrorDynamics<'_> {
    fn transition(&self, dt: f64) -> SMatrix<f64, 6, 6> {
        let fdt = self.f() * dt;
        SMatrix::identity() + fdt + fdt * fdt * 0.5
    }

    fn process_noise(&self, dt: f64) -> SMatrix<f64, 6, 6> {
        let n = self.noise;
        let mut gqg = SMatrix::<f64, 6, 6>::zeros();
        gqg[(V, V)] = n.accel_noise_density.powi(2);
        gqg[(PSI, PSI)] = n.gyro_noise_density.powi(2);
        gqg[(BA, BA)] = 2.0 * n.accel_bias_std_mps2.powi(2) / n.accel_bias_time_s;
        gqg[(BG, BG)] = 2.0 * n.gyro_bias_std_radps.powi(2) / n.gyro_bias_time_s;
        let phi = self.transition(dt);
        (phi * gqg * phi.transpose() + gqg) * (0.5 * dt)
    }
}

/// The filter: the error state (zero between updates) and its covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorStateFilter {
    pub kf: KalmanFilter<6>,
}

/// The rows of `h(δx)` for GNSS east/north velocity at the navigation state.
pub fn velocity_rows(nav: &Navigation) -> [SVector<f64, 6>; 2] {
    let (s, c) = nav.heading_rad.sin_cos();
    let v = nav.speed_mps;
    let mut east = SVector::<f64, 6>::zeros();
    east[V] = s;
    east[PSI] = v * c;
    let mut north = SVector::<f64, 6>::zeros();
    north[V] = c;
    north[PSI] = -v * s;
    [east, north]
}

/// The rows for GNSS east/north position.
pub fn position_rows() -> [SVector<f64, 6>; 2] {
    let mut east = SVector::<f64, 6>::zeros();
    east[E] = 1.0;
    let mut north = SVector::<f64, 6>::zeros();
    north[N] = 1.0;
    [east, north]
}

/// One scalar or a correlated pair of measurements of the error state.
pub struct ErrorMeasurement {
    /// `z − h(x_nav)` per row.
    pub residual: SVector<f64, 2>,
    pub rows: [SVector<f64, 6>; 2],
    pub covariance: SMatrix<f64, 2, 2>,
}

impl ErrorStateFilter {
    pub fn new(covariance: SMatrix<f64, 6, 6>) -> Self {
        Self {
            kf: KalmanFilter::new(SVector::zeros(), covariance),
        }
    }

    pub fn predict(&mut self, nav: &Navigation, noise: &ImuNoise, dt: f64) {
        self.kf.predict(
            &ErrorDynamics {
                navigation: nav,
                noise,
            },
            dt,
        );
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
            SMatrix::<f64, 2, 6>::from_rows(&[m.rows[0].transpose(), m.rows[1].transpose()]);
        let hw = l_inv * h_rows;
        let a = self.kf.update(&hw.row(0).into_owned(), 1.0, z[0]);
        let b = self.kf.update(&hw.row(1).into_owned(), 1.0, z[1]);
        Some([a, b])
    }

    /// The projection `H P Hᵀ` of the covariance on the pair's rows.
    pub fn projected(&self, rows: &[SVector<f64, 6>; 2]) -> SMatrix<f64, 2, 2> {
        let h = SMatrix::<f64, 2, 6>::from_rows(&[rows[0].transpose(), rows[1].transpose()]);
        h * self.kf.estimate.covariance * h.transpose()
    }

    /// Puts the estimated error into the navigation and starts the error state again at zero.
    pub fn inject(&mut self, nav: &mut Navigation) {
        let dx = self.kf.estimate.state;
        nav.east_m += dx[E];
        nav.north_m += dx[N];
        nav.speed_mps += dx[V];
        nav.heading_rad = (nav.heading_rad + dx[PSI]).rem_euclid(std::f64::consts::TAU);
        nav.accel_bias_mps2 += dx[BA];
        nav.gyro_bias_radps += dx[BG];
        self.kf.estimate.state = SVector::zeros();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nav(heading: f64, speed: f64) -> Navigation {
        Navigation {
            east_m: 0.0,
            north_m: 0.0,
            speed_mps: speed,
            heading_rad: heading,
            accel_bias_mps2: 0.0,
            gyro_bias_radps: 0.0,
        }
    }

    #[test]
    fn the_linearisation_matches_the_navigation_it_linearises() {
        // Perturb the start by δx, dead-reckon both for 1 s, compare with Φ δx.
        let noise = ImuNoise::default();
        let base = nav(0.7, 15.0);
        let dx = SVector::<f64, 6>::from_column_slice(&[0.3, -0.2, 0.1, 0.002, 0.01, 1e-4]);
        let mut a = base;
        let mut b = Navigation {
            east_m: base.east_m + dx[E],
            north_m: base.north_m + dx[N],
            speed_mps: base.speed_mps + dx[V],
            heading_rad: base.heading_rad + dx[PSI],
            // The error state is truth − nav: the truth has the bias the nav lacks, and
            // `f − b` makes the truth's acceleration smaller.
            accel_bias_mps2: dx[BA],
            gyro_bias_radps: dx[BG],
        };
        let dt = 0.01;
        let mut phi = SMatrix::<f64, 6, 6>::identity();
        for _ in 0..100 {
            let model = ErrorDynamics {
                navigation: &a,
                noise: &noise,
            };
            phi = model.transition(dt) * phi;
            a.propagate(0.0, 0.0, dt);
            // The truth integrates the same raw readings with its own biases.
            b.propagate(0.0, 0.0, dt);
        }
        let predicted = phi * dx;
        let actual = [
            b.east_m - a.east_m,
            b.north_m - a.north_m,
            b.speed_mps - a.speed_mps,
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
    fn a_whitened_pair_equals_the_vector_update() {
        let p = SMatrix::<f64, 6, 6>::from_diagonal(&SVector::from_column_slice(&[
            4.0, 4.0, 1.0, 0.01, 1e-4, 1e-8,
        ]));
        let mut f = ErrorStateFilter::new(p);
        let n = nav(0.4, 10.0);
        let m = ErrorMeasurement {
            residual: SVector::<f64, 2>::new(0.5, -0.3),
            rows: velocity_rows(&n),
            covariance: SMatrix::<f64, 2, 2>::new(0.04, 0.01, 0.01, 0.09),
        };
        let h = SMatrix::<f64, 2, 6>::from_rows(&[m.rows[0].transpose(), m.rows[1].transpose()]);
        let s = h * p * h.transpose() + m.covariance;
        let k = p * h.transpose() * s.try_inverse().unwrap();
        let x = k * m.residual;
        let pk = (SMatrix::<f64, 6, 6>::identity() - k * h) * p;
        f.update_pair(&m).unwrap();
        assert!((f.kf.estimate.state - x).norm() < 1e-10);
        assert!((f.kf.estimate.covariance - pk).norm() < 1e-10);
    }
}
