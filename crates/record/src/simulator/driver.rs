//! The train's speed profile: a simple driver that accelerates (power-limited), cruises,
//! brakes on a service braking curve to stop at each station, and dwells. Jerk-limited, so the
//! true acceleration is continuous as on a real train.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriverParams {
    pub max_speed_mps: f64,
    /// Starting acceleration; above `power_limit_speed_mps` it falls as 1/v (constant power).
    pub acceleration_mps2: f64,
    pub power_limit_speed_mps: f64,
    /// Service braking used for the braking curve.
    pub braking_mps2: f64,
    pub jerk_mps3: f64,
    pub dwell_s: f64,
    pub initial_dwell_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    Dwell {
        until_s: f64,
    },
    Running,
    /// Stopped at the final station: the run is over.
    Finished,
}

/// Events of the driver worth logging.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriverEvent {
    Arrived(usize),
    Departed(usize),
}

pub struct Driver {
    p: DriverParams,
    stations: Vec<f64>,
    /// Index of the station the train is heading to (or standing at while dwelling).
    target: usize,
    pub phase: Phase,
    pub s: f64,
    pub v: f64,
    pub a: f64,
}

impl Driver {
    pub fn new(p: DriverParams, stations: Vec<f64>) -> Self {
        let until_s = p.initial_dwell_s;
        Self {
            p,
            stations,
            target: 0,
            phase: Phase::Dwell { until_s },
            s: 0.0,
            v: 0.0,
            a: 0.0,
        }
    }

    /// Advances the true state from time `t` (s since start) to `t + dt`.
    pub fn step(&mut self, t: f64, dt: f64) -> Option<DriverEvent> {
        match self.phase {
            Phase::Finished => None,
            Phase::Dwell { until_s } => {
                if t < until_s {
                    return None;
                }
                let from = self.target;
                if self.target + 1 >= self.stations.len() {
                    self.phase = Phase::Finished;
                    return None;
                }
                self.target += 1;
                self.phase = Phase::Running;
                Some(DriverEvent::Departed(from))
            }
            Phase::Running => {
                let d = self.stations[self.target] - self.s;
                let v_brake = (2.0 * self.p.braking_mps2 * d.max(0.0)).sqrt();
                let v_ref = self.p.max_speed_mps.min(v_brake);
                let a_max = self.p.acceleration_mps2
                    * (self.p.power_limit_speed_mps / self.v.max(1e-3)).min(1.0);
                // Proportional speed control, with feed-forward of the braking curve's slope.
                let feed_forward = if v_brake < self.p.max_speed_mps {
                    -self.p.braking_mps2
                } else {
                    0.0
                };
                let a_cmd = (feed_forward + 1.2 * (v_ref - self.v))
                    .clamp(-1.3 * self.p.braking_mps2, a_max);
                // The acceleration ramps (constant jerk) over the step, and speed and
                // position are its exact integrals: the state at the step's end is the
                // state at that instant, to well under the step, which latency estimates
                // of a millisecond need.
                let max_da = self.p.jerk_mps3 * dt;
                let a_next = self.a + (a_cmd - self.a).clamp(-max_da, max_da);
                let v_next = self.v + (self.a + a_next) * dt / 2.0;
                if v_next <= 0.0 {
                    self.s += self.v * dt / 2.0;
                    self.v = 0.0;
                    self.a = 0.0;
                } else {
                    self.s += self.v * dt + (2.0 * self.a + a_next) * dt * dt / 6.0;
                    self.v = v_next;
                    self.a = a_next;
                }
                if d < 0.5 && self.v < 0.05 {
                    self.v = 0.0;
                    self.a = 0.0;
                    self.phase = Phase::Dwell {
                        until_s: t + self.p.dwell_s,
                    };
                    return Some(DriverEvent::Arrived(self.target));
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_driver_stops_at_every_station_within_half_a_metre_and_keeps_limits() {
        let p = DriverParams {
            max_speed_mps: 33.0,
            acceleration_mps2: 0.8,
            power_limit_speed_mps: 15.0,
            braking_mps2: 0.7,
            jerk_mps3: 0.6,
            dwell_s: 20.0,
            initial_dwell_s: 5.0,
        };
        let stations = vec![0.0, 3000.0, 5700.0];
        let mut d = Driver::new(p, stations.clone());
        let dt = 1e-3;
        let mut arrivals = vec![];
        let mut vmax: f64 = 0.0;
        for k in 0..2_000_000 {
            let t = k as f64 * dt;
            if let Some(DriverEvent::Arrived(i)) = d.step(t, dt) {
                arrivals.push((i, d.s));
            }
            vmax = vmax.max(d.v);
            assert!(d.v >= 0.0 && d.a.abs() < 1.0);
            if d.phase == Phase::Finished {
                break;
            }
        }
        assert_eq!(d.phase, Phase::Finished);
        assert_eq!(arrivals.len(), 2);
        for (i, s) in arrivals {
            assert!((s - stations[i]).abs() < 0.5, "station {i} at {s}");
        }
        assert!(vmax > 30.0 && vmax < 33.5, "{vmax}");
    }
}
