//! A GNSS fix's and an IMU's `[sensor."<topic>"]` table checked against the DBCs: every
//! signal found, its unit turned into SI, the keys of the other sensor kinds refused.

use std::collections::HashMap;

use railfuse_can::dbc::{BusDbcs, Signal};

use super::assembled::{self, GnssSignals, ImuSignals, Latest, SignalAt};
use super::sensor::{find_signal, Mapped, Reading};
use super::settings::{MappingError, SensorSource};
use crate::messages::{FixType, MessageKind};
use crate::units::{self, Units, ACCELERATION, COUNT, DEGREES, METRES, RADIANS, RATE, SPEED};

type Dbs = BusDbcs;

fn sensor_error(topic: &str, cause: impl Into<String>) -> MappingError {
    MappingError::Sensor {
        topic: topic.into(),
        cause: cause.into(),
    }
}

/// The keys a speed sensor (odometer, radar) does not take.
pub(super) fn only_for(
    topic: &str,
    kind: MessageKind,
    s: &SensorSource,
) -> Result<(), MappingError> {
    let given = [
        ("latitude", s.latitude.is_some()),
        ("longitude", s.longitude.is_some()),
        ("altitude", s.altitude.is_some()),
        ("accuracy", s.accuracy.is_some()),
        ("fix_type", s.fix_type.is_some()),
        ("fix_types", s.fix_types.is_some()),
        ("satellites", s.satellites.is_some()),
        ("speed", s.speed.is_some()),
        ("course", s.course.is_some()),
        ("acceleration", s.acceleration.is_some()),
        ("angular_rate", s.angular_rate.is_some()),
        ("max_age_s", s.max_age_s.is_some()),
    ];
    match given.iter().find(|(_, g)| *g) {
        Some((key, _)) => Err(sensor_error(
            topic,
            format!(
                "`{key}` is a GNSS fix's or an IMU's; a {} takes `from` or `pulses`",
                kind.type_name()
            ),
        )),
        None => Ok(()),
    }
}

/// A signal's unit's factor among `units`, or why not.
fn unit_scale(signal: &Signal, units: Units, what: &str) -> Result<f64, String> {
    units::factor(units, &signal.unit, what)
}

/// A signal of `given`, its unit one of `units`.
fn signal_at(
    dbs: &Dbs,
    topic: &str,
    key: &'static str,
    given: &str,
    units: Units,
    what: &str,
) -> Result<SignalAt, MappingError> {
    let (message, signal) = find_signal(dbs, topic, key, given)?;
    let scale = unit_scale(signal, units, what).map_err(|cause| MappingError::Signal {
        topic: topic.into(),
        key,
        given: given.into(),
        cause,
    })?;
    Ok(SignalAt {
        message,
        name: signal.name.clone(),
        scale,
        lsb: signal.factor.abs() * scale,
    })
}

fn optional(
    dbs: &Dbs,
    topic: &str,
    key: &'static str,
    given: &Option<String>,
    units: Units,
    what: &str,
) -> Result<Option<SignalAt>, MappingError> {
    given
        .as_ref()
        .map(|g| signal_at(dbs, topic, key, g, units, what))
        .transpose()
}

/// A flag: any unit (0 is "not valid").
fn flag(dbs: &Dbs, topic: &str, given: &Option<String>) -> Result<Option<SignalAt>, MappingError> {
    given
        .as_ref()
        .map(|g| {
            let (message, signal) = find_signal(dbs, topic, "valid", g)?;
            Ok(SignalAt {
                message,
                name: signal.name.clone(),
                scale: 1.0,
                lsb: 0.0,
            })
        })
        .transpose()
}

