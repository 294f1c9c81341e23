//! railfuse's messages in protobuf, MCAP's `protobuf` profile: the types are generated with
//! prost from proto/railfuse/*.proto, and the FileDescriptorSet of those files is what a
//! protobuf channel's schema record holds, so any protobuf reader (mcap-protobuf-support,
//! Foxglove) decodes the channel without railfuse. A channel's schema name is the message's
//! full name, `railfuse.<Type>`: the same as its JSON form's.
//!
//! A catalogue type with a protobuf form implements [`ProtobufForm`] and is marked in the
//! registry; [`crate::log::LogMessage::decode`] and the log writer pick the encoding from the
//! channel.

use std::collections::HashMap;
use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::OnceLock;

use prost::Message;
use prost_types::FileDescriptorSet;

mod wire;
pub use wire::Wire;
pub(crate) use wire::{protobuf_enum, protobuf_form};

/// The prost types generated from proto/railfuse/.
pub mod types {
    include!(concat!(env!("OUT_DIR"), "/railfuse.rs"));
}

/// The FileDescriptorSet of proto/railfuse/ (encoded).
pub const DESCRIPTORS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/railfuse.fds"));

/// The prost types of proto/foxglove/: the fields of Foxglove's schemas railfuse writes its
/// twins in ([`crate::foxglove`]).
pub mod foxglove_types {
    include!(concat!(env!("OUT_DIR"), "/foxglove.rs"));
}

/// The FileDescriptorSet of proto/foxglove/ (with google/protobuf/timestamp.proto).
pub const FOXGLOVE_DESCRIPTORS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/foxglove.fds"));

/// The schema data of a protobuf channel whose messages are `message` (a full name,
/// `railfuse.GnssFix`, `foxglove.LocationFix`): the FileDescriptorSet of the .proto file
/// that defines it and of the files that file imports, nothing else (all of railfuse's
/// files would be 32 KiB in every schema record).
pub fn schema_data(message: &str) -> &'static [u8] {
    static SETS: OnceLock<HashMap<String, Vec<u8>>> = OnceLock::new();
    let sets = SETS.get_or_init(|| {
        let mut sets = HashMap::new();
        for all in [DESCRIPTORS, FOXGLOVE_DESCRIPTORS] {
            let all = FileDescriptorSet::decode(all).expect("build.rs encoded the set");
            for file in &all.file {
                for m in &file.message_type {
                    let name = format!("{}.{}", file.package(), m.name());
                    sets.insert(name, files_for(&all, file.name()).encode_to_vec());
                }
            }
        }
        sets
    });
    sets.get(message)
        .unwrap_or_else(|| panic!("{message} is one of railfuse's protobuf messages"))
}

/// The file `name` of `all` and every file it imports, imports first.
fn files_for(all: &FileDescriptorSet, name: &str) -> FileDescriptorSet {
    let mut set = FileDescriptorSet::default();
    let mut wanted = vec![name.to_owned()];
    while let Some(name) = wanted.pop() {
        if set.file.iter().any(|f| f.name() == name) {
            continue;
        }
        let file = all.file.iter().find(|f| f.name() == name);
        let file = file.expect("protox includes every imported file");
        wanted.extend(file.dependency.iter().cloned());
        set.file.insert(0, file.clone());
    }
    set
}

/// How a channel's messages are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// JSON, with the type's JSON schema: railfuse's first encoding, which older logs have.
    Json,
    /// Protobuf, with railfuse's FileDescriptorSet: the default, a third of JSON's size
    /// and several times faster to write and read.
    #[default]
    Protobuf,
}

impl Encoding {
    /// The MCAP channel's `message_encoding`.
    pub fn message_encoding(self) -> &'static str {
        match self {
            Encoding::Json => "json",
            Encoding::Protobuf => "protobuf",
        }
    }

    /// The MCAP schema record's `encoding`.
    pub fn schema_encoding(self) -> &'static str {
        match self {
            Encoding::Json => "jsonschema",
            Encoding::Protobuf => "protobuf",
        }
    }

    /// The encoding a channel's `message_encoding` names, if railfuse writes it.
    pub fn of_channel(message_encoding: &str) -> Option<Self> {
        match message_encoding {
            "json" => Some(Encoding::Json),
            "protobuf" => Some(Encoding::Protobuf),
            _ => None,
        }
    }
}

impl FromStr for Encoding {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::of_channel(s).ok_or_else(|| format!("unknown encoding '{s}' (json or protobuf)"))
    }
}

/// The encoding of every writer this process opens from now on (0 protobuf, 1 JSON).
static ENCODING: AtomicU8 = AtomicU8::new(0);

