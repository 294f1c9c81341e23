//! Messages of other tools' schemas, read as railfuse's own. A ROS 2 bag's
//! `sensor_msgs/msg/NavSatFix` is a [`GnssFix`](crate::messages::GnssFix), its `Imu` an
//! [`Imu`](crate::messages::Imu), a `geometry_msgs/msg/TwistWithCovarianceStamped` the speed of
//! the sensor its [`Role`] names. One table ([`Translator::for_channel`]) maps a channel's
//! message encoding, schema name and role to a catalogue kind; everything after it (sensor
//! models, pipelines, the viewer) sees catalogue messages only, never an encoding. Readers:
//! [`ros2`] (CDR), [`ros1`] (ROS 1's serialisation, the same messages), [`foxglove`] (Foxglove's well-known schemas in JSON) and [`protobuf`]
//! (the same schemas in protobuf, read through the file's own descriptors).

pub mod can;
pub mod foxglove;
pub mod frames;
pub mod protobuf;
pub mod ros1;
pub mod ros2;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use crate::log::{ChannelInfo, LogMessage, SchemaInfo};
use crate::messages::{AnyMessage, MessageKind};

/// What a sensor is, where its message's schema cannot say (a `Twist` from a Doppler radar
/// or from a wheel odometer).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Radar,
    Odometer,
    Gnss,
    Imu,
}

impl Role {
    pub const NAMES: &'static [&'static str] = &["radar", "odometer", "gnss", "imu"];
}

/// Why one foreign message was not read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ForeignError {
    #[error("CDR payload does not decode as {schema}: {cause}")]
    Cdr { schema: String, cause: String },
    /// A ROS 1 payload that does not decode (counted with the CDR ones: the bytes do not fit
    /// the schema).
    #[error("ROS 1 payload does not decode as {schema}: {cause}")]
    Ros1 { schema: String, cause: String },
    #[error("{0}")]
    Invalid(String),
    /// The channel's schema cannot be used (a protobuf schema that does not parse).
    #[error("{0}")]
    Schema(String),
}

impl ForeignError {
    /// The kind of cause, to count messages by ("cdr": the payload does not decode;
    /// "invalid": it decodes to values that are not a measurement; "schema": the channel's
    /// schema is unusable).
    pub fn kind(&self) -> &'static str {
        match self {
            ForeignError::Cdr { .. } | ForeignError::Ros1 { .. } => "cdr",
            ForeignError::Invalid(_) => "invalid",
            ForeignError::Schema(_) => "schema",
        }
    }
}

/// Where a sensor frame sits on the vehicle, as a bag's `/tf_static` says: `child` in
/// `parent`'s frame, translated by `translation_m` and rotated by the quaternion
/// `rotation_xyzw`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTransform {
    pub parent: String,
    pub child: String,
    pub translation_m: [f64; 3],
    pub rotation_xyzw: [f64; 4],
}

impl std::fmt::Display for FrameTransform {
    /// `gps in base_link at (-3.200, 0.000, 3.900) m, roll 0.0° pitch 0.0° yaw 90.0°`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.translation_m;
        let [qx, qy, qz, qw] = self.rotation_xyzw;
        // Roll, pitch, yaw (z-y-x, as tf's getRPY).
        let roll = (2.0 * (qw * qx + qy * qz)).atan2(1.0 - 2.0 * (qx * qx + qy * qy));
        let pitch = (2.0 * (qw * qy - qz * qx)).clamp(-1.0, 1.0).asin();
        let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        write!(
            f,
            "{} in {} at ({x:.3}, {y:.3}, {z:.3}) m, roll {:.1}° pitch {:.1}° yaw {:.1}°",
            self.child,
            self.parent,
            roll.to_degrees(),
            pitch.to_degrees(),
            yaw.to_degrees()
        )
    }
}

