//! MEMS IMU: specific force and angular rate in the body frame (x forward, y left, z up) with
//! turn-on bias, bias random walk, white noise and LSB quantisation.

use railfuse_catalog::messages::Imu;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{gauss, quantise};
use crate::simulator::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

pub const GRAVITY_MPS2: f64 = 9.80665;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImuParams {
    pub sensor_id: String,
    pub rate_hz: f64,
    pub latency_s: f64,
    pub accel_noise_mps2: f64,
    pub accel_bias_mps2: f64,
    /// Accelerometer bias random walk, m/s² per √s.
    pub accel_bias_walk: f64,
    pub accel_lsb_mps2: f64,
    pub gyro_noise_radps: f64,
    pub gyro_bias_radps: f64,
    pub gyro_bias_walk: f64,
    pub gyro_lsb_radps: f64,
}

pub struct ImuSensor {
    p: ImuParams,
    schedule: Schedule,
    rng: ChaCha8Rng,
    accel_bias: [f64; 3],
    gyro_bias: [f64; 3],
}

impl ImuSensor {
    pub fn new(p: ImuParams, start_ns: u64, mut rng: ChaCha8Rng) -> Self {
        let accel_bias = std::array::from_fn(|_| gauss(&mut rng, p.accel_bias_mps2));
        let gyro_bias = std::array::from_fn(|_| gauss(&mut rng, p.gyro_bias_radps));
        Self {
            schedule: Schedule::new(start_ns, p.rate_hz),
            p,
            rng,
            accel_bias,
            gyro_bias,
        }
    }
}

impl SimSensor for ImuSensor {
    fn step(&mut self, w: &World, out: &mut Outbox) {
        if !self.schedule.due(w.t_ns) {
            return;
        }
        let dt = self.schedule.period_s();
        let p = &self.p;
        for b in &mut self.accel_bias {
            *b += gauss(&mut self.rng, p.accel_bias_walk * dt.sqrt());
        }
        for b in &mut self.gyro_bias {
            *b += gauss(&mut self.rng, p.gyro_bias_walk * dt.sqrt());
        }
        // A right-hand curve (positive curvature) pushes the body towards -y and yaws it
        // clockwise, which is a negative rate about the up axis.
        let truth_f = [
            w.acceleration_mps2,
            -w.speed_mps * w.speed_mps * w.curvature,
            GRAVITY_MPS2,
        ];
        let truth_w = [0.0, 0.0, -w.speed_mps * w.curvature];
        let specific_force_mps2 = std::array::from_fn(|i| {
            quantise(
                truth_f[i] + self.accel_bias[i] + gauss(&mut self.rng, p.accel_noise_mps2),
                p.accel_lsb_mps2,
            )
        });
        let angular_rate_radps = std::array::from_fn(|i| {
            quantise(
                truth_w[i] + self.gyro_bias[i] + gauss(&mut self.rng, p.gyro_noise_radps),
                p.gyro_lsb_radps,
            )
        });
        let msg = Imu {
            stamp_ns: w.t_ns,
            sensor_id: p.sensor_id.clone(),
            specific_force_mps2,
            angular_rate_radps,
            accel_lsb_mps2: (p.accel_lsb_mps2 > 0.0).then_some(p.accel_lsb_mps2),
            gyro_lsb_radps: (p.gyro_lsb_radps > 0.0).then_some(p.gyro_lsb_radps),
        };
        out.push(w.t_ns + seconds(p.latency_s), Emit::Imu(msg));
    }
}
