//! A run's own motion between its fixes: the turn its IMU measured and the distance its
//! odometer (or radar) ran, summed into steps of a tenth of a second. Where a run has no fix
//! (a tunnel, a stretch without RTK), this is what carries its shape across
//! ([`crate::bridge`]). Its IMU's mean specific force and rate over short steps are kept too:
//! the body's roll, which [`crate::lean`] takes the antenna's lean and the cant from.

use nalgebra::Vector3;
use railfuse_catalog::messages::{Imu, Odometer, RadarSpeed, Vehicle};

/// Motion is summed over steps this long, ns.
const STEP_NS: u64 = 100_000_000;

/// Samples further apart than this are a gap in the sensor, not a step to integrate, ns.
const MAX_SAMPLE_GAP_NS: u64 = 500_000_000;

/// The turn and distance over one step, ending at `stamp_ns`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionStep {
    pub stamp_ns: u64,
    /// Distance run, m (the speed sensor's, uncorrected).
    pub distance_m: f64,
    /// Turn clockwise (as heading grows), rad (the gyro's, its bias included).
    pub turn_rad: f64,
}

/// Sums a run's IMU and speed samples into [`MotionStep`]s as they are read.
#[derive(Debug, Default)]
pub struct MotionRecorder {
    steps: Vec<MotionStep>,
    /// The speed sensor read: the first odometer, else the first radar.
    speed_from: Option<String>,
    speed_is_odometer: bool,
    speed: Option<(u64, f64)>,
    last_imu_ns: Option<u64>,
    open: Option<MotionStep>,
}

impl MotionRecorder {
    pub fn odometer(&mut self, m: &Odometer) {
        if self.take_speed(&m.sensor_id, true) && m.speed_mps.is_finite() {
            self.speed = Some((m.stamp_ns, m.speed_mps.max(0.0)));
        }
    }

    pub fn radar(&mut self, m: &RadarSpeed) {
        if m.valid && self.take_speed("radar", false) && m.speed_mps.is_finite() {
            self.speed = Some((m.stamp_ns, m.speed_mps.max(0.0)));
        }
    }

    /// Whether samples of this sensor are the speed read (an odometer displaces a radar).
    fn take_speed(&mut self, id: &str, odometer: bool) -> bool {
        if self.speed_from.is_none() || (odometer && !self.speed_is_odometer) {
            self.speed_from = Some(id.to_owned());
            self.speed_is_odometer = odometer;
        }
        self.speed_from.as_deref() == Some(id)
    }

    /// Integrates from the previous IMU sample to this one with the newest speed.
    pub fn imu(&mut self, m: &Imu) {
        let rate = m.angular_rate_radps[2];
        let last = self.last_imu_ns.replace(m.stamp_ns);
        let (Some(last), Some((speed_ns, speed))) = (last, self.speed) else {
            return;
        };
        let fresh = m.stamp_ns.abs_diff(speed_ns) <= MAX_SAMPLE_GAP_NS;
        if m.stamp_ns <= last
            || m.stamp_ns - last > MAX_SAMPLE_GAP_NS
            || !fresh
            || !rate.is_finite()
        {
            return;
        }
        let dt = (m.stamp_ns - last) as f64 / 1e9;
        // Heading is clockwise from north; the gyro's z (up) is counter-clockwise.
        let (turn, distance) = (-rate * dt, speed * dt);
        let step = self.open.get_or_insert(MotionStep {
            stamp_ns: m.stamp_ns,
            distance_m: 0.0,
            turn_rad: 0.0,
        });
        step.stamp_ns = m.stamp_ns;
        step.distance_m += distance;
        step.turn_rad += turn;
        let started = self.steps.last().map_or(0, |s| s.stamp_ns);
        if m.stamp_ns >= started + STEP_NS {
            self.steps.extend(self.open.take());
        }
    }

    pub fn finish(mut self) -> Vec<MotionStep> {
        self.steps.extend(self.open.take());
        self.steps
    }
}

/// IMU samples are averaged over tilt steps this long, ns.
const TILT_STEP_NS: u64 = 200_000_000;
/// What the run's lean and cant are taken from: its IMU's steps, the vehicle that places it
/// and the antenna, and their topics.
#[derive(Debug, Clone)]
pub struct Tilt {
    pub steps: Vec<TiltStep>,
    pub vehicle: Vehicle,
    pub imu: String,
    pub antenna: String,
}

/// The IMU's mean specific force and rate over one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltStep {
    pub stamp_ns: u64,
    pub specific_force: [f64; 3],
    pub angular_rate: [f64; 3],
}

/// Averages one IMU's samples into [`TiltStep`]s as they are read.
#[derive(Debug, Default)]
pub struct TiltRecorder {
    topic: Option<String>,
    steps: Vec<TiltStep>,
    /// The open step: its first stamp, the sums and the count.
    open: Option<(u64, Vector3<f64>, Vector3<f64>, u32)>,
}

impl TiltRecorder {
    /// Takes a sample of the IMU on `topic` (the first IMU read; others are not this one).
    pub fn imu(&mut self, topic: &str, m: &Imu) {
        if self.topic.get_or_insert_with(|| topic.to_owned()) != topic {
            return;
        }
        let (f, w) = (
            Vector3::from(m.specific_force_mps2),
            Vector3::from(m.angular_rate_radps),
        );
        if !(f.iter().chain(w.iter()).all(|x| x.is_finite())) {
            return;
        }
        let open = self
            .open
            .get_or_insert((m.stamp_ns, Vector3::zeros(), Vector3::zeros(), 0));
        if m.stamp_ns < open.0 {
            return;
        }
        open.1 += f;
        open.2 += w;
        open.3 += 1;
        if m.stamp_ns >= open.0 + TILT_STEP_NS {
            self.close(m.stamp_ns);
        }
    }

    fn close(&mut self, last_ns: u64) {
        if let Some((first, f, w, n)) = self.open.take() {
            let n = f64::from(n.max(1));
            self.steps.push(TiltStep {
                stamp_ns: first + (last_ns - first) / 2,
                specific_force: (f / n).into(),
                angular_rate: (w / n).into(),
            });
        }
    }

    /// The IMU's topic and its steps.
    pub fn finish(mut self) -> (Option<String>, Vec<TiltStep>) {
        if let Some((first, ..)) = self.open {
            self.close(first + TILT_STEP_NS);
        }
        (self.topic, self.steps)
    }
}

/// What taking the antenna's lean out of a run's fixes did ([`crate::lean`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Lean {
    /// Fixes moved.
    pub moved: usize,
    /// The largest move, m.
    pub max_m: f64,
    /// The roll on the straights taken off as the rest of the IMU's mounting, rad.
    pub straight_roll_rad: f64,
}
