use crate::protobuf::types as pb;
use crate::protobuf::{protobuf_enum, protobuf_form, Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::TrackMap;

/// The fused along-track state of one pipeline after a measurement update.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FusedState {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
    pub acceleration_mps2: f64,
    /// Covariance of `[chainage, speed, acceleration]`, row-major 3×3, SI units squared.
    pub covariance: [f64; 9],
    /// Topic of the measurement that produced this state.
    pub source: String,
    /// Sensor calibration states the pipeline estimates beside the motion (a GNSS position
    /// bias, a speed sensor's scale factor); absent when it estimates none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensor_states: Vec<SensorStateEstimate>,
    /// 2-D pipelines: where in the plane, with its uncertainty there (absent for along-track
    /// pipelines, whose position is the chainage on the map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane: Option<PlanePosition>,
}

/// A 2-D pipeline's position in the map's local east/north plane.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PlanePosition {
    pub east_m: f64,
    pub north_m: f64,
    /// Covariance of `[east, north]`, row-major 2×2, m².
    pub covariance_en_m2: [f64; 4],
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    /// Pipelines that estimate it (GNSS/INS): east and north velocity, m/s, with their
    /// covariance (row-major 2×2, (m/s)²), and the heading, clockwise from north.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_en_mps: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_covariance_en: Option<[f64; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_rad: Option<f64>,
}

/// Where a fused state is on the globe, with the uncertainty there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusedGeodetic {
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub altitude_m: f64,
    /// East/north/up, row-major 3×3, m² (nothing known up: zeros).
    pub covariance_enu_m2: [f64; 9],
    /// As ROS and Foxglove name it: 3 known (a 2-D pipeline's own), 1 approximated (an
    /// along-track variance spread along the track's heading).
    pub covariance_type: u8,
    /// Clockwise from north: a 2-D pipeline's own, else the track's.
    pub heading_rad: Option<f64>,
}

impl FusedState {
    /// Its position in the map's local plane: east, north, heading (clockwise from north) and
    /// the east/north covariance (row-major 2×2). A 2-D pipeline's own, map or no map; an
    /// along-track one's chainage on the map, its variance along the track's heading (a 1-D
    /// pipeline knows nothing across the track).
    pub fn local(&self, map: Option<&TrackMap>) -> Option<(f64, f64, Option<f64>, [f64; 4])> {
        if let Some(p) = &self.plane {
            return Some((p.east_m, p.north_m, p.heading_rad, p.covariance_en_m2));
        }
        let (east, north, heading) = map?.locate(self.chainage_m)?;
        let var = self.covariance[0].max(0.0);
        let (s, c) = heading.sin_cos();
        let (ee, en, nn) = (var * s * s, var * s * c, var * c * c);
        Some((east, north, Some(heading), [ee, en, en, nn]))
    }

    /// Its position on the globe (altitude: the map origin's, else 0); `None` for an
    /// along-track state with no map, or anything not finite.
    pub fn geodetic(&self, map: Option<&TrackMap>) -> Option<FusedGeodetic> {
        let (east, north, heading, [ee, en, ne, nn]) = self.local(map)?;
        let (latitude_deg, longitude_deg, altitude_m, covariance_type) = match &self.plane {
            Some(p) => {
                let alt = map.map_or(0.0, |m| m.origin.altitude_m);
                (p.latitude_deg, p.longitude_deg, alt, 3)
            }
            None => {
                let (lat, lon, alt) = map?.origin.to_geodetic(east, north, 0.0);
                (lat, lon, alt, 1)
            }
        };
        let covariance_enu_m2 = [ee, en, 0.0, ne, nn, 0.0, 0.0, 0.0, 0.0];
        let finite = [latitude_deg, longitude_deg, altitude_m]
            .iter()
            .chain(&covariance_enu_m2)
            .all(|v| v.is_finite());
        finite.then_some(FusedGeodetic {
            latitude_deg,
            longitude_deg,
            altitude_m,
            covariance_enu_m2,
            covariance_type,
            heading_rad: heading,
        })
    }
}

