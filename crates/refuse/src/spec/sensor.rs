//! One `[[pipeline.sensor]]` table validated against its pipeline: fields, variances, gates,
//! sensor states, and the federated devices the sensors name.

use toml::Spanned;

use crate::checks::{at_least_zero, positive};
use crate::config::{FilterKind, SensorConfig, Variance, VarianceValue};
use crate::error::Result;
use crate::filter::MASTER;
use crate::measurement::Quantity;
use crate::model::SensorState;

use super::{Place, SensorSpec, MASTER_DEVICE};

/// The federated devices (sub-filters) in order of first mention, without the master.
pub(super) fn devices(sensors: &[Spanned<SensorConfig>]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for s in sensors {
        let d = s.get_ref().device_name();
        if d != MASTER_DEVICE && !names.iter().any(|n| n == d) {
            names.push(d.to_owned());
        }
    }
    names
}

/// One sensor table, validated against its pipeline's filter and motion model.
pub(super) fn sensor(
    s: &SensorConfig,
    filter: Option<FilterKind>,
    motion: usize,
    devices: &[String],
    declared: Place,
) -> Result<SensorSpec, String> {
    let values: Vec<VarianceValue> = match &s.variance {
        Variance::PerField(m) => m.values().copied().collect(),
        v => v.of(Quantity::Chainage).into_iter().collect(),
    };
    for v in values {
        if let VarianceValue::Fixed(v) = v {
            positive("variance", v)?;
        }
    }
    let gate_nis = s.gate_nis.map(|g| positive("gate_nis", g)).transpose()?;
    let measures = |q: Quantity| s.fields.as_ref().is_none_or(|f| f.contains(&q));
    if let Some(fields) = &s.fields {
        if fields.is_empty() {
            return Err("fields is empty".into());
        }
        if motion < 3 && fields.contains(&Quantity::Acceleration) {
            return Err("the constant-velocity model has no acceleration to measure".into());
        }
        if let Variance::PerField(m) = &s.variance {
            if let Some(q) = fields.iter().find(|q| !m.contains_key(q)) {
                return Err(format!("no variance for field {}", q.name()));
            }
        }
    }
    if s.device.is_some() && !filter.is_some_and(FilterKind::is_federated) {
        return Err("device is for federated filters only".into());
    }
    let states = sensor_states(s, motion, &measures)?;
    let speed_window_s = match s.speed_window_s {
        None => None,
        Some(_) if motion < 3 => {
            return Err("speed_window_s needs the acceleration of a 3-state motion model".into())
        }
        Some(_) if !measures(Quantity::Speed) => {
            return Err("speed_window_s, but speed is not among its fields".into())
        }
        Some(w) => Some(positive("speed_window_s", w)?),
    };
    let time_offset_ns = time_offset_ns(s.time_offset_s)?;
    let (device, device_name) = match filter.is_some_and(FilterKind::is_federated) {
        false => (0, None),
        true => match s.device_name() {
            MASTER_DEVICE => (MASTER, Some(MASTER_DEVICE.to_owned())),
            d => (
                devices.iter().position(|n| n == d).unwrap_or_default(),
                Some(d.to_owned()),
            ),
        },
    };
    let adaptive_window = adaptive_window(s)?;
    Ok(SensorSpec {
        topic: s.topic.clone(),
        role: s.role,
        device,
        device_name,
        fields: s.fields.clone(),
        variance: s.variance.clone(),
        gate_nis,
        reset_after: s.reset_after,
        adaptive_window,
        states,
        speed_window_s,
        time_offset_ns,
        required: s.required,
        declared,
    })
}

/// The innovations its variance is matched over (config `adaptive_variance.window`), checked.
fn adaptive_window(s: &SensorConfig) -> Result<Option<usize>, String> {
    match s.adaptive_variance {
        Some(a) if a.window < 2 => Err(format!(
            "adaptive_variance.window = {}: at least 2 innovations",
            a.window
        )),
        a => Ok(a.map(|a| a.window as usize)),
    }
}

/// A sensor's latency (config `time_offset_s`) in ns, checked.
fn time_offset_ns(time_offset_s: Option<f64>) -> Result<i64, String> {
    match time_offset_s {
        None => Ok(0),
        Some(t) if t.is_finite() && t.abs() <= MAX_TIME_OFFSET_S => Ok((t * 1e9).round() as i64),
        Some(t) => Err(format!(
            "time_offset_s = {t}: at most {MAX_TIME_OFFSET_S} s either way (a sensor's \
             latency, not a clock offset: give those with --clock-offset)"
        )),
    }
}

/// The largest sensor latency a configuration may give, s.
const MAX_TIME_OFFSET_S: f64 = 10.0;

/// The calibration states a sensor table asks for, each checked against what it measures.
fn sensor_states(
    s: &SensorConfig,
    motion: usize,
    measures: &dyn Fn(Quantity) -> bool,
) -> Result<Vec<SensorState>, String> {
    let mut states = Vec::new();
    if let Some(b) = s.chainage_bias {
        if !measures(Quantity::Chainage) {
            return Err("chainage_bias, but chainage is not among its fields".into());
        }
        states.push(SensorState::ChainageBias {
            std_m: positive("chainage_bias.std_m", b.std_m)?,
            time_constant_s: positive("chainage_bias.time_constant_s", b.time_constant_s)?,
        });
    }
    if let Some(b) = s.acceleration_bias {
        if motion < 3 || !measures(Quantity::Acceleration) {
            return Err("acceleration_bias, but no acceleration is measured".into());
        }
        states.push(SensorState::AccelerationBias {
            std_mps2: positive("acceleration_bias.std_mps2", b.std_mps2)?,
            time_constant_s: positive("acceleration_bias.time_constant_s", b.time_constant_s)?,
        });
    }
    if let Some(k) = s.scale_factor {
        let quantity = k.quantity.unwrap_or(Quantity::Speed);
        if quantity == Quantity::Acceleration {
            return Err("scale_factor.quantity must be speed or chainage".into());
        }
        if !measures(quantity) {
            return Err(format!(
                "scale_factor of {}, but {} is not among its fields",
                quantity.name(),
                quantity.name()
            ));
        }
        states.push(SensorState::ScaleFactor {
            quantity,
            std: positive("scale_factor.std", k.std)?,
            walk_per_s: at_least_zero("scale_factor.walk_per_s", k.walk_per_s)?,
        });
    }
    Ok(states)
}