/// One foreign message read.
#[derive(Debug, Clone, PartialEq)]
pub enum Translated {
    Message {
        message: AnyMessage,
        /// The message carried no time of its own (a zero `header.stamp`): it took the log
        /// time.
        took_log_time: bool,
    },
    /// Read, and not a measurement (a fix of status NO_FIX), with the reason it is counted
    /// under.
    Skipped(&'static str),
}

/// A position fix as foreign schemas give one (NavSatFix, LocationFix): on the globe, its
/// ENU covariance used where its type is not UNKNOWN (0) and it is finite with non-negative
/// variances.
pub(crate) struct PositionFix {
    pub stamp_ns: u64,
    pub fix_type: crate::messages::FixType,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub altitude_m: f64,
    pub covariance_enu_m2: [f64; 9],
    pub covariance_type: u8,
    pub course_rad: Option<f64>,
}

impl PositionFix {
    /// The catalogue's fix of it; `schema` names the message in an error.
    pub(crate) fn into_gnss_fix(
        self,
        schema: &str,
    ) -> Result<crate::messages::GnssFix, ForeignError> {
        let (lat, lon, alt) = (self.latitude_deg, self.longitude_deg, self.altitude_m);
        if !(lat.abs() <= 90.0 && lon.abs() <= 180.0 && alt.is_finite()) {
            return Err(ForeignError::Invalid(format!(
                "{schema} position ({lat}, {lon}, {alt}) is not on the globe"
            )));
        }
        let c = self.covariance_enu_m2;
        let known = self.covariance_type != 0
            && c.iter().all(|x| x.is_finite())
            && [c[0], c[4], c[8]].iter().all(|v| *v >= 0.0);
        Ok(crate::messages::GnssFix {
            stamp_ns: self.stamp_ns,
            fix_type: self.fix_type,
            satellites: 0,
            hdop: None,
            latitude_deg: Some(lat),
            longitude_deg: Some(lon),
            altitude_m: Some(alt),
            altitude_msl_m: None,
            position_covariance_enu_m2: known.then_some(c),
            speed_mps: None,
            course_rad: self.course_rad,
        })
    }
}

type Decode = fn(&[u8], Option<Role>, u64) -> Result<Translated, ForeignError>;

/// How one channel's payloads are read: by a fixed function of the schema (CDR and JSON,
/// whose layout the schema's name fixes), or through the descriptors the channel's own schema
/// carries (protobuf).
#[derive(Clone)]
enum Decoder {
    Fixed(Decode),
    Protobuf(Arc<protobuf::Reader>),
}

/// How to read a foreign channel as a catalogue kind.
#[derive(Clone)]
pub struct Translator {
    pub kind: MessageKind,
    role: Option<Role>,
    decoder: Decoder,
}

impl std::fmt::Debug for Translator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Translator({:?}, {:?})", self.kind, self.role)
    }
}

impl Translator {
    /// The translator of `channel` (its message encoding and schema) for a sensor of `role`.
    pub fn for_channel(channel: &ChannelInfo, role: Option<Role>) -> Result<Option<Self>, String> {
        let schema = channel.schema.as_deref();
        Self::for_schema(
            &channel.message_encoding,
            schema.map_or("", |s| s.name.as_str()),
            schema.map_or(&[][..], |s| &s.data[..]),
            role,
        )
    }

    /// The translator of a channel of `schema` (its data `schema_data`) in `encoding` for a
    /// sensor of `role`: `Ok(None)` for a schema no translator reads (railfuse's own
    /// included), an error in words for one that needs a role it was not given, or whose
    /// schema cannot be that role.
    pub fn for_schema(
        encoding: &str,
        schema: &str,
        schema_data: &[u8],
        role: Option<Role>,
    ) -> Result<Option<Self>, String> {
        let fixed = |read: Option<(MessageKind, Decode)>| {
            read.map(|(kind, decode)| (kind, Decoder::Fixed(decode)))
        };
        let read = match encoding {
            ros2::ENCODING => fixed(ros2::reader::<ros2::Cdr>(schema, role)?),
            ros1::ENCODING => fixed(ros1::reader(schema, role)?),
            foxglove::ENCODING => fixed(foxglove::reader(schema, role)?),
            protobuf::ENCODING => protobuf::reader(schema, schema_data, role)?
                .map(|(kind, reader)| (kind, Decoder::Protobuf(Arc::new(reader)))),
            _ => None,
        };
        Ok(read.map(|(kind, decoder)| Self {
            kind,
            role,
            decoder,
        }))
    }