impl PlanePosition {
    /// The 3σ covariance ellipse as a closed polygon of `n` points (east, north): the
    /// eigenvectors of the 2×2 covariance scaled by 3√λ.
    pub fn ellipse_3sigma(&self, n: usize) -> Vec<(f64, f64)> {
        let [a, b, _, d] = self.covariance_en_m2;
        // Symmetric 2×2: eigenvalues from the trace and determinant, the major axis's angle
        // from the off-diagonal.
        let (mean, diff) = ((a + d) / 2.0, ((a - d) / 2.0).hypot(b));
        let (major, minor) = ((mean + diff).max(0.0).sqrt(), (mean - diff).max(0.0).sqrt());
        let angle = 0.5 * (2.0 * b).atan2(a - d);
        let (s, c) = angle.sin_cos();
        (0..=n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                let (u, v) = (3.0 * major * t.cos(), 3.0 * minor * t.sin());
                (self.east_m + u * c - v * s, self.north_m + u * s + v * c)
            })
            .collect()
    }
}

/// One estimated sensor calibration state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SensorStateEstimate {
    /// The sensor's topic.
    pub topic: String,
    /// `chainage_bias` (m, measured minus true) or `scale_factor` (dimensionless: 0.003 reads
    /// 0.3 % high).
    pub kind: String,
    pub value: f64,
    /// Its standard deviation.
    pub std: f64,
}

protobuf_form!(FusedState {
    stamp_ns,
    chainage_m,
    speed_mps,
    acceleration_mps2,
    covariance,
    source,
    sensor_states,
    plane,
});
protobuf_form!(SensorStateEstimate {
    topic,
    kind,
    value,
    std
});
protobuf_form!(PlanePosition {
    east_m,
    north_m,
    covariance_en_m2,
    latitude_deg,
    longitude_deg,
    velocity_en_mps,
    velocity_covariance_en,
    heading_rad,
});

impl FusedState {
    pub fn chainage_std_m(&self) -> f64 {
        self.covariance[0].max(0.0).sqrt()
    }
    pub fn speed_std_mps(&self) -> f64 {
        self.covariance[4].max(0.0).sqrt()
    }
}

/// Two-sided 95 % interval of χ² with 1 and 2 degrees of freedom (2.5 % and 97.5 % points):
/// where a consistent filter's NIS of a scalar measurement, and NEES of chainage and speed, lie
/// 95 % of the time.
pub const CHI2_95_1DOF: (f64, f64) = (0.000982069, 5.023886);
pub const CHI2_95_2DOF: (f64, f64) = (0.05063562, 7.377759);

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum GateDecision {
    /// Used in the update.
    Accepted,
    /// Used after a run of gate rejections of its quantity showed the filter, not the sensors,
    /// to be wrong: the estimate's variance was widened first (gate-lockout recovery).
    AcceptedAfterLockout,
    /// NIS above the pipeline's gate: not used.
    RejectedGate,
    /// NaN, infinite or flagged invalid by the sensor: not used.
    RejectedInvalid,
    /// Older than the filter's time after the reorder window: not used.
    RejectedLate,
    /// Arrived before the filter had its first position: not used.
    BeforeInitialisation,
    /// Its device is out of a federated fusion (failed): not used.
    RejectedDeviceFault,
    /// An absolute fix (balise, loop, GNSS) the gate had rejected `reset_after` times in a
    /// row: the filter, not the fix, was wrong, and its position was reset to the fix (the
    /// innovation is the one before the reset).
    ResetToFix,
}

/// What one measurement did to one pipeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FusedDiagnostics {
    pub stamp_ns: u64,
    /// Topic of the measurement.
    pub source: String,
    /// The measured value; absent when it was not a finite number (JSON has no NaN).
    #[serde(default)]
    pub measurement: Option<f64>,
    /// The variance R used for it; absent when there was none usable.
    #[serde(default)]
    pub measurement_variance: Option<f64>,
    /// z − H x⁻ (absent when the measurement never reached the update).
    #[serde(default)]
    pub innovation: Option<f64>,
    /// H P⁻ Hᵀ + R.
    #[serde(default)]
    pub innovation_variance: Option<f64>,
    /// Normalised innovation squared, ν² / S.
    #[serde(default)]
    pub nis: Option<f64>,
    pub decision: GateDecision,
    /// Federated filters: the device (sub-filter) the measurement belongs to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// Filters in the plane: the axis (`east`, `north`) this scalar update was on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<String>,
    /// Why the measurement was not used, where the decision alone does not say.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Particle filters: effective sample size after the update.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effective_sample_size: Option<f64>,
    /// Particle filters: whether the update resampled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resampled: Option<bool>,
    /// Federated filters: information-sharing coefficient β and health of every device.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharing: Option<Vec<DeviceShare>>,
    /// Eddy-current pipelines: what the correlation, the warp and the sleeper count saw.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eddy_current: Option<EddyCurrentDiagnostics>,
}

