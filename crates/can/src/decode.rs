//! A frame's signals in their units.
//!
//! Bits are numbered as DBC files number them ([`bit_positions`]). The raw value is signed
//! by two's complement where the DBC says `-`, or an IEEE float or double where
//! `SIG_VALTYPE_` says so; the physical value is `raw · factor + offset`.

use crate::dbc::{bit_positions, Database, Encoding, Message, Signal};
use crate::frame::Frame;

/// One decoded signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Value {
    pub name: String,
    pub value: f64,
    pub unit: String,
    /// The value table's name for the raw value, where it has one.
    pub label: Option<String>,
    /// Outside the range the DBC declares: kept, and said so.
    pub out_of_range: bool,
}

/// What a frame decodes to.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded<'a> {
    Signals {
        message: &'a Message,
        values: Vec<Value>,
    },
    /// No message with the frame's id in the DBC: the frame stays raw.
    Unknown,
    /// Shorter than the message: its signals cannot all be read.
    TooShort { message: &'a Message },
}

impl Database {
    /// The signals of `frame` (a remote request or an error frame has none).
    pub fn decode(&self, frame: &Frame) -> Decoded<'_> {
        if frame.rtr || frame.error {
            return Decoded::Unknown;
        }
        let Some(message) = self.messages.get(&(frame.id, frame.extended)) else {
            return Decoded::Unknown;
        };
        if frame.data.len() < message.size {
            return Decoded::TooShort { message };
        }
        let mux = message
            .signals
            .iter()
            .find(|s| s.is_multiplexor && s.multiplexed_by.is_none())
            .map(|s| raw_bits(&frame.data, s));
        let values = message
            .signals
            .iter()
            .filter(|s| s.multiplexed_by.is_none_or(|v| mux == Some(v)))
            .map(|s| value(&frame.data, s))
            .collect();
        Decoded::Signals { message, values }
    }
}

/// The signal's physical value from `data`.
fn value(data: &[u8], s: &Signal) -> Value {
    let bits = raw_bits(data, s);
    let (raw, label_key) = match s.encoding {
        Encoding::Unsigned => (bits as f64, Some(bits as i64)),
        Encoding::Signed => {
            let shift = 64 - s.size;
            let signed = ((bits << shift) as i64) >> shift;
            (signed as f64, Some(signed))
        }
        Encoding::Float32 => (f64::from(f32::from_bits(bits as u32)), None),
        Encoding::Float64 => (f64::from_bits(bits), None),
    };
    let value = raw * s.factor + s.offset;
    Value {
        name: s.name.clone(),
        value,
        unit: s.unit.clone(),
        label: label_key.and_then(|k| s.labels.get(&k).cloned()),
        out_of_range: s.range.is_some_and(|(lo, hi)| {
            !(value >= lo - 1e-9 * lo.abs().max(1.0) && value <= hi + 1e-9 * hi.abs().max(1.0))
        }),
    }
}

