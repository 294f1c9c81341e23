//! What the IMU's samples say before they are used: whether a sample is fit to navigate on
//! ([`ImuHealth`]), and, while the train stands, the sensor's static offsets ([`StaticBias`]).
//!
//! At standstill the yaw gyro reads its bias (plus the earth's rate about the local vertical,
//! 15 °/h · sin(latitude), 0.003 °/s at 45°, below a MEMS gyro's bias stability). The forward
//! accelerometer reads its bias plus `g · sin(grade)`: on a 0.5 % gradient 0.05 m/s², far more
//! than the bias. The navigation needs that sum, so the sum is what is measured here.

use railfuse_catalog::messages::Imu;

use super::settings::GnssInsSettings;

const AXES: [&str; 6] = [
    "specific force x",
    "specific force y",
    "specific force z",
    "angular rate x",
    "angular rate y",
    "angular rate z",
];

/// Per-sample checks of an IMU stream: finite, within range, no axis stuck.
#[derive(Debug, Clone)]
pub struct ImuHealth {
    stuck_after: u32,
    last: Option<[f64; 6]>,
    repeats: [u32; 6],
    was_bad: bool,
    first_bad: bool,
}

impl ImuHealth {
    pub fn new(stuck_samples: u32) -> Self {
        Self {
            stuck_after: stuck_samples,
            last: None,
            repeats: [0; 6],
            was_bad: false,
            first_bad: false,
        }
    }

    /// Judges one sample: `Err(why)` when it must not be used.
    pub fn judge(&mut self, m: &Imu, s: &GnssInsSettings) -> Result<(), String> {
        let values: [f64; 6] = std::array::from_fn(|i| match i < 3 {
            true => m.specific_force_mps2[i],
            false => m.angular_rate_radps[i - 3],
        });
        let verdict = self.verdict(&values, s);
        self.first_bad = verdict.is_err() && !self.was_bad;
        self.was_bad = verdict.is_err();
        verdict
    }

    /// The latest sample was the first bad one after good ones.
    pub fn first_of_episode(&self) -> bool {
        self.first_bad
    }

    fn verdict(&mut self, values: &[f64; 6], s: &GnssInsSettings) -> Result<(), String> {
        if let Some(i) = values.iter().position(|x| !x.is_finite()) {
            self.last = None;
            return Err(format!("{} is not a number", AXES[i]));
        }
        for (i, x) in values.iter().enumerate() {
            let limit = match i < 3 {
                true => s.max_specific_force_mps2,
                false => s.max_rate_radps,
            };
            if x.abs() >= limit {
                return Err(format!(
                    "saturated: {} {x:.3} at or beyond the range {limit:.3}",
                    AXES[i]
                ));
            }
        }
        if let Some(last) = self.last {
            let moved = values.iter().zip(&last).any(|(a, b)| a != b);
            for i in 0..6 {
                self.repeats[i] = match values[i] == last[i] {
                    true => self.repeats[i] + 1,
                    false => 0,
                };
            }
            self.last = Some(*values);
            let stuck = |i: usize| self.repeats[i] >= self.stuck_after;
            if (0..6).all(stuck) {
                // A real sensor's noise moves every axis: a reading repeated whole is a frozen
                // sensor (or a driver resending its last sample).
                return Err(format!(
                    "stuck: every axis has repeated its reading for {} samples",
                    self.repeats[0]
                ));
            }
            if let Some(i) = (0..6).find(|&i| moved && stuck(i)) {
                return Err(format!(
                    "stuck: {} has read {} for {} samples while the other axes change",
                    AXES[i], values[i], self.repeats[i]
                ));
            }
        } else {
            self.last = Some(*values);
        }
        Ok(())
    }
}

/// The mean readings while the train stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offsets {
    pub forward_mps2: f64,
    pub yaw_rate_radps: f64,
    pub samples: u64,
    pub seconds: f64,
}

/// The mean yaw rate of the standstill samples since the last look, and over how long.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawRate {
    pub mean_yaw_rate: f64,
    pub seconds: f64,
}

#[derive(Debug, Clone, Default)]
pub struct StaticBias {
    n: u64,
    sum_forward: f64,
    sum_yaw_rate: f64,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    /// Since the last `since_last_take`.
    recent_n: u64,
    recent_sum: f64,
    recent_first_ns: Option<u64>,
}

