use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::ProtobufForm;

/// A block of raw samples from the two eddy-current sensors, which sit `spacing_m` apart
/// along the track. `stamp_ns` is the time of the first sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EddyCurrentBlock {
    pub stamp_ns: u64,
    pub sample_rate_hz: f64,
    /// Distance D between the two sensors along the track, m.
    pub spacing_m: f64,
    /// The leading sensor's samples (volts).
    pub sensor_a: Vec<f32>,
    /// The trailing sensor's samples (volts), same length as `sensor_a`.
    pub sensor_b: Vec<f32>,
    /// The converter's step (V per count), where the samples are on its grid: each sample is
    /// `(count × volts_per_count) as f32`. In protobuf such samples travel as counts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volts_per_count: Option<f64>,
}

impl EddyCurrentBlock {
    /// The samples as counts of `step`, if every one of them is exactly `(count × step) as
    /// f32`: what makes counts a lossless encoding.
    fn counts(samples: &[f32], step: f64) -> Option<Vec<i32>> {
        samples
            .iter()
            .map(|&v| {
                let c = (v as f64 / step).round();
                let fits = c.abs() <= i32::MAX as f64 && (c * step) as f32 == v;
                fits.then_some(c as i32)
            })
            .collect()
    }
}

impl ProtobufForm for EddyCurrentBlock {
    type Message = crate::protobuf::types::EddyCurrentBlock;

    fn to_protobuf(&self) -> Self::Message {
        let step = self.volts_per_count.filter(|s| s.is_finite() && *s > 0.0);
        let counts = step.and_then(|s| {
            Some((
                Self::counts(&self.sensor_a, s)?,
                Self::counts(&self.sensor_b, s)?,
            ))
        });
        let mut m = Self::Message {
            stamp_ns: self.stamp_ns,
            sample_rate_hz: self.sample_rate_hz,
            spacing_m: self.spacing_m,
            volts_per_count: self.volts_per_count.unwrap_or(0.0),
            ..Default::default()
        };
        match counts {
            Some((a, b)) => (m.sensor_a_counts, m.sensor_b_counts) = (a, b),
            None => (m.sensor_a, m.sensor_b) = (self.sensor_a.clone(), self.sensor_b.clone()),
        }
        m
    }

    fn from_protobuf(m: Self::Message) -> Result<Self, String> {
        let has_counts = !(m.sensor_a_counts.is_empty() && m.sensor_b_counts.is_empty());
        let step = m.volts_per_count;
        let (sensor_a, sensor_b) = if has_counts {
            if !(step.is_finite() && step > 0.0) {
                return Err(format!(
                    "counts without a positive volts_per_count ({step})"
                ));
            }
            let volts = |c: &[i32]| c.iter().map(|&c| (c as f64 * step) as f32).collect();
            (volts(&m.sensor_a_counts), volts(&m.sensor_b_counts))
        } else {
            (m.sensor_a, m.sensor_b)
        };
        Ok(EddyCurrentBlock {
            stamp_ns: m.stamp_ns,
            sample_rate_hz: m.sample_rate_hz,
            spacing_m: m.spacing_m,
            sensor_a,
            sensor_b,
            volts_per_count: (step > 0.0).then_some(step),
        })
    }
}