/// One correlation window of an eddy-current pipeline.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EddyCurrentDiagnostics {
    /// The correlation peak (Pearson's ρ) used, and without warping where warping ran.
    pub rho: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unwarped_rho: Option<f64>,
    /// The warp factor k ∈ (−1, 1) and the acceleration it implies, m/s².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warp_k: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warp_acceleration_mps2: Option<f64>,
    /// The Kalman filter's acceleration before the update, to compare with the warp's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter_acceleration_mps2: Option<f64>,
    /// The delay between the sensors, s, and the pyramid level it was measured at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level: Option<u32>,
    /// Sleepers counted so far on each sensor.
    pub sleepers_a: u64,
    pub sleepers_b: u64,
    /// What the window was: `moving`, `moving_off` (a start from standstill fitted whole; its
    /// acceleration is the start's), `standstill` or `no_lock`.
    pub window: String,
}

/// The share and health of one device of a federated filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DeviceShare {
    pub device: String,
    /// Information-sharing coefficient β (0 while failed).
    pub beta: f64,
    /// Why the device is out of the fusion (timeout, stuck, gate_failures, reported), if it is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fault: Option<String>,
}

protobuf_form!(FusedDiagnostics {
    stamp_ns,
    source,
    measurement,
    measurement_variance,
    innovation,
    innovation_variance,
    nis,
    decision,
    device,
    axis,
    reason,
    effective_sample_size,
    resampled,
    sharing,
    eddy_current,
});
protobuf_form!(DeviceShare {
    device,
    beta,
    fault
});
protobuf_form!(EddyCurrentDiagnostics {
    rho,
    unwarped_rho,
    warp_k,
    warp_acceleration_mps2,
    filter_acceleration_mps2,
    delay_s,
    level,
    sleepers_a,
    sleepers_b,
    window,
});
protobuf_enum!(GateDecision {
    Accepted,
    AcceptedAfterLockout,
    RejectedGate,
    RejectedInvalid,
    RejectedLate,
    BeforeInitialisation,
    RejectedDeviceFault,
    ResetToFix,
});

/// The devices' shares travel in a message of their own, so that "no devices" and "not
/// federated" differ.
impl Wire for Option<Vec<DeviceShare>> {
    type W = Option<pb::DeviceShares>;
    fn to_wire(&self) -> Self::W {
        self.as_ref().map(|d| pb::DeviceShares {
            devices: d.to_wire(),
        })
    }
    fn from_wire(w: Self::W, field: &str) -> Result<Self, String> {
        w.map(|s| Wire::from_wire(s.devices, field)).transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_3_sigma_ellipse_follows_the_covariance_s_axes() {
        // σ_e = 2 m, σ_n = 1 m, no correlation: the ellipse reaches 6 m east and 3 m north.
        let p = PlanePosition {
            east_m: 10.0,
            north_m: 20.0,
            covariance_en_m2: [4.0, 0.0, 0.0, 1.0],
            latitude_deg: 0.0,
            longitude_deg: 0.0,
            ..Default::default()
        };
        let pts = p.ellipse_3sigma(4);
        assert!(
            (pts[0].0 - 16.0).abs() < 1e-9 && (pts[0].1 - 20.0).abs() < 1e-9,
            "{pts:?}"
        );
        assert!(
            (pts[1].0 - 10.0).abs() < 1e-9 && (pts[1].1 - 23.0).abs() < 1e-9,
            "{pts:?}"
        );
        // Fully correlated east and north: the major axis (σ √2) on the diagonal.
        let q = PlanePosition {
            covariance_en_m2: [1.0, 1.0, 1.0, 1.0],
            ..p
        };
        let (e, n) = q.ellipse_3sigma(4)[0];
        assert!(((e - 10.0) - (n - 20.0)).abs() < 1e-9, "{e} {n}");
        assert!(
            ((e - 10.0).hypot(n - 20.0) - 3.0 * 2f64.sqrt()).abs() < 1e-9,
            "{e} {n}"
        );
    }
}