/// A GNSS fix's or an IMU's mapping.
pub(super) fn assembled_sensor(
    dbs: &Dbs,
    topic: &str,
    kind: MessageKind,
    s: &SensorSource,
) -> Result<Mapped, MappingError> {
    let speed_keys = [
        ("from", s.from.is_some()),
        ("pulses", s.pulses.is_some()),
        ("quality", s.quality.is_some()),
    ];
    if let Some((key, _)) = speed_keys.iter().find(|(_, g)| *g) {
        return Err(sensor_error(
            topic,
            format!("`{key}` is an odometer's or a radar's"),
        ));
    }
    let max_age_s = s
        .max_age_s
        .unwrap_or(if kind == MessageKind::Imu { 0.1 } else { 1.5 });
    if !(max_age_s.is_finite() && max_age_s > 0.0 && max_age_s <= 10.0) {
        return Err(sensor_error(
            topic,
            "max_age_s is more than 0 and at most 10 s",
        ));
    }
    let max_age_ns = (max_age_s * 1e9) as u64;
    let valid = flag(dbs, topic, &s.valid)?;
    let (reading, message) = match kind {
        MessageKind::Imu => {
            let imu = imu_signals(dbs, topic, s, valid, max_age_ns)?;
            let message = imu.acceleration[0].message;
            (Reading::Imu(Box::new(imu)), message)
        }
        _ => {
            let gnss = gnss_signals(dbs, topic, s, valid, max_age_ns)?;
            let message = gnss.latitude.message;
            (Reading::Gnss(Box::new(gnss)), message)
        }
    };
    Ok(Mapped {
        topic: topic.to_owned(),
        kind,
        message,
        reading,
        valid: None,
        quality: None,
        latest: Latest::default(),
    })
}

/// An IMU's six signals (and its flag).
fn imu_signals(
    dbs: &Dbs,
    topic: &str,
    s: &SensorSource,
    valid: Option<SignalAt>,
    max_age_ns: u64,
) -> Result<ImuSignals, MappingError> {
    if s.latitude.is_some() || s.longitude.is_some() || s.fix_type.is_some() {
        return Err(sensor_error(
            topic,
            "an IMU takes `acceleration` and `angular_rate`",
        ));
    }
    let (Some(a), Some(w)) = (&s.acceleration, &s.angular_rate) else {
        return Err(sensor_error(
            topic,
            "an IMU needs `acceleration` and `angular_rate`, three signals each (x, y, z)",
        ));
    };
    let axes = |key, given: &[String; 3], units, what| -> Result<[SignalAt; 3], MappingError> {
        Ok([
            signal_at(dbs, topic, key, &given[0], units, what)?,
            signal_at(dbs, topic, key, &given[1], units, what)?,
            signal_at(dbs, topic, key, &given[2], units, what)?,
        ])
    };
    Ok(ImuSignals {
        acceleration: axes("acceleration", a, ACCELERATION, "an acceleration")?,
        angular_rate: axes("angular_rate", w, RATE, "an angular rate")?,
        valid,
        max_age_ns,
    })
}

/// A GNSS fix's signals: its position of one message, the rest of any.
fn gnss_signals(
    dbs: &Dbs,
    topic: &str,
    s: &SensorSource,
    valid: Option<SignalAt>,
    max_age_ns: u64,
) -> Result<GnssSignals, MappingError> {
    if s.acceleration.is_some() || s.angular_rate.is_some() {
        return Err(sensor_error(
            topic,
            "a GNSS fix takes no `acceleration` or `angular_rate`",
        ));
    }
    let (Some(lat), Some(lon)) = (&s.latitude, &s.longitude) else {
        return Err(sensor_error(
            topic,
            "a GNSS fix needs `latitude` and `longitude`",
        ));
    };
    let latitude = signal_at(dbs, topic, "latitude", lat, DEGREES, "a latitude")?;
    let longitude = signal_at(dbs, topic, "longitude", lon, DEGREES, "a longitude")?;
    if latitude.message != longitude.message {
        return Err(sensor_error(
            topic,
            "`latitude` and `longitude` must be signals of one message",
        ));
    }
    Ok(GnssSignals {
        latitude,
        longitude,
        altitude: optional(dbs, topic, "altitude", &s.altitude, METRES, "a height")?,
        accuracy: optional(dbs, topic, "accuracy", &s.accuracy, METRES, "an accuracy")?,
        fix_type: optional(
            dbs,
            topic,
            "fix_type",
            &s.fix_type,
            COUNT,
            "a fix type (a number)",
        )?,
        fix_types: fix_types(topic, s)?,
        satellites: optional(dbs, topic, "satellites", &s.satellites, COUNT, "a count")?,
        speed: optional(dbs, topic, "speed", &s.speed, SPEED, "a speed")?,
        course: optional(dbs, topic, "course", &s.course, RADIANS, "a course")?,
        valid,
        max_age_ns,
    })
}

