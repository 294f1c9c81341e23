//! What the pipeline writes: the fused state (chainage, speed, the plane position with its
//! covariance, the IMU biases as sensor states) at the output rate, the learnt IMU error model
//! once a second, and a diagnostics record per measurement.

use nalgebra::SMatrix;
use railfuse_catalog::messages::{FusedState, GateDecision, PlanePosition, SensorStateEstimate};

use super::error_state::{velocity_rows, ErrorVector, BA, BG, BY, DIM, E, K, N, V};
use super::planar_ins::Navigation;
use super::train_geometry::FrontEnd;
use super::{GnssInsPipeline, Out};
use crate::filter::Innovation;
use crate::fused::{measurement_record, Fused};
use crate::measurement::SensorContext;

impl GnssInsPipeline {
    pub(super) fn output(&mut self, t: u64, topic: &str, ctx: &SensorContext, o: &mut Out) {
        let (Some(nav), Some(filter)) = (self.nav, self.filter.as_ref()) else {
            return;
        };
        let p = filter.kf.estimate.covariance;
        let (s, c) = nav.heading_rad.sin_cos();
        let mut along = ErrorVector::zeros();
        along[E] = s;
        along[N] = c;
        let chainage_var = (along.transpose() * p * along)[0];
        let chainage_speed = (along.transpose() * p.column(V))[0];
        let front = self.front_end(ctx, &nav, ctx.track.as_ref());
        let chainage_m = front.chainage_m;
        // The acceleration is the last reading's: its white noise over one IMU interval.
        let white = self.settings.imu_noise.accel_noise_density.powi(2) / self.imu_interval_s;
        let accel_var = p[(BA, BA)] + white;
        let covariance = [
            chainage_var,
            chainage_speed,
            0.0,
            chainage_speed,
            p[(V, V)],
            0.0,
            0.0,
            0.0,
            accel_var,
        ];
        let sensor_states = self.sensor_states(&nav, &p);
        let state = FusedState {
            stamp_ns: t,
            chainage_m,
            speed_mps: nav.speed_mps,
            acceleration_mps2: self.last_acceleration,
            covariance,
            source: topic.to_owned(),
            sensor_states,
            plane: Some(self.plane_position(&nav, &front, &p)),
        };
        o.items.push(Fused {
            state: Some(state),
            ..Default::default()
        });
        let period = (self.settings.output_period_s * 1e9) as u64;
        self.next_output_ns = t + period;
        self.write_model(t, (nav.accel_bias_mps2, nav.gyro_bias_radps), o);
    }

    /// The front end's position in the plane with its covariance, on the globe, and its
    /// velocity and heading.
    fn plane_position(
        &self,
        nav: &Navigation,
        front: &FrontEnd,
        p: &SMatrix<f64, DIM, DIM>,
    ) -> PlanePosition {
        let rows = velocity_rows(nav);
        let h = SMatrix::<f64, 2, DIM>::from_rows(&[rows[0].transpose(), rows[1].transpose()]);
        let ((ve, vn), vc) = front.velocity(nav.velocity(), h * p * h.transpose());
        let pc = front.rows * p * front.rows.transpose();
        let origin = self.origin.expect("set by the first fix");
        let (lat, lon, _) = origin.to_geodetic(front.east_m, front.north_m, 0.0);
        PlanePosition {
            east_m: front.east_m,
            north_m: front.north_m,
            covariance_en_m2: [pc[(0, 0)], pc[(0, 1)], pc[(1, 0)], pc[(1, 1)]],
            latitude_deg: lat,
            longitude_deg: lon,
            velocity_en_mps: Some([ve, vn]),
            velocity_covariance_en: Some([vc[(0, 0)], vc[(0, 1)], vc[(1, 0)], vc[(1, 1)]]),
            heading_rad: Some(nav.heading_rad + front.turn_rad),
        }
    }

    /// The IMU's biases and each speed sensor's scale factor, with their σ.
    fn sensor_states(
        &self,
        nav: &Navigation,
        p: &SMatrix<f64, DIM, DIM>,
    ) -> Vec<SensorStateEstimate> {
        let imu_topic = self.topic(self.roles.imu);
        let state = |topic: &str, kind: &str, value: f64, i: usize| SensorStateEstimate {
            topic: topic.to_owned(),
            kind: kind.into(),
            value,
            std: p[(i, i)].max(0.0).sqrt(),
        };
        let mut states = vec![
            state(imu_topic, "accel_bias", nav.accel_bias_mps2, BA),
            state(imu_topic, "lateral_accel_bias", nav.lateral_bias_mps2, BY),
            state(imu_topic, "gyro_bias", nav.gyro_bias_radps, BG),
        ];
        for (j, sensor) in self.roles.speed.iter().enumerate() {
            if sensor.scale.is_some() {
                let topic = self.topic(sensor.sensor);
                let k = self.calibration.speed_scales[j];
                states.push(state(topic, "scale_factor", k, K + j));
            }
        }
        states
    }

    /// The learnt IMU model, once a second; none with learning off (`applied` would claim a
    /// correction that is not made, and the viewer would say it learns).
    pub(super) fn write_model(&mut self, t: u64, biases: (f64, f64), o: &mut Out) {
        let learning = &self.settings.learning;
        if t < self.next_model_ns || !learning.enabled {
            return;
        }
        let standstill = self
            .standstill
            .estimate()
            .map_or((0, 0.0), |s| (s.samples, s.seconds));
        // Applied: GNSS lost and the model learnt long enough to correct with.
        let applied = self.in_loss && self.learning.correction(0.0, learning).is_some();
        let model = self.learning.message(t, biases, standstill, applied);
        o.items.push(Fused {
            imu_error_model: Some(model),
            ..Default::default()
        });
        self.next_model_ns = t + 1_000_000_000;
    }

    /// Before the filter starts: the static offsets of a standing train, once measured.
    pub(super) fn static_model(&mut self, t: u64, o: &mut Out) {
        if let Some(s) = self.standstill.estimate() {
            self.write_model(t, (s.forward_mps2, s.yaw_rate_radps), o);
        }
    }
}

impl Out {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record(
        &mut self,
        stamp_ns: u64,
        topic: &str,
        axis: Option<&str>,
        (z, r): (Option<f64>, Option<f64>),
        i: Option<Innovation>,
        decision: GateDecision,
        reason: Option<&str>,
    ) {
        let d = measurement_record(stamp_ns, topic, axis, (z, r), i, decision, reason);
        self.items.push(Fused {
            diagnostics: Some(d),
            ..Default::default()
        });
    }

    pub(super) fn diagnostics(
        &mut self,
        stamp_ns: u64,
        topic: &str,
        decision: GateDecision,
        why: &str,
    ) {
        self.record(
            stamp_ns,
            topic,
            None,
            (None, None),
            None,
            decision,
            Some(why),
        );
    }
}
