//! `filter = "gnss_ins"`: how a `[[pipeline]]` table becomes source 003's GNSS/INS pipeline
//! (its `[pipeline.gnss_ins]` settings checked, its GNSS and IMU found by role; every other
//! sensor a speed sensor, a radar or an odometer, with its scale factor if it has one).

use std::sync::Arc;

use crate::base::PipelineBase;
use crate::checks::{at_least_zero, positive};
use crate::config::{FromMessage, PipelineConfig, Variance};
use crate::error::Result;
use crate::kinds::{
    sensor_of, settings_value, whole_message_sensor, KindSpec, MessagePipeline, Outputs, TypedKind,
};
use crate::measurement::{Quantity, SensorModel};

use super::error_state::MAX_SPEED_SENSORS;
use super::{GnssInsPipeline, GnssInsSettings, Roles, SpeedSensor};

/// The `gnss_ins` kind, for [`Registry`](crate::registry::Registry).
pub struct Kind;

#[derive(Debug)]
struct Spec {
    settings: GnssInsSettings,
    roles: Roles,
}

impl TypedKind for Kind {
    const NAME: &'static str = "gnss_ins";
    const SECTION: &'static str = "gnss_ins";
    type Settings = GnssInsSettings;

    fn spec(c: &PipelineConfig, settings: GnssInsSettings) -> Result<Arc<dyn KindSpec>, String> {
        settings.check()?;
        let (gnss, imu) = (
            sensor_of(c, "gnss_ins.gnss", &settings.gnss)?,
            sensor_of(c, "gnss_ins.imu", &settings.imu)?,
        );
        let mut speed = Vec::new();
        for (i, s) in c.sensor.iter().enumerate() {
            let s = s.get_ref();
            if i == gnss || i == imu {
                continue;
            }
            if let Some(f) = s.scale_factor {
                let named = |e: String| format!("sensor {}: {e}", s.topic);
                if f.quantity.is_some_and(|q| q != Quantity::Speed) {
                    return Err(named(
                        "a gnss_ins pipeline's speed sensor scales its speed only".into(),
                    ));
                }
                positive("scale_factor.std", f.std).map_err(named)?;
                at_least_zero("scale_factor.walk_per_s", f.walk_per_s).map_err(named)?;
            }
            if let Some(w) = s.speed_window_s {
                at_least_zero("speed_window_s", w)
                    .map_err(|e| format!("sensor {}: {e}", s.topic))?;
            }
            speed.push(SpeedSensor {
                sensor: i,
                scale: s.scale_factor,
                window_s: s.speed_window_s.unwrap_or(0.0),
            });
        }
        if speed.len() > MAX_SPEED_SENSORS {
            return Err(format!(
                "a gnss_ins pipeline has its GNSS, its IMU and at most {MAX_SPEED_SENSORS} \
                 speed sensors (radar, odometers), not {}",
                speed.len()
            ));
        }
        // The GNSS and the IMU take a topic, a variance and a gate only; a speed sensor may
        // have a scale factor and a speed window besides.
        for i in [gnss, imu] {
            whole_message_sensor(c.filter.get_ref(), c.sensor[i].get_ref())?;
        }
        let roles = Roles { gnss, imu, speed };
        let imu = c.sensor[roles.imu].get_ref();
        if imu.variance != Variance::FromMessage(FromMessage::Message) {
            return Err(format!(
                "sensor {}: a gnss_ins pipeline's IMU takes variance = \"message\"; its error \
                 model is [pipeline.gnss_ins.imu_noise]",
                imu.topic
            ));
        }
        Ok(Arc::new(Spec { settings, roles }))
    }
}

impl KindSpec for Spec {
    fn name(&self) -> &'static str {
        Kind::NAME
    }
    fn settings(&self) -> toml::Value {
        settings_value(&self.settings)
    }
    fn build(&self, base: PipelineBase) -> Result<Box<dyn MessagePipeline>> {
        let p = GnssInsPipeline::new(base, self.settings.clone(), self.roles.clone())?;
        Ok(Box::new(p))
    }
    fn accepts(&self, sensor: usize, model: SensorModel) -> Result<(), String> {
        let r = &self.roles;
        let (fits, role) = match sensor {
            s if s == r.gnss => (
                model == SensorModel::GnssFix,
                "its GNSS receiver (gnss_ins.gnss)",
            ),
            s if s == r.imu => (
                model == SensorModel::ImuAcceleration,
                "its IMU (gnss_ins.imu)",
            ),
            _ => (
                matches!(model, SensorModel::RadarSpeed | SensorModel::OdometerSpeed),
                "a speed sensor: besides its GNSS and IMU a gnss_ins pipeline reads speed \
                 sensors only (a radar, an odometer)",
            ),
        };
        match fits {
            true => Ok(()),
            false => Err(format!("it is {role}")),
        }
    }
    fn outputs(&self) -> Outputs {
        Outputs {
            imu_error_model: true,
            ..Outputs::default()
        }
    }
}
