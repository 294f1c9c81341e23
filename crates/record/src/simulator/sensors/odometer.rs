//! Wheel/axle odometer (pulse generator): counts pulses of the real wheel, converts them with
//! the configured (nominal) diameter, and so carries the wear error and every slip (traction)
//! and slide (braking) of its axle.

use std::collections::VecDeque;
use std::f64::consts::PI;

use railfuse_catalog::messages::Odometer;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::simulator::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OdometerParams {
    pub sensor_id: String,
    pub rate_hz: f64,
    pub latency_s: f64,
    pub pulses_per_revolution: u32,
    /// The diameter the unit is configured with.
    pub configured_diameter_m: f64,
    /// The worn wheel's real diameter.
    pub true_diameter_m: f64,
    /// Window over which speed is computed from pulses, s.
    pub speed_window_s: f64,
    /// Slip episodes under traction (a powered axle), per second while accelerating.
    pub slip_rate_per_s: f64,
    /// Slide episodes under braking, per second while braking.
    pub slide_rate_per_s: f64,
    /// Magnitude ranges of slip (wheel faster) and slide (wheel slower), as fractions.
    pub slip_range: (f64, f64),
    pub slide_range: (f64, f64),
    pub episode_s: (f64, f64),
}

pub struct OdometerSensor {
    p: OdometerParams,
    index: usize,
    /// Its axle's lever arm x (behind the front end), m.
    along_m: f64,
    schedule: Schedule,
    rng: ChaCha8Rng,
    wheel_distance_m: f64,
    /// (stamp, pulse count) samples over the speed window.
    history: VecDeque<(u64, u64)>,
    last_pulses: u64,
    /// Current slip (+) or slide (−) fraction and until when it lasts.
    episode: (f64, u64),
}

impl OdometerSensor {
    pub fn new(
        p: OdometerParams,
        index: usize,
        along_m: f64,
        start_ns: u64,
        rng: ChaCha8Rng,
    ) -> Self {
        Self {
            schedule: Schedule::new(start_ns, p.rate_hz),
            p,
            index,
            along_m,
            rng,
            wheel_distance_m: 0.0,
            history: VecDeque::new(),
            last_pulses: 0,
            episode: (0.0, 0),
        }
    }
}

impl SimSensor for OdometerSensor {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        let p = &self.p;
        if w.t_ns >= self.episode.1 {
            self.episode.0 = 0.0;
            let (rate, range, sign) = if w.acceleration_mps2 > 0.3 {
                (p.slip_rate_per_s, p.slip_range, 1.0)
            } else if w.acceleration_mps2 < -0.4 {
                (p.slide_rate_per_s, p.slide_range, -1.0)
            } else {
                (0.0, (0.0, 0.0), 0.0)
            };
            if rate > 0.0 && w.speed_mps > 1.0 && self.rng.random_bool((rate * w.dt).min(1.0)) {
                let magnitude = self.rng.random_range(range.0..range.1);
                let length = self.rng.random_range(p.episode_s.0..p.episode_s.1);
                self.episode = (sign * magnitude, w.t_ns + seconds(length));
            }
        }
        // The wheel rolls the rail, longer than the chainage on a gradient.
        self.wheel_distance_m += w.rail_speed_at(self.along_m) * (1.0 + self.episode.0) * w.dt;
        if !self.schedule.due(w.t_ns) {
            return;
        }
        let pulse_len_true = PI * p.true_diameter_m / p.pulses_per_revolution as f64;
        let pulse_len_cfg = PI * p.configured_diameter_m / p.pulses_per_revolution as f64;
        let pulses = (self.wheel_distance_m / pulse_len_true).floor() as u64;
        self.history.push_back((w.t_ns, pulses));
        while self.history.len() > 2
            && (w.t_ns - self.history[1].0) as f64 / 1e9 >= p.speed_window_s
        {
            self.history.pop_front();
        }
        let (t0, c0) = *self.history.front().expect("just pushed");
        let span = (w.t_ns - t0) as f64 / 1e9;
        let speed = if span > 0.0 {
            (pulses - c0) as f64 * pulse_len_cfg / span
        } else {
            0.0
        };
        let msg = Odometer {
            stamp_ns: w.t_ns,
            sensor_id: p.sensor_id.clone(),
            pulse_count: Some(pulses),
            pulses_per_revolution: Some(p.pulses_per_revolution),
            wheel_diameter_m: Some(p.configured_diameter_m),
            distance_increment_m: Some((pulses - self.last_pulses) as f64 * pulse_len_cfg),
            speed_mps: speed,
        };
        self.last_pulses = pulses;
        out.push(
            w.t_ns + seconds(p.latency_s),
            Emit::Odometer(self.index, msg),
        );
    }
}
