//! `filter = "eddy_current"`: how a `[[pipeline]]` table becomes source 004's eddy-current
//! pipeline (its `[pipeline.eddy_current]` settings checked, its one sensor the block
//! channel).

use std::sync::Arc;

use crate::base::PipelineBase;
use crate::config::PipelineConfig;
use crate::error::Result;
use crate::kinds::{
    constant_acceleration, sensor_of, settings_value, whole_message_sensors, KindSpec,
    MessagePipeline, TypedKind,
};
use crate::model::ConstantAcceleration;

use super::{EddyCurrentPipeline, EddyCurrentSettings};

/// The `eddy_current` kind, for [`Registry`](crate::registry::Registry).
pub struct Kind;

#[derive(Debug)]
struct Spec {
    settings: EddyCurrentSettings,
    motion: ConstantAcceleration,
}

impl TypedKind for Kind {
    const NAME: &'static str = "eddy_current";
    const SECTION: &'static str = "eddy_current";
    type Settings = EddyCurrentSettings;

    fn spec(
        c: &PipelineConfig,
        settings: EddyCurrentSettings,
    ) -> Result<Arc<dyn KindSpec>, String> {
        settings.check()?;
        let motion = constant_acceleration(
            &c.motion,
            "an eddy_current pipeline's filter is constant acceleration",
        )?;
        sensor_of(c, "eddy_current.topic", &settings.topic)?;
        whole_message_sensors(c)?;
        if c.sensor.len() != 1 {
            return Err(format!(
                "an eddy_current pipeline has one sensor (eddy_current.topic), not {}",
                c.sensor.len()
            ));
        }
        Ok(Arc::new(Spec { settings, motion }))
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
        let p = EddyCurrentPipeline::new(base, self.settings.clone(), self.motion)?;
        Ok(Box::new(p))
    }
    fn reads_raw_blocks(&self) -> bool {
        true
    }
}