/// Sets the encoding of every writer this process opens from now on: the CLI's `--encoding`.
pub fn set_encoding_by_default(encoding: Encoding) {
    let code = match encoding {
        Encoding::Protobuf => 0,
        Encoding::Json => 1,
    };
    ENCODING.store(code, Ordering::Relaxed);
}

/// The encoding writers take unless told otherwise.
pub fn encoding_by_default() -> Encoding {
    match ENCODING.load(Ordering::Relaxed) {
        1 => Encoding::Json,
        _ => Encoding::Protobuf,
    }
}

/// A catalogue type's protobuf form: the prost message it travels as, both ways.
pub trait ProtobufForm: Sized {
    type Message: Message + Default;
    fn to_protobuf(&self) -> Self::Message;
    /// The catalogue message, or why the protobuf message is not a valid one.
    fn from_protobuf(m: Self::Message) -> Result<Self, String>;
}

/// A repeated field that must hold exactly `N` values (a fixed-size array of the type).
pub fn fixed<const N: usize>(values: Vec<f64>, field: &str) -> Result<[f64; N], String> {
    let n = values.len();
    values
        .try_into()
        .map_err(|_| format!("{field} has {n} values, not {N}"))
}

/// A repeated field that holds `N` values or none (an optional fixed-size array).
pub fn optional_fixed<const N: usize>(
    values: Vec<f64>,
    field: &str,
) -> Result<Option<[f64; N]>, String> {
    match values.is_empty() {
        true => Ok(None),
        false => fixed(values, field).map(Some),
    }
}

/// Each value as a whole number of `step`s, if every one is exactly `exact(count × step)`
/// with |count| ≤ `max`: what makes counts a lossless form of a sensor's values (an ADC's,
/// an IMU's), and a smaller one.
pub fn whole_steps<T: Copy + PartialEq + Into<f64>>(
    values: &[T],
    step: f64,
    max: f64,
    exact: impl Fn(f64) -> T,
) -> Option<Vec<i32>> {
    values
        .iter()
        .map(|&v| {
            let c = (v.into() / step).round();
            (c.abs() <= max && exact(c * step) == v).then_some(c as i32)
        })
        .collect()
}

/// `m` encoded as protobuf, appended to `buf`.
pub fn encode<M: ProtobufForm>(m: &M, buf: &mut Vec<u8>) {
    m.to_protobuf()
        .encode(buf)
        .expect("a Vec has room for any message");
}