/// `fix_types`, its values' keys whole numbers; u-blox's without it.
fn fix_types(topic: &str, s: &SensorSource) -> Result<HashMap<i64, FixType>, MappingError> {
    let Some(table) = &s.fix_types else {
        return Ok(assembled::ublox_fix_types());
    };
    table
        .iter()
        .map(|(k, v)| {
            k.trim()
                .parse::<i64>()
                .map(|k| (k, *v))
                .map_err(|_| sensor_error(topic, format!("fix_types: '{k}' is not a whole number")))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::sync::Arc;

    use railfuse_can::dbc::{BusDbcs, Database};

    use crate::foreign::can::{SensorBridge, SensorSource};
    use crate::messages::{AnyMessage, CanFrame, FixType};

    const GNSS: &str = r#"VERSION ""

NS_ :

BS_:

BU_: GNSS

BO_ 3 pos: 8 GNSS
 SG_ Valid : 0|1@1+ (1,0) [0|1] "" GNSS
 SG_ Lat : 1|28@1+ (1e-06,-90) [-90|90] "deg" GNSS
 SG_ Lon : 29|29@1+ (1e-06,-180) [-180|180] "deg" GNSS
 SG_ Acc : 58|6@1+ (1,0) [0|63] "m" GNSS

BO_ 1 status: 1 GNSS
 SG_ Fix : 0|3@1+ (1,0) [0|5] "" GNSS
 SG_ Sats : 3|5@1+ (1,0) [0|31] "" GNSS

BO_ 9 imu: 8 GNSS
 SG_ Ax : 0|10@1+ (0.125,-64) [-64|63.875] "m/s^2" GNSS
 SG_ Ay : 10|10@1+ (0.125,-64) [-64|63.875] "m/s^2" GNSS
 SG_ Az : 20|10@1+ (0.125,-64) [-64|63.875] "m/s^2" GNSS
 SG_ Wx : 30|11@1+ (0.25,-256) [-256|255.75] "deg/s" GNSS
 SG_ Wy : 41|11@1+ (0.25,-256) [-256|255.75] "deg/s" GNSS
 SG_ Wz : 52|11@1+ (0.25,-256) [-256|255.75] "deg/s" GNSS
"#;

    fn dbcs() -> BusDbcs {
        BusDbcs(vec![(
            Some("CAN2".into()),
            Arc::new(Database::parse("g.dbc", GNSS).unwrap()),
        )])
    }

    /// Bits into a little-endian payload.
    fn pack(fields: &[(u32, u32, u64)]) -> Vec<u8> {
        let mut word = 0u64;
        for &(start, size, raw) in fields {
            word |= (raw & ((1 << size) - 1)) << start;
        }
        word.to_le_bytes().to_vec()
    }

    fn frame(t_ms: u64, id: u32, data: Vec<u8>) -> CanFrame {
        CanFrame {
            stamp_ns: t_ms * 1_000_000,
            receive_ns: t_ms * 1_000_000,
            bus: "CAN2".into(),
            ..crate::foreign::can::bridge::tests::frame(id, &data)
        }
    }

    fn gnss() -> SensorSource {
        SensorSource {
            latitude: Some("can:pos.Lat".into()),
            longitude: Some("can:pos.Lon".into()),
            valid: Some("can:pos.Valid".into()),
            accuracy: Some("can:pos.Acc".into()),
            fix_type: Some("can:status.Fix".into()),
            satellites: Some("can:status.Sats".into()),
            ..Default::default()
        }
    }

    fn pos(t_ms: u64, valid: u64) -> CanFrame {
        // 55.870142°, 9.791234°, 3 m.
        let lat = ((55.870142 + 90.0) * 1e6_f64).round() as u64;
        let lon = ((9.791234 + 180.0) * 1e6_f64).round() as u64;
        frame(
            t_ms,
            3,
            pack(&[(0, 1, valid), (1, 28, lat), (29, 29, lon), (58, 6, 3)]),
        )
    }

    #[test]
    fn a_fix_is_made_of_its_position_and_the_latest_status_of_another_message() {
        let sensors = BTreeMap::from([("/gnss/fix".to_owned(), gnss())]);
        let mut b = SensorBridge::with_databases(dbcs(), &sensors).unwrap();
        assert!(b
            .frame(&frame(0, 1, pack(&[(0, 3, 3), (3, 5, 11)])))
            .is_empty());
        let made = b.frame(&pos(200, 1));
        let AnyMessage::GnssFix(f) = &made[0].1 else {
            panic!("{made:?}")
        };
        assert_eq!((f.fix_type, f.satellites), (FixType::Single, 11));
        assert!((f.latitude_deg.unwrap() - 55.870142).abs() < 1e-9);
        assert_eq!(f.position_covariance_enu_m2.unwrap()[0], 9.0);
        // The module says the position is not valid: a fix of type none, no position.
        let AnyMessage::GnssFix(f) = &b.frame(&pos(1200, 0))[0].1 else {
            panic!()
        };
        assert_eq!((f.fix_type, f.latitude_deg), (FixType::None, None));
        // The status went quiet for longer than max_age_s: its fix type is not known.
        let AnyMessage::GnssFix(f) = &b.frame(&pos(3000, 1))[0].1 else {
            panic!()
        };
        assert_eq!(f.fix_type, FixType::None);
        // Another bus's frames are not this DBC's.
        let mut other = pos(3100, 1);
        other.bus = "CAN1".into();
        assert!(b.frame(&other).is_empty());
    }

    #[test]
    fn an_imu_sample_is_in_si_units_with_its_dbc_steps() {
        let sensors = BTreeMap::from([(
            "/imu".to_owned(),
            SensorSource {
                acceleration: Some([
                    "can:imu.Ax".into(),
                    "can:imu.Ay".into(),
                    "can:imu.Az".into(),
                ]),
                angular_rate: Some([
                    "can:imu.Wx".into(),
                    "can:imu.Wy".into(),
                    "can:imu.Wz".into(),
                ]),
                ..Default::default()
            },
        )]);
        let mut b = SensorBridge::with_databases(dbcs(), &sensors).unwrap();
        // ax = 0.125 m/s², az = 9.875 m/s², wz = 2.5 °/s.
        let data = pack(&[
            (0, 10, 513),
            (10, 10, 512),
            (20, 10, 591),
            (30, 11, 1024),
            (41, 11, 1024),
            (52, 11, 1034),
        ]);
        let made = b.frame(&frame(10, 9, data));
        let AnyMessage::Imu(m) = &made[0].1 else {
            panic!("{made:?}")
        };
        assert_eq!(m.specific_force_mps2, [0.125, 0.0, 9.875]);
        assert!((m.angular_rate_radps[2] - 2.5f64.to_radians()).abs() < 1e-12);
        assert_eq!(m.accel_lsb_mps2, Some(0.125));
        assert!((m.gyro_lsb_radps.unwrap() - 0.25f64.to_radians()).abs() < 1e-15);
    }

    #[test]
    fn mappings_that_cannot_make_a_fix_or_a_sample_say_why() {
        let bad = |topic: &str, s: SensorSource| {
            let sensors = BTreeMap::from([(topic.to_owned(), s)]);
            SensorBridge::with_databases(dbcs(), &sensors)
                .err()
                .expect("refused")
                .to_string()
        };
        let cases = [
            (
                "/gnss/fix",
                SensorSource {
                    longitude: None,
                    ..gnss()
                },
                "needs `latitude` and `longitude`",
            ),
            (
                "/gnss/fix",
                SensorSource {
                    longitude: Some("can:status.Sats".into()),
                    ..gnss()
                },
                "is in ''",
            ),
            (
                "/gnss/fix",
                SensorSource {
                    from: Some("can:pos.Lat".into()),
                    ..gnss()
                },
                "`from` is an odometer's",
            ),
            (
                "/gnss/fix",
                SensorSource {
                    fix_types: Some(BTreeMap::from([("x".into(), FixType::Single)])),
                    ..gnss()
                },
                "'x' is not a whole number",
            ),
            (
                "/imu",
                SensorSource {
                    acceleration: Some([
                        "can:imu.Ax".into(),
                        "can:imu.Ay".into(),
                        "can:imu.Wz".into(),
                    ]),
                    angular_rate: Some([
                        "can:imu.Wx".into(),
                        "can:imu.Wy".into(),
                        "can:imu.Wz".into(),
                    ]),
                    ..Default::default()
                },
                "is in 'deg/s': an acceleration",
            ),
            (
                "/odometer/1",
                SensorSource {
                    from: Some("can:imu.Ax".into()),
                    latitude: Some("can:pos.Lat".into()),
                    ..Default::default()
                },
                "`latitude` is a GNSS fix's",
            ),
        ];
        for (topic, s, says) in cases {
            let e = bad(topic, s);
            assert!(e.contains(says), "{topic}: {e}");
        }
    }
}
