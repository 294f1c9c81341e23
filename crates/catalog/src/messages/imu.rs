use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::types as pb;
use crate::protobuf::{fixed, whole_steps, ProtobufForm};

/// One inertial sample in the sensor's body frame (x forward, y left, z up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Imu {
    pub stamp_ns: u64,
    pub sensor_id: String,
    /// Specific force (acceleration minus gravity, as an accelerometer measures it), m/s².
    pub specific_force_mps2: [f64; 3],
    /// Angular rate, rad/s.
    pub angular_rate_radps: [f64; 3],
    /// The accelerometer's step (LSB), m/s², where its values are whole steps (each exactly
    /// `count × step`, as the sensor delivers them). In protobuf such values travel as counts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel_lsb_mps2: Option<f64>,
    /// The gyro's step (LSB), rad/s, likewise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_lsb_radps: Option<f64>,
}

/// Three values as counts of `lsb` where they are whole steps, else as themselves.
fn axes(values: &[f64; 3], lsb: Option<f64>) -> (Vec<i32>, Vec<f64>) {
    let step = lsb.filter(|s| s.is_finite() && *s > 0.0);
    match step.and_then(|s| whole_steps(values, s, i32::MAX as f64, |v| v)) {
        Some(counts) => (counts, Vec::new()),
        None => (Vec::new(), values.to_vec()),
    }
}

/// [`axes`] undone; `what` names the field in an error.
fn values(counts: Vec<i32>, values: Vec<f64>, lsb: f64, what: &str) -> Result<[f64; 3], String> {
    if counts.is_empty() {
        return fixed(values, what);
    }
    if !(lsb.is_finite() && lsb > 0.0) {
        return Err(format!("{what} as counts without a positive step ({lsb})"));
    }
    let counts: [i32; 3] = counts
        .try_into()
        .map_err(|c: Vec<i32>| format!("{what} has {} counts, not 3", c.len()))?;
    Ok(counts.map(|c| c as f64 * lsb))
}

impl ProtobufForm for Imu {
    type Message = pb::Imu;

    fn to_protobuf(&self) -> pb::Imu {
        let (force_counts, force) = axes(&self.specific_force_mps2, self.accel_lsb_mps2);
        let (rate_counts, rate) = axes(&self.angular_rate_radps, self.gyro_lsb_radps);
        pb::Imu {
            stamp_ns: self.stamp_ns,
            sensor_id: self.sensor_id.clone(),
            specific_force_mps2: force,
            angular_rate_radps: rate,
            accel_lsb_mps2: self.accel_lsb_mps2.unwrap_or(0.0),
            gyro_lsb_radps: self.gyro_lsb_radps.unwrap_or(0.0),
            specific_force_counts: force_counts,
            angular_rate_counts: rate_counts,
        }
    }

    fn from_protobuf(m: pb::Imu) -> Result<Self, String> {
        let (accel, gyro) = (m.accel_lsb_mps2, m.gyro_lsb_radps);
        Ok(Imu {
            stamp_ns: m.stamp_ns,
            sensor_id: m.sensor_id,
            specific_force_mps2: values(
                m.specific_force_counts,
                m.specific_force_mps2,
                accel,
                "specific_force",
            )?,
            angular_rate_radps: values(
                m.angular_rate_counts,
                m.angular_rate_radps,
                gyro,
                "angular_rate",
            )?,
            accel_lsb_mps2: (accel > 0.0).then_some(accel),
            gyro_lsb_radps: (gyro > 0.0).then_some(gyro),
        })
    }
}