    /// Reads one payload; `log_time_ns` stands in for a missing sensor time.
    pub fn translate(&self, data: &[u8], log_time_ns: u64) -> Result<Translated, ForeignError> {
        match &self.decoder {
            Decoder::Fixed(decode) => decode(data, self.role, log_time_ns),
            Decoder::Protobuf(reader) => reader.translate(data, log_time_ns),
        }
    }

    /// The foreign channel `info` as the railfuse channel it is read as: the same id and
    /// topic, the catalogue kind's JSON schema.
    pub fn channel(&self, info: &ChannelInfo) -> Arc<ChannelInfo> {
        Arc::new(ChannelInfo {
            id: info.id,
            topic: info.topic.clone(),
            message_encoding: crate::log::MESSAGE_ENCODING.to_owned(),
            metadata: info.metadata.clone(),
            schema: Some(Arc::new(SchemaInfo {
                id: info.schema.as_ref().map_or(0, |s| s.id),
                name: self.kind.schema_name().to_owned(),
                encoding: crate::log::SCHEMA_ENCODING.to_owned(),
                data: self.kind.schema_bytes(),
            })),
        })
    }

    /// The schemas a translator reads, for messages that list what would fit.
    pub fn schemas() -> Vec<String> {
        let in_encoding = |encoding: &str, schemas: &[&str]| {
            schemas
                .iter()
                .map(|s| format!("{s} ({encoding})"))
                .collect::<Vec<_>>()
        };
        [
            in_encoding(ros2::ENCODING, ros2::SCHEMAS),
            in_encoding(ros1::ENCODING, &ros1::SCHEMAS),
            in_encoding(foxglove::ENCODING, &[foxglove::LOCATION_FIX]),
            in_encoding(protobuf::ENCODING, protobuf::SCHEMAS),
        ]
        .concat()
    }
}

/// The foreign channels of one log being read, each with its translator and the railfuse
/// channel it reads as: what a command that walks a log (tune, eval) puts between the
/// reader and its own code, so that it sees catalogue messages only.
#[derive(Default)]
pub struct ForeignChannels {
    read_as: crate::log::IdMap<(Translator, Arc<ChannelInfo>)>,
}

impl ForeignChannels {
    /// Meets a channel: the channel to treat it as (the railfuse one it translates to with
    /// `role`, else itself), or why a sensor of `role` cannot read it.
    pub fn channel(
        &mut self,
        c: Arc<ChannelInfo>,
        role: Option<Role>,
    ) -> Result<Arc<ChannelInfo>, String> {
        match Translator::for_channel(&c, role)? {
            Some(t) => {
                let read_as = t.channel(&c);
                self.read_as.insert(c.id, (t, read_as.clone()));
                Ok(read_as)
            }
            None => Ok(c),
        }
    }

    /// A message as its channel is treated: translated (into `buf`) on a foreign channel,
    /// unchanged on another; `Ok(None)` for one read and skipped (a NO_FIX fix).
    pub fn message<'a>(
        &'a self,
        m: LogMessage<'a>,
        buf: &'a mut Vec<u8>,
    ) -> Result<Option<LogMessage<'a>>, ForeignError> {
        let Some((t, channel)) = self.read_as.get(&m.channel.id) else {
            return Ok(Some(m));
        };
        match t.translate(m.data, m.log_time_ns)? {
            Translated::Message { message, .. } => {
                *buf = message.to_json();
                Ok(Some(LogMessage {
                    channel,
                    data: buf,
                    ..m
                }))
            }
            Translated::Skipped(_) => Ok(None),
        }
    }
}
