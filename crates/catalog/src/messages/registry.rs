//! The registry: every message type of the catalogue, declared once. From that one list come
//! each type's [`ChannelMessage`] implementation (schema name `railfuse.<Type>`), the
//! [`MessageKind`] of each type (schema name, JSON schema, decoding from a channel's bytes) and
//! [`AnyMessage`], a message of any type. Recorder sources, importers, the replay, the sensor
//! models and the viewer dispatch on these instead of keeping lists of their own: a new message
//! type is one line here and one module beside it.

use super::*;

macro_rules! registry {
    ($($ty:ident),* $(,)?) => {
        $(
            impl ChannelMessage for $ty {
                const SCHEMA_NAME: &'static str = concat!("railfuse.", stringify!($ty));
                const KIND: MessageKind = MessageKind::$ty;
                fn stamp_ns(&self) -> u64 {
                    self.stamp_ns
                }
                fn stamp_ns_mut(&mut self) -> &mut u64 {
                    &mut self.stamp_ns
                }
            }

            impl From<$ty> for AnyMessage {
                fn from(m: $ty) -> Self {
                    AnyMessage::$ty(m)
                }
            }
        )*

        /// The type of a catalogue message.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum MessageKind {
            $($ty,)*
        }

        /// A message of any catalogue type.
        #[derive(Debug, Clone, PartialEq)]
        pub enum AnyMessage {
            $($ty($ty),)*
        }

        impl MessageKind {
            /// Every kind, in declaration order.
            pub const ALL: &'static [MessageKind] = &[$(MessageKind::$ty,)*];

            /// The MCAP schema name, `railfuse.<Type>`.
            pub fn schema_name(self) -> &'static str {
                match self {
                    $(MessageKind::$ty => <$ty as ChannelMessage>::SCHEMA_NAME,)*
                }
            }

            /// The type's name as JSON lines give it (`"type": "RadarSpeed"`).
            pub fn type_name(self) -> &'static str {
                match self {
                    $(MessageKind::$ty => stringify!($ty),)*
                }
            }

            /// The JSON schema stored in the MCAP schema record.
            pub fn schema_bytes(self) -> Vec<u8> {
                match self {
                    $(MessageKind::$ty => <$ty as ChannelMessage>::schema_bytes(),)*
                }
            }

            /// Decodes a protobuf payload of this kind.
            pub fn decode_protobuf(self, data: &[u8]) -> Result<AnyMessage, String> {
                match self {
                    $(MessageKind::$ty => crate::protobuf::decode::<$ty>(data).map(AnyMessage::$ty),)*
                }
            }

            /// Decodes a JSON payload of this kind.
            pub fn decode(self, data: &[u8]) -> serde_json::Result<AnyMessage> {
                match self {
                    $(MessageKind::$ty => serde_json::from_slice::<$ty>(data).map(AnyMessage::$ty),)*
                }
            }

            /// A message of this kind from a JSON value (a gateway's JSON line).
            pub fn from_value(self, v: serde_json::Value) -> serde_json::Result<AnyMessage> {
                match self {
                    $(MessageKind::$ty => serde_json::from_value::<$ty>(v).map(AnyMessage::$ty),)*
                }
            }
        }

        impl AnyMessage {
            pub fn kind(&self) -> MessageKind {
                match self {
                    $(AnyMessage::$ty(_) => MessageKind::$ty,)*
                }
            }

            /// The sensor's own timestamp, ns since the Unix epoch.
            pub fn stamp_ns(&self) -> u64 {
                match self {
                    $(AnyMessage::$ty(m) => m.stamp_ns,)*
                }
            }

            /// The timestamp, to move a message in time (a log replayed on a live clock).
            pub fn stamp_ns_mut(&mut self) -> &mut u64 {
                match self {
                    $(AnyMessage::$ty(m) => &mut m.stamp_ns,)*
                }
            }

            /// The protobuf payload.
            pub fn to_protobuf(&self) -> Vec<u8> {
                let mut buf = Vec::new();
                match self {
                    $(AnyMessage::$ty(m) => crate::protobuf::encode(m, &mut buf),)*
                }
                buf
            }

            /// The JSON payload.
            pub fn to_json(&self) -> Vec<u8> {
                let encoded = match self {
                    $(AnyMessage::$ty(m) => serde_json::to_vec(m),)*
                };
                encoded.expect("a catalogue message serialises")
            }
        }
    };
}

registry!(
    GnssFix,
    Imu,
    RadarSpeed,
    Odometer,
    LoopPosition,
    BalisePassage,
    EddyCurrentBlock,
    TrackMap,
    Vehicle,
    GroundTruth,
    Event,
    FusedState,
    FusedDiagnostics,
    SafetyStatus,
    TrainPosition,
    ImuErrorModel,
    RecorderDiagnostics,
    TuneEvaluation,
    TimeReference,
    CanFrame,
    CanSignals,
);

impl MessageKind {
    /// The kind whose schema is `name`.
    pub fn from_schema(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.schema_name() == name)
    }

    /// The kind whose type name is `name` (`RadarSpeed`).
    pub fn from_type_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.type_name() == name)
    }

    /// Whose clock this kind's `stamp_ns` is on: what correcting a recorder's clock moves.
    pub fn stamp_clock(self) -> StampClock {
        use MessageKind::*;
        match self {
            // The receiver's solution time, and a reference system's (GNSS-timed) truth.
            GnssFix | TimeReference | GroundTruth => StampClock::Gnss,
            Imu | RadarSpeed | Odometer | LoopPosition | BalisePassage | EddyCurrentBlock
            | Event | RecorderDiagnostics | CanFrame | CanSignals => StampClock::Recorder,
            TrackMap | Vehicle | FusedState | FusedDiagnostics | SafetyStatus | TrainPosition
            | ImuErrorModel | TuneEvaluation => StampClock::Derived,
        }
    }
}

/// Whose clock a message's stamp is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampClock {
    /// GNSS time, whichever recorder logged it: a recorder's clock correction leaves it.
    Gnss,
    /// The recorder's own clock (it stamped the sample on arrival): corrected with the
    /// recorder's clock, as its log time is.
    Recorder,
    /// Made from other messages' stamps (fused states) or not a time at all (a map).
    Derived,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_round_trips_through_its_name_encoding_and_decoding() {
        for &kind in MessageKind::ALL {
            assert_eq!(MessageKind::from_schema(kind.schema_name()), Some(kind));
            assert_eq!(MessageKind::from_type_name(kind.type_name()), Some(kind));
            let m = kind.example();
            assert_eq!(m.kind(), kind);
            let back = kind.decode(&m.to_json()).unwrap();
            assert_eq!(back, m, "{kind:?}");
            // Every field of the sample survives: nothing is left at a default.
            let again: serde_json::Value = serde_json::from_slice(&back.to_json()).unwrap();
            assert_eq!(again, kind.example_json(), "{kind:?}");
            let schema: serde_json::Value = serde_json::from_slice(&kind.schema_bytes()).unwrap();
            assert_eq!(schema["type"], "object", "{kind:?}");
            assert!(schema["properties"]["stamp_ns"].is_object(), "{kind:?}");
        }
    }
}
