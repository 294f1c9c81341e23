//! railfuse's messages in protobuf, MCAP's `protobuf` profile: the types are generated with
//! prost from proto/railfuse/*.proto, and the FileDescriptorSet of those files is what a
//! protobuf channel's schema record holds, so any protobuf reader (mcap-protobuf-support,
//! Foxglove) decodes the channel without railfuse. A channel's schema name is the message's
//! full name, `railfuse.<Type>`: the same as its JSON form's.
//!
//! A catalogue type with a protobuf form implements [`ProtobufForm`] and is marked in the
//! registry; [`crate::log::LogMessage::decode`] and the log writer pick the encoding from the
//! channel.

use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};

use prost::Message;

use crate::messages::MessageKind;

/// The prost types generated from proto/railfuse/.
pub mod types {
    include!(concat!(env!("OUT_DIR"), "/railfuse.rs"));
}

/// The FileDescriptorSet of proto/railfuse/ (encoded): every protobuf channel's schema data.
pub const DESCRIPTORS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/railfuse.fds"));

/// How a channel's messages are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// JSON, with the type's JSON schema (railfuse's first encoding; every type has it).
    #[default]
    Json,
    /// Protobuf, with railfuse's FileDescriptorSet, for the types that have a protobuf form.
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

/// Which encoding a writer gives each channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EncodingPolicy {
    /// Protobuf for the bulk data ([`PROTOBUF_BY_DEFAULT`]), JSON for the rest.
    #[default]
    Default,
    /// This encoding for every type that has it (JSON for a type without a protobuf form).
    Only(Encoding),
}

/// The kinds written in protobuf unless told otherwise: the eddy-current blocks, which are
/// most of a log's bytes in JSON (10 kHz samples as decimal text).
pub const PROTOBUF_BY_DEFAULT: &[MessageKind] = &[MessageKind::EddyCurrentBlock];

impl EncodingPolicy {
    /// The encoding of a channel of `kind`.
    pub fn for_kind(self, kind: MessageKind) -> Encoding {
        let wanted = match self {
            EncodingPolicy::Only(e) => e,
            EncodingPolicy::Default if PROTOBUF_BY_DEFAULT.contains(&kind) => Encoding::Protobuf,
            EncodingPolicy::Default => Encoding::Json,
        };
        match kind.has_protobuf() {
            true => wanted,
            false => Encoding::Json,
        }
    }
}

/// The policy of every writer this process opens from now on (0 default, 1 JSON, 2 protobuf).
static POLICY: AtomicU8 = AtomicU8::new(0);

/// Sets the policy of every writer this process opens from now on: the CLI's `--encoding`.
pub fn set_policy_by_default(policy: EncodingPolicy) {
    let code = match policy {
        EncodingPolicy::Default => 0,
        EncodingPolicy::Only(Encoding::Json) => 1,
        EncodingPolicy::Only(Encoding::Protobuf) => 2,
    };
    POLICY.store(code, Ordering::Relaxed);
}

/// The policy writers take unless told otherwise.
pub fn policy_by_default() -> EncodingPolicy {
    match POLICY.load(Ordering::Relaxed) {
        1 => EncodingPolicy::Only(Encoding::Json),
        2 => EncodingPolicy::Only(Encoding::Protobuf),
        _ => EncodingPolicy::Default,
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
    use crate::messages::{ChannelMessage, EddyCurrentBlock};

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
    fn every_kind_with_a_protobuf_form_round_trips_through_it() {
        for &kind in MessageKind::ALL.iter().filter(|k| k.has_protobuf()) {
            let m = kind.example();
            let data = m.to_protobuf().expect("a protobuf form");
            assert_eq!(kind.decode_protobuf(&data).unwrap().unwrap(), m, "{kind:?}");
        }
        assert!(MessageKind::EddyCurrentBlock.has_protobuf());
    }

    #[test]
    fn samples_on_the_converter_grid_travel_as_counts_and_others_as_volts_losslessly() {
        let step = 0.0005;
        let on_grid: Vec<f32> = (-2000..2000).map(|c| (c as f64 * step) as f32).collect();
        let b = block(on_grid, Some(step));
        let m = b.to_protobuf();
        assert_eq!(m.sensor_a_counts.len(), 4000);
        assert!(m.sensor_a.is_empty());
        let mut counts = Vec::new();
        encode(&b, &mut counts);
        assert_eq!(decode::<EddyCurrentBlock>(&counts).unwrap(), b);
        // Counts of at most ±2000 take two bytes each, against four for a float.
        assert!(counts.len() < 2 * 2 * 4000 + 64, "{} bytes", counts.len());
        // One sample off the grid: the block travels in volts, still exactly.
        let mut off = b.clone();
        off.sensor_b[7] += 1e-5;
        let m = off.to_protobuf();
        assert!(m.sensor_a_counts.is_empty() && m.sensor_b.len() == 4000);
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
    fn counts_without_a_step_and_damaged_bytes_are_errors_not_samples() {
        let mut m = block(vec![0.0005], Some(0.0005)).to_protobuf();
        m.volts_per_count = 0.0;
        let bad = m.encode_to_vec();
        assert!(decode::<EddyCurrentBlock>(&bad)
            .unwrap_err()
            .contains("volts_per_count"));
        assert!(decode::<EddyCurrentBlock>(&[0x2a, 0xff, 0xff]).is_err());
    }

    #[test]
    fn a_protobuf_channel_is_written_with_the_descriptors_and_read_back_by_every_decoder() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("p.mcap");
        let options = WriterOptions {
            encoding: EncodingPolicy::Only(Encoding::Protobuf),
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
                assert_eq!(schema.data.as_slice(), DESCRIPTORS);
                assert_eq!(m.decode::<EddyCurrentBlock>(&path).unwrap(), b);
                assert_eq!(m.decode_any(&path).unwrap(), Some(b.clone().into()));
                #[derive(serde::Deserialize)]
                struct Stamp {
                    stamp_ns: u64,
                }
                assert_eq!(
                    m.decode_fields::<Stamp>(&path).unwrap().stamp_ns,
                    b.stamp_ns
                );
                seen += 1;
            }
        }
        assert_eq!(seen, 1);
    }
}
