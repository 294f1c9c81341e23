//! The `[can]` and `[sensor."<topic>"]` tables of a configuration, checked against the DBC,
//! and the bridge that makes the sensors' messages from frames.

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_can::dbc::{BusDbcs, Database, Encoding, Signal};
use railfuse_can::decode::{Decoded, Value};
use serde::Serialize;

use super::assembled::{Latest, MessageKey};
use super::pulse_counter::{NoReading, PulseCounter};
use super::sensor::{find_signal, Mapped, Reading, SignalRef};
pub use super::settings::{CanBuses, CanSettings, MappingError, SensorSource};
use crate::messages::{AnyMessage, CanFrame, MessageKind, Odometer, RadarSpeed};

/// What the bridge has seen, for the report.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BridgeCounts {
    /// Sensor messages made, by topic.
    pub made: BTreeMap<String, u64>,
    /// Frames no DBC message has (kept raw), by bus and id (`can0 0x7FF`).
    pub unknown_ids: BTreeMap<String, u64>,
    /// Frames shorter than their message, by message.
    pub too_short: BTreeMap<String, u64>,
    /// Mapped signals out of their declared range (left out: no reading), by message.signal.
    pub out_of_range: BTreeMap<String, u64>,
    /// Mapped values that are not finite numbers (left out), by message.signal.
    pub not_finite: BTreeMap<String, u64>,
    /// Pulse counts that jumped as no wheel turns (a counter restarted; counting starts
    /// anew), by message.signal.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub counter_restarts: BTreeMap<String, u64>,
    /// Other values that made no reading (a fix type `fix_types` does not name), by cause.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub other: BTreeMap<String, u64>,
}

/// The vehicle's DBCs (one a bus, or one for every bus) and the sensors mapped from their
/// signals.
pub struct SensorBridge {
    dbs: BusDbcs,
    mapped: Vec<Mapped>,
    pub counts: BridgeCounts,
}

/// A speed unit's factor to m/s.
fn speed_scale(unit: &str) -> Option<f64> {
    match unit.trim().to_ascii_lowercase().as_str() {
        "m/s" | "mps" | "m/sec" => Some(1.0),
        "km/h" | "kph" | "kmh" | "km/hr" => Some(1.0 / 3.6),
        "mph" => Some(0.447_04),
        _ => None,
    }
}

impl SensorBridge {
    /// The bridge of `settings` (its DBC relative to `base`) for the sensors of `sensors`.
    pub fn new(
        settings: &CanSettings,
        base: &Path,
        sensors: &BTreeMap<String, SensorSource>,
    ) -> Result<Self, MappingError> {
        let db = Database::open(&base.join(&settings.dbc))?;
        Self::with_database(db, settings.bus.clone(), sensors)
    }

    /// The bridge of a DBC already read.
    pub fn with_database(
        db: Database,
        bus: Option<String>,
        sensors: &BTreeMap<String, SensorSource>,
    ) -> Result<Self, MappingError> {
        Self::with_databases(BusDbcs(vec![(bus, std::sync::Arc::new(db))]), sensors)
    }

    /// The bridge of DBCs already read, each of its bus (`None`: every bus no other names).
    pub fn with_databases(
        dbs: BusDbcs,
        sensors: &BTreeMap<String, SensorSource>,
    ) -> Result<Self, MappingError> {
        let mapped = sensors
            .iter()
            .map(|(topic, source)| map_sensor(&dbs, topic, source))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            dbs,
            mapped,
            counts: BridgeCounts::default(),
        })
    }

    /// The topics the bridge makes, with their kinds.
    pub fn topics(&self) -> impl Iterator<Item = (&str, MessageKind)> {
        self.mapped.iter().map(|m| (m.topic.as_str(), m.kind))
    }

    /// The sensor messages `frame` makes, with their topics (none for most frames).
    pub fn frame(&mut self, frame: &CanFrame) -> Vec<(&str, AnyMessage)> {
        let Some(dbi) = self.dbs.index_of(&frame.bus) else {
            return Vec::new();
        };
        let f = frame.to_frame();
        let (message, values) = match self.dbs.0[dbi].1.decode(&f) {
            Decoded::Signals { message, values } => (message, values),
            Decoded::Unknown => {
                if !f.error && !f.rtr {
                    let key = format!("{} 0x{:X}", f.bus, f.id);
                    *self.counts.unknown_ids.entry(key).or_insert(0) += 1;
                }
                return Vec::new();
            }
            Decoded::TooShort { message } => {
                *self
                    .counts
                    .too_short
                    .entry(message.name.clone())
                    .or_insert(0) += 1;
                return Vec::new();
            }
        };
        let key = (dbi, f.id, f.extended);
        let mut out = Vec::new();
        for m in &mut self.mapped {
            m.latest
                .remember(key, f.stamp_ns, &values, m.reading.assembled());
            if m.message != key {
                continue;
            }
            if let Some(made) = m.make(f.stamp_ns, &message.name, &values, &mut self.counts) {
                *self.counts.made.entry(m.topic.clone()).or_insert(0) += 1;
                out.push((m.topic.as_str(), made));
            }
        }
        out
    }
}

