//! A sensor's measurement noise as a configuration gives it: a variance in SI units squared,
//! "message" (each message's own reported variance), or a table of those per quantity. Below
//! the configuration and every pipeline, which all read it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::measurement::Quantity;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(
    untagged,
    expecting = "a variance (a number, SI units squared), \"message\", or a table of those per field"
)]
pub enum Variance {
    Fixed(f64),
    FromMessage(FromMessage),
    PerField(BTreeMap<Quantity, VarianceValue>),
}

/// One field's variance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(
    untagged,
    expecting = "a variance (a number, SI units squared) or \"message\""
)]
pub enum VarianceValue {
    Fixed(f64),
    FromMessage(FromMessage),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FromMessage {
    Message,
}

impl Variance {
    /// The variance setting of one field, if the sensor gives one for it.
    pub fn of(&self, q: Quantity) -> Option<VarianceValue> {
        match self {
            Variance::Fixed(v) => Some(VarianceValue::Fixed(*v)),
            Variance::FromMessage(m) => Some(VarianceValue::FromMessage(*m)),
            Variance::PerField(map) => map.get(&q).copied(),
        }
    }
}

/// A speed sensor's sample's variance: the configured one (`Fixed`), else the one it
/// reported; or why the sample cannot be used (one wording for every pipeline that reads
/// speed sensors whole).
pub fn speed_variance(
    m: &crate::measurement::Measurement,
    configured: Option<VarianceValue>,
) -> Result<f64, &'static str> {
    let variance = match configured {
        Some(VarianceValue::Fixed(v)) => Some(v),
        _ => m.reported_variance,
    };
    match variance {
        _ if !m.valid => Err("flagged invalid by the sensor"),
        _ if !(m.value.is_finite() && m.value >= 0.0) => Err("not a finite speed ≥ 0"),
        None => Err("a speed without its variance (give the sensor one)"),
        Some(r) if !(r > 0.0 && r.is_finite()) => Err("a variance that is not positive"),
        Some(r) => Ok(r),
    }
}
