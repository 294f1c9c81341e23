use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::{whole_steps, ProtobufForm};

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
    /// `(count × volts_per_count) as f32`. In protobuf such samples travel as 16-bit counts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volts_per_count: Option<f64>,
}

/// The samples as 16-bit counts of `step`, if every one is exactly `(count × step) as f32`.
fn counts(samples: &[f32], step: f64) -> Option<Vec<i16>> {
    let counts = whole_steps(samples, step, i16::MAX as f64, |v| v as f32)?;
    Some(counts.into_iter().map(|c| c as i16).collect())
}

/// Counts byte-planed: every count's low byte, then every count's high byte.
fn planed(counts: &[i16]) -> Vec<u8> {
    let low = counts.iter().map(|c| c.to_le_bytes()[0]);
    let high = counts.iter().map(|c| c.to_le_bytes()[1]);
    low.chain(high).collect()
}

/// [`planed`] undone.
fn unplaned(bytes: &[u8]) -> Vec<i16> {
    let (low, high) = bytes.split_at(bytes.len() / 2);
    low.iter()
        .zip(high)
        .map(|(&l, &h)| i16::from_le_bytes([l, h]))
        .collect()
}

impl ProtobufForm for EddyCurrentBlock {
    type Message = crate::protobuf::types::EddyCurrentBlock;

    fn to_protobuf(&self) -> Self::Message {
        let step = self.volts_per_count.filter(|s| s.is_finite() && *s > 0.0);
        let same_length = self.sensor_a.len() == self.sensor_b.len();
        let counts = step.filter(|_| same_length).and_then(|s| {
            let mut both = counts(&self.sensor_a, s)?;
            both.extend(counts(&self.sensor_b, s)?);
            Some(planed(&both))
        });
        let mut m = Self::Message {
            stamp_ns: self.stamp_ns,
            sample_rate_hz: self.sample_rate_hz,
            spacing_m: self.spacing_m,
            volts_per_count: self.volts_per_count.unwrap_or(0.0),
            ..Default::default()
        };
        match counts {
            Some(c) => m.counts_i16 = c,
            None => (m.sensor_a, m.sensor_b) = (self.sensor_a.clone(), self.sensor_b.clone()),
        }
        m
    }

    fn from_protobuf(m: Self::Message) -> Result<Self, String> {
        let step = m.volts_per_count;
        let (sensor_a, sensor_b) = if m.counts_i16.is_empty() {
            (m.sensor_a, m.sensor_b)
        } else {
            if !(step.is_finite() && step > 0.0) {
                return Err(format!(
                    "counts without a positive volts_per_count ({step})"
                ));
            }
            if m.counts_i16.len() % 4 != 0 {
                let n = m.counts_i16.len();
                return Err(format!(
                    "counts_i16 has {n} bytes, not two sensors' 16-bit counts"
                ));
            }
            let volts: Vec<f32> = unplaned(&m.counts_i16)
                .into_iter()
                .map(|c| (c as f64 * step) as f32)
                .collect();
            let (a, b) = volts.split_at(volts.len() / 2);
            (a.to_vec(), b.to_vec())
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