impl Mapped {
    /// The sensor's message from one frame's decoded `values` (of DBC message `name`), or
    /// none (its signal absent, not a number, out of range, or a count with nothing to measure
    /// against), what was left out counted.
    fn make(
        &mut self,
        stamp_ns: u64,
        name: &str,
        values: &[Value],
        counts: &mut BridgeCounts,
    ) -> Option<AnyMessage> {
        match &self.reading {
            Reading::Gnss(g) => return g.make(&self.latest, stamp_ns, &mut counts.other),
            Reading::Imu(i) => return i.make(&self.topic, &self.latest, stamp_ns),
            _ => {}
        }
        let find = |r: &SignalRef| values.iter().find(|v| v.name == r.name);
        // Absent: a multiplexed signal this frame does not carry.
        let v = find(self.reading.signal()?)?;
        let key = format!("{name}.{}", v.name);
        if !v.value.is_finite() {
            *counts.not_finite.entry(key).or_insert(0) += 1;
            return None;
        }
        if v.out_of_range {
            // All ones is CAN's "not available"; past the range is no reading either.
            *counts.out_of_range.entry(key).or_insert(0) += 1;
            return None;
        }
        let read = |r: &Option<SignalRef>| {
            let r = r.as_ref()?;
            Some(find(r)?.value * r.scale).filter(|x| x.is_finite())
        };
        let mut odometer = Odometer {
            stamp_ns,
            sensor_id: self.topic.clone(),
            pulse_count: None,
            pulses_per_revolution: None,
            wheel_diameter_m: None,
            distance_increment_m: None,
            speed_mps: 0.0,
        };
        match (&mut self.reading, self.kind) {
            (Reading::Speed(s), MessageKind::RadarSpeed) => {
                Some(AnyMessage::RadarSpeed(RadarSpeed {
                    stamp_ns,
                    speed_mps: (v.value * s.scale).abs(),
                    quality: read(&self.quality).map_or(1.0, |q| q.clamp(0.0, 1.0)),
                    valid: read(&self.valid).is_none_or(|x| x != 0.0),
                    speed_variance_m2ps2: None,
                }))
            }
            (Reading::Speed(s), _) => {
                odometer.speed_mps = (v.value * s.scale).abs();
                Some(AnyMessage::Odometer(odometer))
            }
            (Reading::Gnss(_) | Reading::Imu(_), _) => None,
            (
                Reading::Pulses {
                    counter,
                    per_revolution,
                    diameter_m,
                    ..
                },
                _,
            ) => {
                let r = match counter.count(stamp_ns, v.value as u64) {
                    Ok(r) => r,
                    Err(NoReading::Restarted) => {
                        *counts.counter_restarts.entry(key).or_insert(0) += 1;
                        return None;
                    }
                    Err(_) => return None,
                };
                odometer.pulse_count = Some(r.total);
                odometer.pulses_per_revolution = Some(*per_revolution);
                odometer.wheel_diameter_m = Some(*diameter_m);
                odometer.distance_increment_m = Some(r.increment_m);
                odometer.speed_mps = r.speed_mps;
                Some(AnyMessage::Odometer(odometer))
            }
        }
    }
}