/// The signal's raw bits, most significant first assembled into a u64.
fn raw_bits(data: &[u8], s: &Signal) -> u64 {
    let positions = bit_positions(s.start_bit, s.size, s.little_endian);
    // `positions` runs from the least significant bit (Intel) or the most (Motorola).
    let bit = |p: u32| u64::from((data[(p / 8) as usize] >> (p % 8)) & 1);
    match s.little_endian {
        true => positions
            .iter()
            .enumerate()
            .fold(0, |v, (i, &p)| v | (bit(p) << i)),
        false => positions.iter().fold(0, |v, &p| (v << 1) | bit(p)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DBC: &str = r#"VERSION ""

NS_ :

BS_:

BU_: Brake Traction

BO_ 256 WheelSpeed: 8 Traction
 SG_ AxleSpeed1 : 0|16@1+ (0.01,0) [0|150] "m/s" Brake
 SG_ AxleSpeed2 : 23|16@0+ (0.01,0) [0|150] "m/s" Brake
 SG_ Accel : 39|12@0- (0.001,0) [-2|2] "m/s2" Brake
 SG_ Direction : 52|2@1+ (1,0) [0|3] "" Brake

BO_ 2147484672 Radar: 8 Traction
 SG_ Mode M : 0|4@1+ (1,0) [0|0] "" Brake
 SG_ Speed m1 : 8|32@1- (1,0) [0|0] "m/s" Brake
 SG_ Distance m2 : 8|32@1+ (0.5,-100) [0|1000] "m" Brake

VAL_ 256 Direction 0 "standstill" 1 "forward" 2 "backward" 3 "invalid" ;

SIG_VALTYPE_ 2147484672 Speed : 1;
"#;

    fn frame(id: u32, extended: bool, data: &[u8]) -> Frame {
        Frame {
            stamp_ns: 0,
            bus: "can0".into(),
            id,
            extended,
            rtr: false,
            error: false,
            fd: false,
            brs: false,
            esi: false,
            data: data.to_vec(),
        }
    }

    fn values(db: &Database, f: &Frame) -> Vec<Value> {
        match db.decode(f) {
            Decoded::Signals { values, .. } => values,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn intel_motorola_signed_floats_multiplexed_and_labelled_signals_decode() {
        let db = Database::parse("t.dbc", DBC).unwrap();
        // AxleSpeed1 = 0x0BB8 (30.00 m/s, Intel); AxleSpeed2 = 0x0BB9 Motorola from bit 23
        // (byte 2 then byte 3); Accel = -1 (12 bits Motorola from bit 39: byte 4, half of
        // byte 5) = -0.001; Direction = 1 at bits 52-53 (byte 6).
        let f = frame(
            256,
            false,
            &[0xB8, 0x0B, 0x0B, 0xB9, 0xFF, 0xF0, 0x10, 0x00],
        );
        let v = values(&db, &f);
        let get = |n: &str| v.iter().find(|x| x.name == n).unwrap().clone();
        assert!((get("AxleSpeed1").value - 30.00).abs() < 1e-9);
        assert!((get("AxleSpeed2").value - 30.01).abs() < 1e-9);
        assert!((get("Accel").value + 0.001).abs() < 1e-12);
        assert_eq!(get("Direction").label.as_deref(), Some("forward"));
        assert_eq!(get("AxleSpeed1").unit, "m/s");
        // Mode 1: Speed, an IEEE float; Mode 2: Distance instead.
        let mut data = vec![1, 0, 0, 0, 0, 0, 0, 0];
        data[1..5].copy_from_slice(&12.5f32.to_bits().to_le_bytes());
        let v = values(&db, &frame(0x400, true, &data));
        assert_eq!(v.len(), 2);
        assert_eq!(v[1].name, "Speed");
        assert!((v[1].value - 12.5).abs() < 1e-9);
        data[0] = 2;
        data[1..5].copy_from_slice(&3000u32.to_le_bytes());
        let v = values(&db, &frame(0x400, true, &data));
        assert_eq!((v[1].name.as_str(), v[1].value), ("Distance", 1400.0));
        // Out of its range (1400 > 1000): kept, flagged.
        assert!(v[1].out_of_range);
        assert_eq!(db.decode(&frame(0x200, false, &[0; 8])), Decoded::Unknown);
        assert!(matches!(
            db.decode(&frame(256, false, &[0; 4])),
            Decoded::TooShort { .. }
        ));
    }

    #[test]
    fn a_signal_past_its_frame_and_a_broken_line_are_named_by_line() {
        let past = DBC.replace("SG_ Direction : 52|2@1+", "SG_ Direction : 63|2@1+");
        let e = Database::parse("v.dbc", &past).unwrap_err().to_string();
        assert!(
            e.starts_with("v.dbc:13: WheelSpeed Direction: its 2 bits from bit 63"),
            "{e}"
        );
        let twice = DBC.replace("BO_ 2147484672 Radar", "BO_ 256 Radar");
        let e = Database::parse("v.dbc", &twice).unwrap_err().to_string();
        assert_eq!(e, "v.dbc:15: a second message with id 0x100");
        let broken = DBC.replace("SG_ Accel : 39|12@0-", "SG_ Accel : 39|12@0x");
        let e = Database::parse("v.dbc", &broken).unwrap_err().to_string();
        assert!(e.starts_with("v.dbc:"), "{e}");
    }
}
