//! A message's signals packed into a frame's payload: what a sensor on the bus sends, and what
//! the simulator sends in its place.
//!
//! The inverse of [`decode`](crate::decode): the raw value is `(value − offset) / factor`
//! rounded to the nearest integer and held to the bits the signal has (a value past them is
//! clipped to the nearest it can say, as a sensor's firmware saturates), then laid out bit by
//! bit in [`bit_positions`] order.

use crate::dbc::{bit_positions, Encoding, Message, Signal};

impl Message {
    /// The payload carrying `values` (by signal name); a signal not given is 0, and a
    /// multiplexed signal is packed only when `values` sets its multiplexor to its value.
    pub fn encode(&self, values: &[(&str, f64)]) -> Vec<u8> {
        let mut data = vec![0u8; self.size];
        let given = |name: &str| values.iter().find(|(n, _)| *n == name).map(|&(_, v)| v);
        let mux = self
            .signals
            .iter()
            .find(|s| s.is_multiplexor && s.multiplexed_by.is_none())
            .and_then(|s| given(&s.name))
            .map(|v| v.round() as u64);
        for s in &self.signals {
            if s.multiplexed_by.is_some_and(|m| Some(m) != mux) {
                continue;
            }
            if let Some(v) = given(&s.name) {
                put_bits(&mut data, s, raw_bits(s, v));
            }
        }
        data
    }
}

/// The signal's raw bits for the physical value `value`.
fn raw_bits(s: &Signal, value: f64) -> u64 {
    let raw = (value - s.offset) / s.factor;
    let mask = if s.size >= 64 {
        u64::MAX
    } else {
        (1u64 << s.size) - 1
    };
    match s.encoding {
        Encoding::Float32 => u64::from((raw as f32).to_bits()),
        Encoding::Float64 => raw.to_bits(),
        Encoding::Unsigned => {
            let max = mask as f64;
            (raw.round().clamp(0.0, max) as u64) & mask
        }
        Encoding::Signed => {
            let half = (1u64 << (s.size - 1)) as f64;
            let r = raw.round().clamp(-half, half - 1.0) as i64;
            (r as u64) & mask
        }
    }
}

/// Lays `bits` (most significant first for Motorola, least for Intel, as they are read) into
/// `data`.
fn put_bits(data: &mut [u8], s: &Signal, bits: u64) {
    let positions = bit_positions(s.start_bit, s.size, s.little_endian);
    let n = positions.len();
    for (i, &p) in positions.iter().enumerate() {
        // Intel reads bit i as the value's bit i; Motorola reads the most significant first.
        let bit = match s.little_endian {
            true => (bits >> i) & 1,
            false => (bits >> (n - 1 - i)) & 1,
        };
        let (byte, shift) = ((p / 8) as usize, p % 8);
        data[byte] = (data[byte] & !(1 << shift)) | ((bit as u8) << shift);
    }
}

#[cfg(test)]
mod tests {
    use crate::dbc::Database;
    use crate::decode::Decoded;
    use crate::frame::Frame;

    const DBC: &str = include_str!("../../../samples/vehicle.dbc");

    fn decode(db: &Database, id: u32, extended: bool, data: Vec<u8>) -> Vec<(String, f64)> {
        let frame = Frame {
            stamp_ns: 0,
            bus: "can0".into(),
            id,
            extended,
            rtr: false,
            error: false,
            fd: false,
            brs: false,
            esi: false,
            data,
        };
        match db.decode(&frame) {
            Decoded::Signals { values, .. } => {
                values.into_iter().map(|v| (v.name, v.value)).collect()
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn every_kind_of_signal_decodes_to_what_was_encoded() {
        let db = Database::parse("vehicle.dbc", DBC).unwrap();
        let by_name = |n: &str| db.messages.values().find(|m| m.name == n).unwrap();
        // Intel unsigned and Motorola signed, a bit flag and Motorola 32-bit counters.
        let radar = by_name("RadarSpeed");
        let data = radar.encode(&[
            ("GroundSpeed", -12.345),
            ("Quality", 87.5),
            ("Valid", 1.0),
            ("Acceleration", 0.5),
        ]);
        let got = decode(&db, radar.id, false, data);
        assert_eq!(got[0], ("GroundSpeed".into(), -12.345));
        assert_eq!(got[1], ("Quality".into(), 87.5));
        assert_eq!(got[2], ("Valid".into(), 1.0));
        assert!((got[3].1 - 0.5).abs() < 1e-12);
        let pulses = by_name("AxlePulses");
        let data = pulses.encode(&[("PulseCount1", 4_000_000_123.0), ("PulseCount2", 7.0)]);
        let got = decode(&db, pulses.id, false, data);
        assert_eq!(
            got,
            [
                ("PulseCount1".into(), 4_000_000_123.0),
                ("PulseCount2".into(), 7.0)
            ]
        );
        // Multiplexed on a 29-bit id, IEEE float and double.
        let brake = by_name("BrakeStatus");
        let data = brake.encode(&[
            ("Mux", 2.0),
            ("BrakeTemperature", 81.25),
            ("DoorState", 3.0),
        ]);
        let got = decode(&db, brake.id, true, data);
        assert_eq!(
            got,
            [("Mux".into(), 2.0), ("BrakeTemperature".into(), 81.25)]
        );
        let time = by_name("GatewayTime");
        let got = decode(
            &db,
            time.id,
            false,
            time.encode(&[("Uptime", 1234.000_001)]),
        );
        assert_eq!(got, [("Uptime".into(), 1234.000_001)]);
        // Past its bits: saturated, as a sensor's firmware does.
        let wheel = by_name("WheelSpeed");
        let got = decode(&db, wheel.id, false, wheel.encode(&[("AxleSpeed1", 900.0)]));
        assert_eq!(got[0], ("AxleSpeed1".into(), 655.35));
    }
}
