//! `filter = "gnss_ins"`: how a `[[pipeline]]` table becomes source 003's GNSS/INS pipeline
//! (its `[pipeline.gnss_ins]` settings checked, its two sensors found by role).

use std::sync::Arc;

use crate::base::PipelineBase;
use crate::config::{FromMessage, PipelineConfig, Variance};
use crate::error::Result;
use crate::kinds::{
    sensor_of, settings_value, whole_message_sensors, KindSpec, MessagePipeline, Outputs, TypedKind,
};

use super::{GnssInsPipeline, GnssInsSettings, Roles};

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
        let roles = Roles {
            gnss: sensor_of(c, "gnss_ins.gnss", &settings.gnss)?,
            imu: sensor_of(c, "gnss_ins.imu", &settings.imu)?,
        };
        whole_message_sensors(c)?;
        if c.sensor.len() != 2 {
            return Err(format!(
                "a gnss_ins pipeline has two sensors (gnss_ins.gnss and gnss_ins.imu), not {}",
                c.sensor.len()
            ));
        }
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
        let p = GnssInsPipeline::new(base, self.settings.clone(), self.roles)?;
        Ok(Box::new(p))
    }
    fn outputs(&self) -> Outputs {
        Outputs {
            imu_error_model: true,
            ..Outputs::default()
        }
    }
}
