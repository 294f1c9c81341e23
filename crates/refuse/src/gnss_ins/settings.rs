//! `[pipeline.gnss_ins]`: the table of a `gnss_ins` pipeline, the file form and the validated
//! settings in one (every field has a default; [`GnssInsSettings::check`] validates).

use crate::checks::{all_at_least_zero, all_positive, positive};
use railfuse_catalog::messages::FixType;
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

/// `[pipeline.gnss_ins.nhc]`: the non-holonomic constraint. A train's body neither slides
/// sideways nor lifts off its rails: its lateral speed is zero, fused as a pseudo-measurement.
/// Off, the navigation is a free planar INS whose lateral accelerometer bias moves it
/// sideways (source 003's car INS).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct NonHolonomic {
    pub enabled: bool,
    /// σ of the zero lateral speed, m/s: a bogie's hunting and the body's sway on its
    /// springs, a few centimetres a second.
    pub lateral_std_mps: f64,
    /// Fused at most this often, s.
    pub period_s: f64,
}

impl Default for NonHolonomic {
    fn default() -> Self {
        Self {
            enabled: true,
            lateral_std_mps: 0.05,
            period_s: 0.1,
        }
    }
}

/// `[pipeline.gnss_ins.track]`: the track constraint. A train cannot leave its track: the
/// navigation's offset from the track map's centre line (the map in the log, the one every
/// pipeline uses) is a measurement of zero, and the track's heading there one of the train's
/// (either way along the track). Through a curve the heading also tells where along the track
/// the train is (`∂ψ_track/∂s = κ`). Without a map in the log it does nothing, and says so.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrackConstraint {
    pub enabled: bool,
    /// σ of the cross-track offset, m: the map's survey error and the antenna's and IMU's
    /// place on the body.
    pub cross_track_std_m: f64,
    /// σ of the heading against the track's, rad (0: position only): the map's heading error
    /// between its vertices and the body's yaw on its bogies.
    pub heading_std_rad: f64,
    /// Fused at most this often, s. A map's error wanders over hundreds of metres: fused
    /// ten times a second as if independent, it made the along-track covariance too small
    /// (seed003, seeds 1–5: NEES inside its 95 % interval 76 % at 0.1 s, 84 % at 1 s).
    pub period_s: f64,
    /// A fix further from the track than this many σ (its own and the map's) is multipath:
    /// its position is refused, its speed and course fused (0: off). A station building's
    /// reflection puts an RTK fix claiming 2 cm metres beside the rails.
    pub max_fix_offset_sigma: f64,
}

impl Default for TrackConstraint {
    fn default() -> Self {
        Self {
            enabled: true,
            cross_track_std_m: 0.3,
            heading_std_rad: 0.01,
            period_s: 1.0,
            max_fix_offset_sigma: 4.0,
        }
    }
}

/// `[pipeline.gnss_ins.receiver_bias]`: a receiver's error is not white. Part of what its
/// covariance reports is a bias that wanders over a minute (multipath, the atmosphere, an
/// RTK solution converging after a loss); fused as white noise, a hundred fixes look like a
/// hundred independent ones and the covariance shrinks far below the error. Here that part
/// is a first-order Gauss–Markov state east and north, of stationary σ `share × reported σ`
/// for each fix type (the rest white), correlation time `time_constant_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ReceiverBias {
    pub enabled: bool,
    pub time_constant_s: f64,
    /// The share of a fix's reported σ that is bias, per fix type, 0–1 (0.99 at most).
    pub single: f64,
    pub dgps: f64,
    pub rtk_float: f64,
    pub rtk_fixed: f64,
}

impl Default for ReceiverBias {
    /// A single-frequency receiver: half of a single-point or DGPS σ is bias, a third of an
    /// RTK float's, a tenth of an RTK fixed's.
    fn default() -> Self {
        Self {
            enabled: true,
            time_constant_s: 60.0,
            single: 0.5,
            dgps: 0.5,
            rtk_float: 0.3,
            rtk_fixed: 0.1,
        }
    }
}

impl ReceiverBias {
    /// The bias's share of a fix of type `fix`'s σ (0 when off).
    pub fn share(&self, fix: FixType) -> f64 {
        match (self.enabled, fix) {
            (false, _) | (true, FixType::None) => 0.0,
            (true, FixType::Single) => self.single,
            (true, FixType::Dgps) => self.dgps,
            (true, FixType::RtkFloat) => self.rtk_float,
            (true, FixType::RtkFixed) => self.rtk_fixed,
        }
    }

    fn check(&self) -> Result<(), String> {
        positive(
            "gnss_ins.receiver_bias.time_constant_s",
            self.time_constant_s,
        )?;
        for (what, x) in [
            ("single", self.single),
            ("dgps", self.dgps),
            ("rtk_float", self.rtk_float),
            ("rtk_fixed", self.rtk_fixed),
        ] {
            if !(0.0..=0.99).contains(&x) {
                return Err(format!(
                    "gnss_ins.receiver_bias.{what} = {x}: a share of the fix's σ, 0 to 0.99"
                ));
            }
        }
        Ok(())
    }
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
    /// The train's constraints (railfuse's, not source 003's): zero lateral speed, and the
    /// track map.
    pub nhc: NonHolonomic,
    pub track: TrackConstraint,
    pub receiver_bias: ReceiverBias,
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
            nhc: NonHolonomic::default(),
            track: TrackConstraint::default(),
            receiver_bias: ReceiverBias::default(),
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
        self.receiver_bias.check()?;
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
                ("nhc.lateral_std_mps", self.nhc.lateral_std_mps),
                ("nhc.period_s", self.nhc.period_s),
                ("track.cross_track_std_m", self.track.cross_track_std_m),
                ("track.period_s", self.track.period_s),
            ],
        )?;
        all_at_least_zero(
            "gnss_ins",
            &[
                ("track.heading_std_rad", self.track.heading_std_rad),
                (
                    "track.max_fix_offset_sigma",
                    self.track.max_fix_offset_sigma,
                ),
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
