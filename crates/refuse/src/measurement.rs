//! Sensor models: how a message of each channel kind becomes a scalar measurement of the
//! along-track state `[s, v, a]`.
//!
//! | schema | measures | H |
//! |---|---|---|
//! | `railfuse.LoopPosition` | chainage | `[1, 0, 0]` |
//! | `railfuse.BalisePassage` | chainage (surveyed, at the passage) | `[1, 0, 0]` |
//! | `railfuse.RadarSpeed` | speed (invalid samples rejected) | `[0, 1, 0]` |
//! | `railfuse.Odometer` | speed over its window | `[0, 1, 0]` |

use std::path::Path;

use nalgebra::RowVector3;
use railfuse_catalog::log::LogMessage;
use railfuse_catalog::messages::{BalisePassage, ChannelMessage, LoopPosition, Odometer, RadarSpeed};

use crate::error::Result;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Chainage,
    Speed,
}

impl Quantity {
    /// The observation row on `[s, v, a]`.
    pub fn h(self) -> RowVector3<f64> {
        match self {
            Quantity::Chainage => RowVector3::new(1.0, 0.0, 0.0),
            Quantity::Speed => RowVector3::new(0.0, 1.0, 0.0),
        }
    }
}

/// One scalar measurement taken from a message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub stamp_ns: u64,
    pub quantity: Quantity,
    pub value: f64,
    /// The variance the sensor reported with it, if any.
    pub reported_variance: Option<f64>,
    /// False when the sensor itself flags the sample as unusable.
    pub valid: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorModel {
    LoopPosition,
    BalisePosition,
    RadarSpeed,
    OdometerSpeed,
}

impl SensorModel {
    pub const SUPPORTED: &'static [&'static str] =
        &[LoopPosition::SCHEMA_NAME, BalisePassage::SCHEMA_NAME, RadarSpeed::SCHEMA_NAME, Odometer::SCHEMA_NAME];

    pub fn for_schema(schema: &str) -> Option<Self> {
        Some(match schema {
            s if s == LoopPosition::SCHEMA_NAME => SensorModel::LoopPosition,
            s if s == BalisePassage::SCHEMA_NAME => SensorModel::BalisePosition,
            s if s == RadarSpeed::SCHEMA_NAME => SensorModel::RadarSpeed,
            s if s == Odometer::SCHEMA_NAME => SensorModel::OdometerSpeed,
            _ => return None,
        })
    }

    pub fn decode(self, msg: &LogMessage<'_>, path: &Path) -> Result<Measurement> {
        Ok(match self {
            SensorModel::LoopPosition => {
                let m: LoopPosition = msg.decode(path)?;
                Measurement { stamp_ns: m.stamp_ns, quantity: Quantity::Chainage, value: m.chainage_m, reported_variance: m.variance_m2, valid: true }
            }
            SensorModel::BalisePosition => {
                let m: BalisePassage = msg.decode(path)?;
                Measurement { stamp_ns: m.stamp_ns, quantity: Quantity::Chainage, value: m.chainage_m, reported_variance: m.variance_m2, valid: true }
            }
            SensorModel::RadarSpeed => {
                let m: RadarSpeed = msg.decode(path)?;
                Measurement { stamp_ns: m.stamp_ns, quantity: Quantity::Speed, value: m.speed_mps, reported_variance: m.speed_variance_m2ps2, valid: m.valid }
            }
            SensorModel::OdometerSpeed => {
                let m: Odometer = msg.decode(path)?;
                Measurement { stamp_ns: m.stamp_ns, quantity: Quantity::Speed, value: m.speed_mps, reported_variance: None, valid: true }
            }
        })
    }
}
