//! The car body's vibration: what the track excites beyond following it, as an accelerometer
//! and a gyro on the floor feel it.
//!
//! Each axis is a sum of resonances, each a damped oscillator driven by white noise
//! (`ẍ = −ω²x − 2ζωẋ + σ_w w`) whose output `2ζωẋ` has the stated RMS: a band around the mode
//! with unit gain at its peak and none at 0 Hz (the body's displacement and velocity stay
//! bounded, so it has no lasting acceleration; the spring force `ω²x` would carry the drive's
//! white floor down to 0 Hz and look like a wandering accelerometer bias). The modes are the
//! body's own (bounce about 1.1 Hz, sway 0.8 Hz, roll and pitch near 1 Hz) and the bogie and track band
//! (6–10 Hz). The level grows with speed up to `reference_speed_mps` and is nothing at a
//! standstill, as on a train: a car at rest in a station is still. The levels are those of a
//! coach's floor at line speed: about 0.3 m/s² RMS vertically, 0.15 sideways, 0.05 along
//! the train, a few mrad/s of roll, pitch and yaw rate (unweighted, as EN 12299's
//! measurements of running behaviour report them).

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::sensors::gauss;

/// What a resonance drives: specific force along body x, y or z (m/s²), or the angular rate
/// about them (rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RideAxis {
    AlongX,
    AlongY,
    AlongZ,
    AboutX,
    AboutY,
    AboutZ,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Resonance {
    pub axis: RideAxis,
    pub frequency_hz: f64,
    pub damping: f64,
    /// RMS of its output at the reference speed (m/s² or rad/s).
    pub rms: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RideParams {
    pub reference_speed_mps: f64,
    pub resonances: Vec<Resonance>,
}

impl RideParams {
    /// A coach's floor on a main line at 120 km/h.
    pub fn coach() -> RideParams {
        let r = |axis, frequency_hz, damping, rms| Resonance {
            axis,
            frequency_hz,
            damping,
            rms,
        };
        use RideAxis::*;
        RideParams {
            reference_speed_mps: 33.3,
            resonances: vec![
                r(AlongZ, 1.1, 0.15, 0.15),
                r(AlongZ, 9.0, 0.10, 0.25),
                r(AlongY, 0.8, 0.20, 0.10),
                r(AlongY, 6.0, 0.10, 0.12),
                r(AlongX, 4.0, 0.20, 0.05),
                r(AboutX, 0.9, 0.20, 0.004),
                r(AboutY, 1.3, 0.20, 0.003),
                r(AboutZ, 1.0, 0.20, 0.002),
            ],
        }
    }
}

/// The body's vibration now, in body axes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RideSample {
    pub specific_force: [f64; 3],
    pub angular_rate: [f64; 3],
}

/// The resonances' states, stepped with the simulation.
pub struct Ride {
    p: RideParams,
    /// Each resonance's (x, ẋ).
    states: Vec<(f64, f64)>,
    rng: ChaCha8Rng,
}

impl Ride {
    pub fn new(p: RideParams, rng: ChaCha8Rng) -> Ride {
        Ride {
            states: vec![(0.0, 0.0); p.resonances.len()],
            p,
            rng,
        }
    }

    /// Steps every resonance by `dt` at `speed_mps` (semi-implicit Euler: stable at the
    /// simulation's 1 ms for these frequencies) and gives the vibration.
    pub fn step(&mut self, speed_mps: f64, dt: f64) -> RideSample {
        let level = (speed_mps.abs() / self.p.reference_speed_mps).min(1.5);
        let mut now = RideSample::default();
        for (r, (x, v)) in self.p.resonances.iter().zip(&mut self.states) {
            let omega = std::f64::consts::TAU * r.frequency_hz;
            // ẋ has variance σ_w² / 4ζω, so the output 2ζωẋ has ζωσ_w²: the drive that gives
            // the stated RMS.
            let drive = level * r.rms / (r.damping * omega).sqrt();
            *v += (-omega * omega * *x - 2.0 * r.damping * omega * *v) * dt
                + drive * gauss(&mut self.rng, dt.sqrt());
            *x += *v * dt;
            let out = 2.0 * r.damping * omega * *v;
            match r.axis {
                RideAxis::AlongX => now.specific_force[0] += out,
                RideAxis::AlongY => now.specific_force[1] += out,
                RideAxis::AlongZ => now.specific_force[2] += out,
                RideAxis::AboutX => now.angular_rate[0] += out,
                RideAxis::AboutY => now.angular_rate[1] += out,
                RideAxis::AboutZ => now.angular_rate[2] += out,
            }
        }
        now
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::sensors::rng_stream;

    #[test]
    fn the_vibration_has_its_stated_level_at_speed_and_none_at_rest() {
        let mut ride = Ride::new(RideParams::coach(), rng_stream(1, 40));
        let (mut sum, mut n) = ([0.0f64; 3], 0);
        for k in 0..600_000 {
            let s = ride.step(33.3, 1e-3);
            if k > 20_000 {
                for i in 0..3 {
                    sum[i] += s.specific_force[i].powi(2);
                }
                n += 1;
            }
        }
        let rms = sum.map(|x| (x / n as f64).sqrt());
        // Vertical: √(0.15² + 0.25²) = 0.29; sideways √(0.10² + 0.12²) = 0.16; along 0.05.
        assert!((rms[2] - 0.29).abs() < 0.04, "{rms:?}");
        assert!((rms[1] - 0.16).abs() < 0.03, "{rms:?}");
        assert!((rms[0] - 0.05).abs() < 0.01, "{rms:?}");
        let mut still = Ride::new(RideParams::coach(), rng_stream(1, 40));
        assert_eq!(still.step(0.0, 1e-3), RideSample::default());
    }
}
