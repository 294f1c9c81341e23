//! Speed sensors in the GNSS/INS (railfuse's, not source 003's): every train has wheel
//! odometers and many a Doppler radar, and through a GNSS loss they hold the along-track error
//! the IMU alone lets grow. Each measures the forward speed, scaled by its own factor (a worn
//! wheel, a radar's beam angle):
//!
//! ```text
//! z_j = (1 + k_j) |u − a W_j / 2|      H: δu ↦ (1 + k_j) sgn,  δk_j ↦ |u − a W_j / 2|
//! ```
//!
//! `W_j` the window its speed is the mean over (`speed_window_s`), `a` the latest forward
//! acceleration, and `k_j` a state only for a sensor with a `scale_factor` (else 0). A wheel
//! slipping or sliding disagrees with the rest: the sensor's NIS gate (`gate_nis`) keeps it
//! out.

use std::path::Path;

use railfuse_catalog::log::LogMessage;
use railfuse_catalog::messages::GateDecision;

use super::error_state::{unit, K, V};
use super::{GnssInsPipeline, Out};
use crate::error::{Error, Result};
use crate::measurement::{Measurement, SensorContext, SensorModel};

impl GnssInsPipeline {
    /// A speed sensor's message as its speed measurement. The channel was bound as a radar
    /// or an odometer (the kind's `accepts` refused anything else), so only a message without
    /// a speed is an error here.
    pub(super) fn decode_speed(
        &mut self,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
    ) -> Result<Measurement> {
        if let Some(model) = SensorModel::for_schema(msg.channel.schema_name()) {
            model.decode(msg, input, context, &mut self.scratch)?;
            if let Some(m) = self.scratch.pop() {
                return Ok(m);
            }
        }
        Err(Error::Channel {
            input: input.to_owned(),
            pipeline: self.base.name.clone(),
            topic: msg.channel.topic.clone(),
            declared: "a gnss_ins speed sensor".into(),
            problem: "gives no speed".into(),
        })
    }

    /// The `j`-th speed sensor's measurement, fused (or gated, or refused with the reason).
    pub(super) fn speed(&mut self, j: usize, m: &Measurement, o: &mut Out) {
        let sensor = self.roles.speed[j];
        let topic = self.topic(sensor.sensor).to_owned();
        if self.nav.is_none() {
            self.counts.before_initialisation += 1;
            return;
        }
        let r = match crate::noise::speed_variance(m, self.speed_variance[j]) {
            Ok(r) => r,
            Err(why) => {
                self.counts.rejected_invalid += 1;
                o.diagnostics(m.stamp_ns, &topic, GateDecision::RejectedInvalid, why);
                return;
            }
        };
        self.advance_to(m.stamp_ns);
        let (Some(nav), Some(filter)) = (self.nav.as_mut(), self.filter.as_mut()) else {
            return;
        };
        let mean = nav.speed_mps - 0.5 * self.last_acceleration * sensor.window_s;
        let scale = 1.0 + self.calibration.speed_scales[j];
        let mut row = unit(V) * scale * mean.signum();
        if sensor.scale.is_some() {
            row[K + j] = mean.abs();
        }
        let row = row.transpose();
        let residual = m.value - scale * mean.abs();
        let innovation = filter.kf.innovation(&row, r, residual);
        let gated = self.base.gates[sensor.sensor].is_some_and(|g| innovation.nis > g);
        let decision = match gated {
            true => GateDecision::RejectedGate,
            false => {
                filter.kf.update(&row, r, residual);
                filter.inject(nav, &mut self.calibration);
                GateDecision::Accepted
            }
        };
        match gated {
            true => self.counts.rejected_gate += 1,
            false => self.counts.accepted += 1,
        }
        let z = (Some(m.value), Some(r));
        o.record(
            m.stamp_ns,
            &topic,
            Some("speed"),
            z,
            Some(innovation),
            decision,
            gated.then_some("NIS beyond the gate"),
        );
    }
}
