//! Sensors whose message is made from several signals, possibly of several CAN messages: a
//! GNSS fix (position, its accuracy, fix type, satellites, height, speed, course) and an IMU
//! sample (three accelerations, three angular rates). Each signal's latest value is kept with
//! its time; the sensor's message is made when its trigger message arrives (the position's,
//! the first acceleration's), from values no older than `max_age_s`.

use std::collections::{BTreeMap, HashMap};

use railfuse_can::decode::Value;

use crate::messages::{AnyMessage, FixType, GnssFix, Imu};

/// A DBC message: (the DBC's index among the buses', id, extended).
pub(super) type MessageKey = (usize, u32, bool);

/// One mapped signal: its message, name, scale to SI and the step of one raw count in SI.
#[derive(Debug, Clone)]
pub(super) struct SignalAt {
    pub message: MessageKey,
    pub name: String,
    pub scale: f64,
    pub lsb: f64,
}

/// The latest value of each signal a sensor reads, with its frame's time.
#[derive(Debug, Default)]
pub(super) struct Latest(HashMap<(MessageKey, String), (u64, f64)>);

impl Latest {
    /// Keeps the values of `message`'s frame that `signals` read.
    pub fn remember<'a>(
        &mut self,
        message: MessageKey,
        stamp_ns: u64,
        values: &[Value],
        signals: impl Iterator<Item = &'a SignalAt>,
    ) {
        for s in signals.filter(|s| s.message == message) {
            if let Some(v) = values.iter().find(|v| v.name == s.name) {
                if v.value.is_finite() && !v.out_of_range {
                    self.0
                        .insert((message, s.name.clone()), (stamp_ns, v.value));
                } else {
                    self.0.remove(&(message, s.name.clone()));
                }
            }
        }
    }

    /// A signal's value in SI units, if one came within `max_age_ns` of `now`.
    fn get(&self, s: &SignalAt, now: u64, max_age_ns: u64) -> Option<f64> {
        let &(t, v) = self.0.get(&(s.message, s.name.clone()))?;
        (now.abs_diff(t) <= max_age_ns).then_some(v * s.scale)
    }
}

/// u-blox's fix types (NAV-PVT `fixType`), which GNSS modules on CAN pass on: 0 no fix, 1
/// dead reckoning only, 2 2-D, 3 3-D, 4 GNSS and dead reckoning, 5 time only.
pub(super) fn ublox_fix_types() -> HashMap<i64, FixType> {
    HashMap::from([
        (0, FixType::None),
        (1, FixType::None),
        (2, FixType::Single),
        (3, FixType::Single),
        (4, FixType::Single),
        (5, FixType::None),
    ])
}

/// A GNSS fix's signals.
#[derive(Debug, Clone)]
pub(super) struct GnssSignals {
    pub latitude: SignalAt,
    pub longitude: SignalAt,
    pub altitude: Option<SignalAt>,
    pub accuracy: Option<SignalAt>,
    pub fix_type: Option<SignalAt>,
    pub fix_types: HashMap<i64, FixType>,
    pub satellites: Option<SignalAt>,
    pub speed: Option<SignalAt>,
    pub course: Option<SignalAt>,
    pub valid: Option<SignalAt>,
    pub max_age_ns: u64,
}

impl GnssSignals {
    pub fn signals(&self) -> impl Iterator<Item = &SignalAt> {
        [&self.latitude, &self.longitude]
            .into_iter()
            .chain(self.altitude.iter())
            .chain(self.accuracy.iter())
            .chain(self.fix_type.iter())
            .chain(self.satellites.iter())
            .chain(self.speed.iter())
            .chain(self.course.iter())
            .chain(self.valid.iter())
    }

