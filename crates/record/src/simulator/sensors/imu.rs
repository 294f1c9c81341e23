//! MEMS IMU: specific force and angular rate in its own axes (mounted in the body, x forward,
//! y left, z up, by its [`SensorMount`]) at its place on the train, with turn-on bias, bias
//! random walk, white noise and LSB quantisation.

use railfuse_catalog::messages::{Imu, SensorMount};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{gauss, quantise};
use crate::simulator::kinematics::motion;
use crate::simulator::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

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
    mount: SensorMount,
    schedule: Schedule,
    rng: ChaCha8Rng,
    accel_bias: [f64; 3],
    gyro_bias: [f64; 3],
}

impl ImuSensor {
    pub fn new(p: ImuParams, mount: SensorMount, start_ns: u64, mut rng: ChaCha8Rng) -> Self {
        let accel_bias = std::array::from_fn(|_| gauss(&mut rng, p.accel_bias_mps2));
        let gyro_bias = std::array::from_fn(|_| gauss(&mut rng, p.gyro_bias_radps));
        Self {
            schedule: Schedule::new(start_ns, p.rate_hz),
            p,
            mount,
            rng,
            accel_bias,
            gyro_bias,
        }
    }
}

impl SimSensor for ImuSensor {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
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
        // On a level line a right-hand curve (positive curvature) pushes the body towards -y
        // and yaws it clockwise, a negative rate about the up axis; gradients, cant, the
        // body's lean and vibration, and the mounting add to that (see kinematics.rs).
        let m = motion(w, &self.mount);
        let (truth_f, truth_w) = (m.specific_force, m.angular_rate);
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
