//! `[pipeline.gnss_ins]`: the table of a `gnss_ins` pipeline, the file form and the validated
//! settings in one (every field has a default; [`GnssInsSettings::check`] validates).

use crate::checks::all_positive;
use serde::{Deserialize, Serialize};

use super::adaptive_noise::AdaptiveNoiseSettings;
use super::error_learning::LearningSettings;
use super::error_state::ImuNoise;
use super::quality_gate::GateSettings;
use crate::prefilter::PreFilterSettings;

/// The pre-filter of each channel pair (`[pipeline.gnss_ins.prefilter]`): the GNSS east and
/// north position, its east and north velocity, and the IMU's forward specific force and yaw
/// rate (the source's Filter2), each axis a filter of its own.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PreFilters {
    pub position: PreFilterSettings,
    pub velocity: PreFilterSettings,
    pub imu: PreFilterSettings,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GnssInsSettings {
    /// The GNSS receiver's topic and the IMU's (each one of the pipeline's sensors).
    pub gnss: String,
    pub imu: String,
    pub gate: GateSettings,
    pub prefilter: PreFilters,
    /// Fuse the receiver's speed and course as east/north velocity.
    pub velocity: bool,
    /// The receiver's speed σ, m/s (a fix carries no speed accuracy); the course's σ is
    /// this over the speed. 0.1 m/s is a single-frequency receiver's Doppler speed.
    pub speed_std_mps: f64,
    /// Carry speed and course into east/north velocity by the unscented transform (source
    /// 003's PU-RLS) rather than by linearising.
    pub unscented_velocity: bool,
    /// Below this speed the course says nothing: velocity is fused only above it, m/s.
    pub min_course_speed_mps: f64,
    /// The AKF: the receiver's R scaled by what the innovations show
    /// ([`super::adaptive_noise`]); absent, the receiver's R as it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adaptive: Option<AdaptiveNoiseSettings>,
    pub imu_noise: ImuNoise,
    pub learning: LearningSettings,
    /// The filter starts at the first gated fix with at least this speed and a course, m/s:
    /// the heading comes from the course, and below it the course is noise.
    pub init_speed_mps: f64,
    /// A fix slower than this means the train stands: zero speed and zero turn rate are
    /// fused, and the IMU's static bias is measured, m/s.
    pub standstill_speed_mps: f64,
    /// Specific force at or beyond this (m/s²) is a saturated accelerometer; angular rate at
    /// or beyond `max_rate_radps` a saturated gyro: the sample is refused. ±2 g and
    /// ±125 °/s are the ETH node's ranges, and a train is far inside both.
    pub max_specific_force_mps2: f64,
    pub max_rate_radps: f64,
    /// An IMU axis that repeats its value this many samples in a row while another axis
    /// changes is stuck: the samples are refused until it moves.
    pub stuck_samples: u32,
    /// A GNSS fix further than this from the plane's origin is absurd, m.
    pub max_distance_m: f64,
    /// States are written at least this often while the IMU runs (GNSS lost or silent), s.
    pub output_period_s: f64,
}

impl Default for GnssInsSettings {
    fn default() -> Self {
        Self {
            gnss: "/gnss/fix".into(),
            imu: "/imu".into(),
            gate: GateSettings::default(),
            prefilter: PreFilters::default(),
            velocity: true,
            speed_std_mps: 0.1,
            unscented_velocity: false,
            min_course_speed_mps: 1.0,
            adaptive: None,
            imu_noise: ImuNoise::default(),
            learning: LearningSettings::default(),
            init_speed_mps: 2.0,
            standstill_speed_mps: 0.2,
            max_specific_force_mps2: 2.0 * 9.80665,
            max_rate_radps: 125f64.to_radians(),
            stuck_samples: 50,
            max_distance_m: 1000e3,
            output_period_s: 0.1,
        }
    }
}

impl GnssInsSettings {
    pub fn check(&self) -> Result<(), String> {
        self.gate.check()?;
        self.imu_noise.check()?;
        for (what, p) in [
            ("prefilter.position", &self.prefilter.position),
            ("prefilter.velocity", &self.prefilter.velocity),
            ("prefilter.imu", &self.prefilter.imu),
        ] {
            p.check().map_err(|e| format!("gnss_ins.{what}: {e}"))?;
        }
        all_positive(
            "gnss_ins",
            &[
                ("speed_std_mps", self.speed_std_mps),
                ("init_speed_mps", self.init_speed_mps),
                ("max_specific_force_mps2", self.max_specific_force_mps2),
                ("max_rate_radps", self.max_rate_radps),
                ("max_distance_m", self.max_distance_m),
                ("output_period_s", self.output_period_s),
                ("learning.window_s", self.learning.window_s),
                ("learning.loss_after_s", self.learning.loss_after_s),
            ],
        )?;
        if !(self.standstill_speed_mps >= 0.0 && self.standstill_speed_mps < self.init_speed_mps) {
            return Err(format!(
                "gnss_ins.standstill_speed_mps = {} must be at least 0 and below init_speed_mps {}",
                self.standstill_speed_mps, self.init_speed_mps
            ));
        }
        if let Some(a) = &self.adaptive {
            if a.window < 2 || !(a.min_scale > 0.0 && a.min_scale <= 1.0 && a.max_scale >= 1.0) {
                return Err(
                    "gnss_ins.adaptive: window must be at least 2, min_scale in (0, 1], \
                     max_scale at least 1"
                        .into(),
                );
            }
        }
        if self.stuck_samples < 2 {
            return Err("gnss_ins.stuck_samples must be at least 2".into());
        }
        if self.gnss == self.imu {
            return Err(format!(
                "gnss_ins.gnss and gnss_ins.imu are both {}: two topics",
                self.gnss
            ));
        }
        Ok(())
    }
}