impl StaticBias {
    /// A sample taken while the train stands: its forward specific force and its rate about
    /// the vertical, as the navigation takes them (levelled where a map says how).
    pub fn push(&mut self, stamp_ns: u64, forward_mps2: f64, yaw_rate_radps: f64) {
        self.n += 1;
        self.sum_forward += forward_mps2;
        self.sum_yaw_rate += yaw_rate_radps;
        self.first_ns.get_or_insert(stamp_ns);
        self.last_ns = Some(stamp_ns);
        self.recent_n += 1;
        self.recent_sum += yaw_rate_radps;
        self.recent_first_ns.get_or_insert(stamp_ns);
    }

    pub fn last_ns(&self) -> Option<u64> {
        self.last_ns
    }

    /// The offsets over every standstill sample so far.
    pub fn estimate(&self) -> Option<Offsets> {
        (self.n > 0).then(|| Offsets {
            forward_mps2: self.sum_forward / self.n as f64,
            yaw_rate_radps: self.sum_yaw_rate / self.n as f64,
            samples: self.n,
            seconds: match (self.first_ns, self.last_ns) {
                (Some(a), Some(b)) => railfuse_catalog::seconds_between(a, b),
                _ => 0.0,
            },
        })
    }

    pub fn since_last_take(&mut self) -> Option<YawRate> {
        let n = std::mem::take(&mut self.recent_n);
        let sum = std::mem::take(&mut self.recent_sum);
        let first = self.recent_first_ns.take();
        (n > 0).then(|| YawRate {
            mean_yaw_rate: sum / n as f64,
            seconds: match (first, self.last_ns) {
                (Some(a), Some(b)) => railfuse_catalog::seconds_between(a, b).max(1e-3),
                _ => 1e-3,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn imu(t: u64, f: [f64; 3], w: [f64; 3]) -> Imu {
        Imu {
            stamp_ns: t,
            sensor_id: "imu".into(),
            specific_force_mps2: f,
            angular_rate_radps: w,
            accel_lsb_mps2: None,
            gyro_lsb_radps: None,
        }
    }

    #[test]
    fn bad_samples_are_refused_with_the_axis_and_the_cause() {
        let s = GnssInsSettings::default();
        let mut h = ImuHealth::new(5);
        assert!(h
            .judge(&imu(0, [0.1, 0.0, 9.8], [0.0, 0.0, 0.01]), &s)
            .is_ok());
        let e = h
            .judge(&imu(1, [f64::NAN, 0.0, 9.8], [0.0; 3]), &s)
            .unwrap_err();
        assert_eq!(e, "specific force x is not a number");
        assert!(h.first_of_episode());
        let e = h
            .judge(&imu(2, [0.1, 0.0, 25.0], [0.0; 3]), &s)
            .unwrap_err();
        assert!(e.starts_with("saturated: specific force z"), "{e}");
        assert!(!h.first_of_episode(), "the same episode");
        // Gyro z stuck at 0.02 while every other axis moves.
        let mut h = ImuHealth::new(5);
        let mut verdicts = Vec::new();
        for k in 0..10u64 {
            let x = 0.01 * k as f64;
            let f = [0.1 + x, -x, 9.8 + x];
            verdicts.push(h.judge(&imu(k, f, [x, -x, 0.02]), &s));
        }
        assert!(verdicts[..5].iter().all(Result::is_ok));
        let e = verdicts[5].clone().unwrap_err();
        assert_eq!(
            e,
            "stuck: angular rate z has read 0.02 for 5 samples while the other axes change"
        );
        // The whole reading repeated: a frozen sensor.
        let mut h = ImuHealth::new(5);
        let v: Vec<_> = (0..10)
            .map(|k| h.judge(&imu(k, [0.1, 0.2, 9.8], [0.01; 3]), &s))
            .collect();
        assert!(v[..5].iter().all(Result::is_ok));
        assert_eq!(
            v[5].clone().unwrap_err(),
            "stuck: every axis has repeated its reading for 5 samples"
        );
    }

    #[test]
    fn static_offsets_are_the_standstill_means() {
        let mut b = StaticBias::default();
        assert!(b.estimate().is_none());
        for k in 0..100u64 {
            let noise = if k % 2 == 0 { 1e-3 } else { -1e-3 };
            b.push(k * 5_000_000, 0.05 + noise, 2e-4 + noise);
        }
        let o = b.estimate().unwrap();
        assert!((o.forward_mps2 - 0.05).abs() < 1e-12 && (o.yaw_rate_radps - 2e-4).abs() < 1e-12);
        assert_eq!(o.samples, 100);
        assert!((o.seconds - 0.495).abs() < 1e-9);
        let r = b.since_last_take().unwrap();
        assert!((r.mean_yaw_rate - 2e-4).abs() < 1e-12);
        assert!(b.since_last_take().is_none());
    }
}
