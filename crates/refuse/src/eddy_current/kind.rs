//! `filter = "eddy_current"`: how a `[[pipeline]]` table becomes source 004's eddy-current
//! pipeline (its `[pipeline.eddy_current]` settings checked, one sensor the block channel,
//! any other a speed sensor aiding its Kalman filter: an odometer, a radar).

use std::sync::Arc;

use crate::base::PipelineBase;
use crate::checks::at_least_zero;
use crate::config::PipelineConfig;
use crate::error::Result;
use crate::kinds::{
    constant_acceleration, sensor_of, settings_value, whole_message_sensor, KindSpec,
    MessagePipeline, TypedKind,
};
use crate::measurement::SensorModel;
use crate::model::ConstantAcceleration;

use super::aiding::SpeedAid;
use super::{EddyCurrentPipeline, EddyCurrentSettings};

/// The `eddy_current` kind, for [`Registry`](crate::registry::Registry).
pub struct Kind;

#[derive(Debug)]
struct Spec {
    settings: EddyCurrentSettings,
    motion: ConstantAcceleration,
    block: usize,
    aids: Vec<SpeedAid>,
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
        let block = sensor_of(c, "eddy_current.topic", &settings.topic)?;
        whole_message_sensor(c.filter.get_ref(), c.sensor[block].get_ref())?;
        let mut aids = Vec::new();
        for (i, s) in c.sensor.iter().enumerate().filter(|(i, _)| *i != block) {
            let s = s.get_ref();
            let named = |e: String| format!("sensor {}: {e}", s.topic);
            let window_s =
                at_least_zero("speed_window_s", s.speed_window_s.unwrap_or(0.0)).map_err(named)?;
            let mut bare = s.clone();
            bare.speed_window_s = None;
            whole_message_sensor(c.filter.get_ref(), &bare)
                .map_err(|_| named("a speed sensor of an eddy_current pipeline takes a topic, a variance, a gate and a speed window only".into()))?;
            aids.push(SpeedAid {
                sensor: i,
                window_s,
            });
        }
        if !aids.is_empty() && !settings.kalman {
            return Err(
                "speed sensors beside the block channel aid the Kalman filter: they need \
                 eddy_current.kalman = true"
                    .into(),
            );
        }
        Ok(Arc::new(Spec {
            settings,
            motion,
            block,
            aids,
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
        let p = EddyCurrentPipeline::new(
            base,
            self.settings.clone(),
            self.motion,
            self.block,
            self.aids.clone(),
        )?;
        Ok(Box::new(p))
    }
    fn reads_raw_blocks(&self) -> bool {
        true
    }
    fn accepts(&self, sensor: usize, model: SensorModel) -> Result<(), String> {
        let (fits, role) = match sensor == self.block {
            true => (
                model == SensorModel::EddyCurrent,
                "its block channel (eddy_current.topic), which carries railfuse.EddyCurrentBlock",
            ),
            false => (
                matches!(model, SensorModel::OdometerSpeed | SensorModel::RadarSpeed),
                "a speed sensor: besides its block channel an eddy_current pipeline reads \
                 speed sensors only (an odometer, a radar)",
            ),
        };
        match fits {
            true => Ok(()),
            false => Err(format!("it is {role}")),
        }
    }
}