/// The kind of sensor `topic` is: an odometer, a radar, a GNSS fix or an IMU.
fn sensor_kind(topic: &str) -> Result<MessageKind, MappingError> {
    let cause = match crate::topics::standard_kind(topic) {
        Some(
            k @ (MessageKind::Odometer
            | MessageKind::RadarSpeed
            | MessageKind::GnssFix
            | MessageKind::Imu),
        ) => return Ok(k),
        Some(k) => format!(
            "is a {} channel: CAN signals make odometers, radars, GNSS fixes and IMUs",
            k.type_name()
        ),
        None => "is not a sensor topic CAN signals make (/odometer/1, /odometer/2, \
                 /radar/speed, /gnss/fix, /imu)"
            .into(),
    };
    Err(MappingError::Sensor {
        topic: topic.into(),
        cause,
    })
}

/// The sensor's main signal (a speed, or an axle's pulse count), its message and how it was
/// given.
fn main_reading<'a>(
    db: &BusDbcs,
    topic: &str,
    kind: MessageKind,
    source: &'a SensorSource,
) -> Result<(MessageKey, Reading, &'a str), MappingError> {
    Ok(match (&source.from, &source.pulses) {
        (Some(from), None) => {
            let (message, signal) = find_signal(db, topic, "from", from)?;
            let scale = speed_scale(&signal.unit).ok_or_else(|| MappingError::Signal {
                topic: topic.into(),
                key: "from",
                given: from.clone(),
                cause: format!("is in '{}': a speed is in m/s, km/h or mph", signal.unit),
            })?;
            let speed = SignalRef {
                name: signal.name.clone(),
                scale,
            };
            (message, Reading::Speed(speed), from)
        }
        (None, Some(pulses)) if kind == MessageKind::Odometer => {
            let (message, signal) = find_signal(db, topic, "pulses", pulses)?;
            (
                message,
                pulse_reading(topic, pulses, signal, source)?,
                pulses,
            )
        }
        (None, Some(_)) => {
            return Err(MappingError::Sensor {
                topic: topic.into(),
                cause: "`pulses` makes an odometer; a radar gives its speed in `from`".into(),
            })
        }
        _ => {
            return Err(MappingError::Sensor {
                topic: topic.into(),
                cause: "give one of `from` (a speed signal) or `pulses` (an axle's pulse count)"
                    .into(),
            })
        }
    })
}

/// `topic`'s sensor from `source`, checked against the DBCs.
fn map_sensor(db: &BusDbcs, topic: &str, source: &SensorSource) -> Result<Mapped, MappingError> {
    let kind = sensor_kind(topic)?;
    if matches!(kind, MessageKind::GnssFix | MessageKind::Imu) {
        return super::mapping::assembled_sensor(db, topic, kind, source);
    }
    super::mapping::only_for(topic, kind, source)?;
    if kind == MessageKind::Odometer && (source.valid.is_some() || source.quality.is_some()) {
        return Err(MappingError::Sensor {
            topic: topic.into(),
            cause: "an odometer has no `valid` or `quality`: those are a radar's".into(),
        });
    }
    let (message, reading, main) = main_reading(db, topic, kind, source)?;
    let same_message = |key: &'static str, given: &Option<String>, percent: bool| {
        let Some(given) = given else {
            return Ok(None);
        };
        let (m, signal) = find_signal(db, topic, key, given)?;
        if m != message {
            return Err(MappingError::Signal {
                topic: topic.into(),
                key,
                given: given.clone(),
                cause: format!("is not in the message of `from` ({main})"),
            });
        }
        let scale = if percent && signal.unit.trim() == "%" {
            0.01
        } else {
            1.0
        };
        Ok(Some(SignalRef {
            name: signal.name.clone(),
            scale,
        }))
    };
    let valid = same_message("valid", &source.valid, false)?;
    let quality = same_message("quality", &source.quality, true)?;
    Ok(Mapped {
        topic: topic.to_owned(),
        kind,
        message,
        reading,
        valid,
        quality,
        latest: Latest::default(),
    })
}