/// A protobuf payload decoded as `M`.
pub fn decode<M: ProtobufForm>(data: &[u8]) -> Result<M, String> {
    let m = M::Message::decode(data).map_err(|e| e.to_string())?;
    M::from_protobuf(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::{LogReader, LogRecord, LogWriter, WriterOptions};
    use crate::messages::{ChannelMessage, EddyCurrentBlock, MessageKind};

    fn block(samples: Vec<f32>, volts_per_count: Option<f64>) -> EddyCurrentBlock {
        EddyCurrentBlock {
            stamp_ns: 1_780_000_000_000_000_000,
            sample_rate_hz: 10_000.0,
            spacing_m: 0.3,
            sensor_b: samples.iter().map(|v| -v).collect(),
            sensor_a: samples,
            volts_per_count,
        }
    }

    #[test]
    fn every_kind_round_trips_through_its_protobuf_form() {
        for &kind in MessageKind::ALL {
            let m = kind.example();
            let data = m.to_protobuf();
            assert_eq!(kind.decode_protobuf(&data).unwrap(), m, "{kind:?}");
        }
    }

    #[test]
    fn samples_on_the_converter_grid_travel_as_counts_and_others_as_volts_losslessly() {
        let step = 0.0005;
        let on_grid: Vec<f32> = (-2000..2000).map(|c| (c as f64 * step) as f32).collect();
        let b = block(on_grid, Some(step));
        let m = b.to_protobuf();
        assert_eq!(m.counts_i16.len(), 2 * 2 * 4000);
        assert!(m.sensor_a.is_empty());
        // Byte-planed: the low bytes of every count first. Count −2000 is 0xF830.
        assert_eq!((m.counts_i16[0], m.counts_i16[8000]), (0x30, 0xF8));
        let mut counts = Vec::new();
        encode(&b, &mut counts);
        assert_eq!(decode::<EddyCurrentBlock>(&counts).unwrap(), b);
        // Two bytes a count, against four for a float.
        assert!(counts.len() < 2 * 2 * 4000 + 64, "{} bytes", counts.len());
        // One sample off the grid: the block travels in volts, still exactly.
        let mut off = b.clone();
        off.sensor_b[7] += 1e-5;
        let m = off.to_protobuf();
        assert!(m.counts_i16.is_empty() && m.sensor_b.len() == 4000);
        // Beyond 16 bits: volts too.
        let loud = block(vec![40_000.0 * step as f32], Some(step));
        assert!(loud.to_protobuf().counts_i16.is_empty());
        let mut data = Vec::new();
        encode(&loud, &mut data);
        assert_eq!(decode::<EddyCurrentBlock>(&data).unwrap(), loud);
        let mut volts = Vec::new();
        encode(&off, &mut volts);
        assert_eq!(decode::<EddyCurrentBlock>(&volts).unwrap(), off);
        // No step: volts, and none invented on the way back.
        let plain = block(vec![0.123, -0.456], None);
        let mut data = Vec::new();
        encode(&plain, &mut data);
        assert_eq!(decode::<EddyCurrentBlock>(&data).unwrap(), plain);
    }

    #[test]
    fn imu_values_in_whole_steps_travel_as_counts_and_come_back_to_the_bit() {
        use crate::messages::Imu;
        let (accel, gyro) = (0.061e-3 * 9.80665, 4.37e-3_f64.to_radians());
        let q = |x: f64, lsb: f64| (x / lsb).round() * lsb;
        let imu = Imu {
            stamp_ns: 5,
            sensor_id: "imu0".into(),
            specific_force_mps2: [0.31, -0.02, 9.81].map(|x| q(x, accel)),
            angular_rate_radps: [0.0, 0.001, -0.02].map(|x| q(x, gyro)),
            accel_lsb_mps2: Some(accel),
            gyro_lsb_radps: Some(gyro),
        };
        let m = imu.to_protobuf();
        assert_eq!(m.specific_force_counts.len(), 3);
        assert!(m.specific_force_mps2.is_empty() && m.angular_rate_radps.is_empty());
        let mut data = Vec::new();
        encode(&imu, &mut data);
        assert_eq!(decode::<Imu>(&data).unwrap(), imu);
        // Counts of at most 3 bytes and the steps, against six doubles.
        assert!(data.len() < 48, "{} bytes", data.len());
        // A value off the grid: that sensor's values go as doubles, still exactly.
        let mut off = imu.clone();
        off.specific_force_mps2[1] += 1e-9;
        assert!(off.to_protobuf().specific_force_counts.is_empty());
        let mut data = Vec::new();
        encode(&off, &mut data);
        assert_eq!(decode::<Imu>(&data).unwrap(), off);
    }

    #[test]
    fn counts_without_a_step_and_damaged_bytes_are_errors_not_samples() {
        let mut m = block(vec![0.0005], Some(0.0005)).to_protobuf();
        m.volts_per_count = 0.0;
        let bad = m.encode_to_vec();
        assert!(decode::<EddyCurrentBlock>(&bad)
            .unwrap_err()
            .contains("volts_per_count"));
        assert!(decode::<EddyCurrentBlock>(&[0x2a, 0xff, 0xff]).is_err());
        // Counts of two sensors are a multiple of four bytes.
        let mut odd = block(vec![0.0005], Some(0.0005)).to_protobuf();
        odd.counts_i16.pop();
        let odd = odd.encode_to_vec();
        assert!(decode::<EddyCurrentBlock>(&odd)
            .unwrap_err()
            .contains("counts_i16"));
    }

    #[test]
    fn a_protobuf_channel_is_written_with_the_descriptors_and_read_back_by_every_decoder() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("p.mcap");
        let options = WriterOptions {
            encoding: Encoding::Protobuf,
            ..WriterOptions::default()
        };
        let mut w = LogWriter::create_with(&path, &options).unwrap();
        let c = w
            .add_channel::<EddyCurrentBlock>("/eddy_current/block")
            .unwrap();
        let b = block(vec![0.001, -0.0015, 0.0], Some(0.0005));
        w.write(c, b.stamp_ns, &b).unwrap();
        w.finish().unwrap();
        let mut r = LogReader::open(&path).unwrap();
        let mut seen = 0;
        while let Some(rec) = r.next() {
            if let LogRecord::Message(m) = rec.unwrap() {
                assert_eq!(m.channel.message_encoding, "protobuf");
                let schema = m.channel.schema.as_ref().unwrap();
                assert_eq!(
                    (schema.name.as_str(), schema.encoding.as_str()),
                    (EddyCurrentBlock::SCHEMA_NAME, "protobuf")
                );
                assert_eq!(
                    schema.data.as_slice(),
                    schema_data(EddyCurrentBlock::SCHEMA_NAME)
                );
                assert_eq!(m.decode::<EddyCurrentBlock>(&path).unwrap(), b);
                assert_eq!(m.decode_any(&path).unwrap(), Some(b.clone().into()));
                seen += 1;
            }
        }
        assert_eq!(seen, 1);
    }
}
