//! `[pipeline.eddy_current]`: the table of an `eddy_current` pipeline (every field has a
//! default; [`EddyCurrentSettings::check`] validates).

use crate::checks::{all_positive, at_least_zero};
use serde::{Deserialize, Serialize};

use super::speed::CorrelatorKind;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EddyCurrentSettings {
    /// The sensor pair's topic (one of the pipeline's sensors).
    pub topic: String,
    pub correlator: CorrelatorKind,
    /// Constant-acceleration warping before the correlation's peak is taken.
    pub warp: bool,
    /// Warped pipelines: a start from a standstill fitted as `x = ½ α (t − t₀)²` on the
    /// distance grid (the warp of a window the train stood through part of), until the
    /// correlator's window no longer reaches back to the start.
    pub start_fit: bool,
    /// A constant-acceleration Kalman filter over the measurements; without it the state is
    /// the latest measurement as it is.
    pub kalman: bool,
    /// The fixed low-pass's cutoff, Hz (the source's 1000 Hz).
    pub lowpass_hz: f64,
    /// The band-pass's lowest lower edge, Hz (it follows the speed down to this).
    pub band_floor_hz: f64,
    /// A correlation peak below this is no measurement.
    pub min_rho: f64,
    /// The warp search's bound on |acceleration|, m/s².
    pub max_acceleration_mps2: f64,
    /// Activity under this many times the noise floor is a standstill.
    pub standstill_factor: f64,
    /// Added to every correlation speed's variance, (m/s)²: what the lag's statistics do
    /// not see (the sensors' slightly different responses).
    pub speed_noise_floor_mps: f64,
    /// Warp and filter accelerations further apart than this many σ are flagged (divergence
    /// or a wrong warp), and the warp's is not fused.
    pub acceleration_check_sigma: f64,
    /// Sleeper sections without a map: the spacing, m.
    pub sleeper_spacing_m: f64,
    /// Distance by counting sleepers (else by integrating the speed).
    pub count_sleepers: bool,
    /// Where the run starts (the front end's chainage), m: until a switch of the map's atlas
    /// fixes it.
    pub initial_chainage_m: f64,
    /// A switch seen in the signal is looked for in the map this far either side of where
    /// the pipeline thinks it is, m (0: no landmarks).
    pub landmark_search_m: f64,
    /// A speed sensor's (an odometer's) error in proportion to the speed, `k`: its variance
    /// gains `(k v)²` (a worn wheel, a slip under the gate; 0.01 = 1 %), so that at line
    /// speed the correlator, not the wheel, sets the speed.
    pub speed_sensor_scale_std: f64,
}

impl Default for EddyCurrentSettings {
    fn default() -> Self {
        EddyCurrentSettings {
            topic: "/eddy_current/block".into(),
            correlator: CorrelatorKind::OpenLoop,
            warp: true,
            start_fit: true,
            kalman: true,
            lowpass_hz: 1000.0,
            band_floor_hz: 0.5,
            min_rho: 0.5,
            max_acceleration_mps2: 2.5,
            standstill_factor: 4.0,
            speed_noise_floor_mps: 0.005,
            acceleration_check_sigma: 4.0,
            sleeper_spacing_m: 0.625,
            count_sleepers: true,
            initial_chainage_m: 0.0,
            landmark_search_m: 50.0,
            speed_sensor_scale_std: 0.01,
        }
    }
}

impl EddyCurrentSettings {
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("lowpass_hz", self.lowpass_hz),
            ("band_floor_hz", self.band_floor_hz),
            ("max_acceleration_mps2", self.max_acceleration_mps2),
            ("standstill_factor", self.standstill_factor),
            ("speed_noise_floor_mps", self.speed_noise_floor_mps),
            ("acceleration_check_sigma", self.acceleration_check_sigma),
            ("sleeper_spacing_m", self.sleeper_spacing_m),
        ];
        all_positive("eddy_current", &positive)?;
        at_least_zero(
            "eddy_current.speed_sensor_scale_std",
            self.speed_sensor_scale_std,
        )?;
        if !(self.initial_chainage_m.is_finite()
            && self.landmark_search_m.is_finite()
            && self.landmark_search_m >= 0.0)
        {
            return Err(format!(
                "eddy_current.initial_chainage_m and landmark_search_m must be finite (and the \
                 search not negative), not {} and {}",
                self.initial_chainage_m, self.landmark_search_m
            ));
        }
        if !(0.0..1.0).contains(&self.min_rho) {
            return Err(format!(
                "eddy_current.min_rho is a correlation in [0, 1), not {}",
                self.min_rho
            ));
        }
        Ok(())
    }
}
