//! `filter = "ekf_safety"`: how a `[[pipeline]]` table becomes source 002's safety pipeline
//! (its `[pipeline.safety]` settings checked, its three sensors found by role).

use std::sync::Arc;

use crate::base::PipelineBase;
use crate::config::PipelineConfig;
use crate::error::Result;
use crate::kinds::{
    constant_acceleration, sensor_of, settings_value, whole_message_sensors, KindSpec,
    MessagePipeline, Outputs, TypedKind,
};
use crate::model::ConstantAcceleration;

use super::{Roles, SafetyPipeline, SafetySettings};

/// The `ekf_safety` kind, for [`Registry`](crate::registry::Registry).
pub struct Kind;

#[derive(Debug)]
struct Spec {
    settings: SafetySettings,
    roles: Roles,
    /// Per axis, when the acceleration input is off.
    motion: ConstantAcceleration,
}

impl TypedKind for Kind {
    const NAME: &'static str = "ekf_safety";
    const SECTION: &'static str = "safety";
    type Settings = SafetySettings;

    fn spec(c: &PipelineConfig, settings: SafetySettings) -> Result<Arc<dyn KindSpec>, String> {
        settings.check()?;
        let motion = constant_acceleration(
            &c.motion,
            "an ekf_safety pipeline runs constant acceleration per axis",
        )?;
        let axle = |role: &str, topic: &Option<String>| {
            topic.as_ref().map(|t| sensor_of(c, role, t)).transpose()
        };
        let roles = Roles {
            gnss: sensor_of(c, "safety.gnss", &settings.gnss)?,
            axle_1: axle("safety.axle_1", &settings.axle_1)?,
            axle_2: axle("safety.axle_2", &settings.axle_2)?,
        };
        whole_message_sensors(c)?;
        let roles_given =
            1 + usize::from(roles.axle_1.is_some()) + usize::from(roles.axle_2.is_some());
        if c.sensor.len() != roles_given {
            return Err(format!(
                "an ekf_safety pipeline has one sensor per role it names (safety.gnss, axle_1, \
                 axle_2: {roles_given} here), not {}",
                c.sensor.len()
            ));
        }
        Ok(Arc::new(Spec {
            settings,
            roles,
            motion,
        }))
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
        let p = SafetyPipeline::new(base, self.settings.clone(), self.roles, self.motion)?;
        Ok(Box::new(p))
    }
    fn outputs(&self) -> Outputs {
        Outputs {
            safety: true,
            ..Outputs::default()
        }
    }
}