    /// The fix of the position frame at `now`. A fix the module says is invalid (or of a
    /// type with no position) is a fix of type none, without a position.
    pub fn make(
        &self,
        latest: &Latest,
        now: u64,
        counts: &mut BTreeMap<String, u64>,
    ) -> Option<AnyMessage> {
        let age = self.max_age_ns;
        let get = |s: &Option<SignalAt>| s.as_ref().and_then(|s| latest.get(s, now, age));
        let (lat, lon) = (
            latest.get(&self.latitude, now, 0)?,
            latest.get(&self.longitude, now, 0)?,
        );
        let valid = match &self.valid {
            Some(v) => latest.get(v, now, age).is_some_and(|x| x != 0.0),
            None => true,
        };
        let fix_type = match get(&self.fix_type) {
            Some(t) => match self.fix_types.get(&(t.round() as i64)) {
                Some(&f) => f,
                None => {
                    *counts
                        .entry(format!("fix type {t} not in fix_types"))
                        .or_insert(0) += 1;
                    FixType::None
                }
            },
            // Mapped but not heard from lately: unknown, so not a usable fix.
            None if self.fix_type.is_some() => FixType::None,
            None => FixType::Single,
        };
        let fix_type = if valid { fix_type } else { FixType::None };
        let has = fix_type.has_position()
            && (-90.0..=90.0).contains(&lat)
            && (-180.0..=180.0).contains(&lon);
        let sigma = get(&self.accuracy).filter(|a| *a > 0.0);
        Some(AnyMessage::GnssFix(GnssFix {
            stamp_ns: now,
            fix_type: if has { fix_type } else { FixType::None },
            satellites: get(&self.satellites).map_or(0, |n| n.clamp(0.0, 255.0) as u8),
            hdop: None,
            latitude_deg: has.then_some(lat),
            longitude_deg: has.then_some(lon),
            altitude_m: None,
            altitude_msl_m: get(&self.altitude).filter(|_| has),
            position_covariance_enu_m2: sigma.filter(|_| has).map(|s| {
                let (h, v) = (s * s, 4.0 * s * s);
                [h, 0.0, 0.0, 0.0, h, 0.0, 0.0, 0.0, v]
            }),
            speed_mps: get(&self.speed).filter(|_| has).map(f64::abs),
            course_rad: get(&self.course)
                .filter(|_| has)
                .map(|c| c.rem_euclid(std::f64::consts::TAU)),
        }))
    }
}

/// An IMU sample's signals.
#[derive(Debug, Clone)]
pub(super) struct ImuSignals {
    pub acceleration: [SignalAt; 3],
    pub angular_rate: [SignalAt; 3],
    pub valid: Option<SignalAt>,
    pub max_age_ns: u64,
}

impl ImuSignals {
    pub fn signals(&self) -> impl Iterator<Item = &SignalAt> {
        self.acceleration
            .iter()
            .chain(&self.angular_rate)
            .chain(self.valid.iter())
    }

    /// The sample of the first acceleration's frame at `now`.
    pub fn make(&self, sensor_id: &str, latest: &Latest, now: u64) -> Option<AnyMessage> {
        let age = self.max_age_ns;
        if let Some(v) = &self.valid {
            if latest.get(v, now, age)? == 0.0 {
                return None;
            }
        }
        let axes = |s: &[SignalAt; 3]| -> Option<[f64; 3]> {
            Some([
                latest.get(&s[0], now, age)?,
                latest.get(&s[1], now, age)?,
                latest.get(&s[2], now, age)?,
            ])
        };
        let one_step = |s: &[SignalAt; 3]| {
            let lsb = s[0].lsb;
            (lsb > 0.0 && s.iter().all(|a| (a.lsb - lsb).abs() <= 1e-12 * lsb)).then_some(lsb)
        };
        Some(AnyMessage::Imu(Imu {
            stamp_ns: now,
            sensor_id: sensor_id.to_owned(),
            specific_force_mps2: axes(&self.acceleration)?,
            angular_rate_radps: axes(&self.angular_rate)?,
            accel_lsb_mps2: one_step(&self.acceleration),
            gyro_lsb_radps: one_step(&self.angular_rate),
        }))
    }
}