/// An odometer read from its axle's pulse count: the signal must be a plain count, and the
/// wheel known.
fn pulse_reading(
    topic: &str,
    given: &str,
    signal: &Signal,
    source: &SensorSource,
) -> Result<Reading, MappingError> {
    let bad = |cause: String| MappingError::Signal {
        topic: topic.into(),
        key: "pulses",
        given: given.into(),
        cause,
    };
    if signal.encoding != Encoding::Unsigned || signal.factor != 1.0 || signal.offset != 0.0 {
        return Err(bad(
            "is not a count: a pulse count is an unsigned signal with factor 1 and offset 0".into(),
        ));
    }
    let sensor = |cause: &str| MappingError::Sensor {
        topic: topic.into(),
        cause: cause.into(),
    };
    let per_revolution = source
        .pulses_per_revolution
        .filter(|&n| n > 0)
        .ok_or_else(|| sensor("`pulses` needs pulses_per_revolution, a positive whole number"))?;
    let diameter_m = source
        .wheel_diameter_m
        .filter(|d| d.is_finite() && (0.1..=3.0).contains(d))
        .ok_or_else(|| sensor("`pulses` needs wheel_diameter_m, 0.1 to 3 m"))?;
    let window_s = source.speed_window_s.unwrap_or(0.2);
    if !(window_s.is_finite() && window_s > 0.0 && window_s <= 10.0) {
        return Err(sensor(
            "speed_window_s is a window of more than 0 and at most 10 s",
        ));
    }
    Ok(Reading::Pulses {
        signal: SignalRef {
            name: signal.name.clone(),
            scale: 1.0,
        },
        counter: PulseCounter::new(signal.size, per_revolution, diameter_m, window_s),
        per_revolution,
        diameter_m,
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::messages::CanData;

    const DBC: &str = r#"VERSION ""

NS_ :

BS_:

BU_: TCU Radar

BO_ 256 WheelSpeed: 4 TCU
 SG_ AxleKmh : 0|16@1+ (0.01,0) [0|400] "km/h" Radar
 SG_ Raw : 16|16@1+ (1,0) [0|100] "rpm" Radar

BO_ 288 RadarSpeed: 4 Radar
 SG_ Speed : 0|16@1- (0.01,0) [-300|300] "m/s" TCU
 SG_ Quality : 16|8@1+ (1,0) [0|100] "%" TCU
 SG_ Valid : 24|1@1+ (1,0) [0|1] "" TCU
"#;

    fn db() -> Database {
        Database::parse("t.dbc", DBC).unwrap()
    }

    fn source(from: &str, valid: Option<&str>, quality: Option<&str>) -> SensorSource {
        SensorSource {
            from: Some(from.into()),
            pulses: None,
            pulses_per_revolution: None,
            wheel_diameter_m: None,
            speed_window_s: None,
            valid: valid.map(Into::into),
            quality: quality.map(Into::into),
            ..Default::default()
        }
    }

    fn pulses(signal: &str, per_revolution: Option<u32>) -> SensorSource {
        SensorSource {
            from: None,
            pulses: Some(signal.into()),
            pulses_per_revolution: per_revolution,
            wheel_diameter_m: Some(0.85),
            ..source("", None, None)
        }
    }

    #[test]
    fn an_axle_s_pulse_count_becomes_an_odometer_with_its_distance_and_speed() {
        let sensors = BTreeMap::from([(
            "/odometer/1".to_owned(),
            pulses("can:WheelSpeed.Raw", Some(200)),
        )]);
        let mut b = SensorBridge::with_database(db(), None, &sensors).unwrap();
        let at = |t: u64, count: u16| CanFrame {
            stamp_ns: t,
            ..frame(256, &[0, 0, count.to_le_bytes()[0], count.to_le_bytes()[1]])
        };
        assert!(
            b.frame(&at(0, 10)).is_empty(),
            "the first count has nothing to measure against"
        );
        let made = b.frame(&at(100_000_000, 60));
        let AnyMessage::Odometer(o) = &made[0].1 else {
            panic!("{made:?}")
        };
        let metres = 50.0 * std::f64::consts::PI * 0.85 / 200.0;
        assert_eq!(o.pulse_count, Some(50));
        assert!((o.distance_increment_m.unwrap() - metres).abs() < 1e-12);
        assert!((o.speed_mps - metres / 0.1).abs() < 1e-9);
        assert_eq!(
            (o.pulses_per_revolution, o.wheel_diameter_m),
            (Some(200), Some(0.85))
        );
    }

    /// A classic frame on can0.
    pub(in crate::foreign::can) fn frame(id: u32, data: &[u8]) -> CanFrame {
        CanFrame {
            stamp_ns: 77,
            receive_ns: 78,
            bus: "can0".into(),
            id,
            extended: false,
            remote: false,
            error: false,
            fd: false,
            brs: false,
            esi: false,
            data: CanData(data.to_vec()),
        }
    }

    #[test]
    fn signals_become_sensors_in_si_units_and_the_radar_s_flags_change_them() {
        let sensors = BTreeMap::from([
            (
                "/odometer/1".to_owned(),
                source("can:WheelSpeed.AxleKmh", None, None),
            ),
            (
                "/radar/speed".to_owned(),
                source(
                    "can:RadarSpeed.Speed",
                    Some("can:RadarSpeed.Valid"),
                    Some("can:RadarSpeed.Quality"),
                ),
            ),
        ]);
        let mut b = SensorBridge::with_database(db(), None, &sensors).unwrap();
        // 72 km/h is 20 m/s.
        let made = b.frame(&frame(256, &7200u16.to_le_bytes().repeat(2)));
        let [(topic, AnyMessage::Odometer(o))] = &made[..] else {
            panic!("{made:?}")
        };
        assert_eq!((*topic, o.stamp_ns), ("/odometer/1", 77));
        assert!((o.speed_mps - 20.0).abs() < 1e-12);
        // Backwards at 12.5 m/s, 80 % quality, valid; then the same with Valid 0.
        let mut data = (-1250i16).to_le_bytes().to_vec();
        data.extend([80, 1]);
        let made = b.frame(&frame(288, &data));
        let AnyMessage::RadarSpeed(r) = &made[0].1 else {
            panic!()
        };
        assert!((r.speed_mps - 12.5).abs() < 1e-12 && (r.quality - 0.8).abs() < 1e-12 && r.valid);
        data[3] = 0;
        let AnyMessage::RadarSpeed(r) = &b.frame(&frame(288, &data))[0].1 else {
            panic!()
        };
        assert!(!r.valid, "Valid 0 is a radar with no measurement");
        // Past its range (all ones: "not available"): no reading, counted.
        assert!(b.frame(&frame(256, &[0xFF, 0xFF, 0, 0])).is_empty());
        assert_eq!(b.counts.out_of_range["WheelSpeed.AxleKmh"], 1);
        assert!(b.frame(&frame(0x7FF, &[1])).is_empty());
        assert_eq!(b.counts.unknown_ids["can0 0x7FF"], 1);
        assert!(b.frame(&frame(256, &[1])).is_empty());
        assert_eq!(b.counts.too_short["WheelSpeed"], 1);
        assert_eq!(b.counts.made["/odometer/1"], 1);
        // Another bus is not read when one is named.
        let mut only = SensorBridge::with_database(db(), Some("can1".into()), &sensors).unwrap();
        assert!(only.frame(&frame(256, &[0, 1, 0, 0])).is_empty());
    }

    #[test]
    fn a_mapping_the_dbc_cannot_give_says_what_and_where() {
        let bad = |topic: &str, s: SensorSource| {
            let sensors = BTreeMap::from([(topic.to_owned(), s)]);
            SensorBridge::with_database(db(), None, &sensors)
                .err()
                .expect("refused")
                .to_string()
        };
        for (topic, s, says) in [
            (
                "/odometer/1",
                source("WheelSpeed.AxleKmh", None, None),
                "\"can:Message.Signal\"",
            ),
            (
                "/odometer/1",
                source("can:Wheel.AxleKmh", None, None),
                "no DBC has a message Wheel",
            ),
            (
                "/odometer/1",
                source("can:WheelSpeed.Raw", None, None),
                "is in 'rpm'",
            ),
            (
                "/odometer/1",
                source("can:WheelSpeed.AxleKmh", Some("can:RadarSpeed.Valid"), None),
                "an odometer has no",
            ),
            (
                "/radar/speed",
                source("can:RadarSpeed.Speed", Some("can:WheelSpeed.Raw"), None),
                "not in the message of `from`",
            ),
            (
                "/gnss/fix",
                source("can:RadarSpeed.Speed", None, None),
                "`from` is an odometer's or a radar's",
            ),
            (
                "/balise",
                source("can:RadarSpeed.Speed", None, None),
                "is a BalisePassage channel",
            ),
            (
                "/wheel",
                source("can:RadarSpeed.Speed", None, None),
                "not a sensor topic CAN signals make",
            ),
        ] {
            let e = bad(topic, s);
            assert!(e.contains(says), "{topic}: {e}");
        }
    }
}
