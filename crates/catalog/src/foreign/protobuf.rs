//! Protobuf channels (MCAP message encoding `protobuf`), as the Foxglove SDK and
//! mcap-protobuf-support write them: the schema's data is a `FileDescriptorSet` holding the
//! message named by the schema. Each channel's messages are read through the descriptors its
//! own schema carries (prost-reflect), so field numbers and types are the writer's and nothing
//! here assumes them; a field is looked up by its name in the schema.
//!
//! - `foxglove.LocationFix` → GNSS fix, as in JSON ([`super::foxglove`]): a single fix; the
//!   covariance used unless its type is UNKNOWN; `timestamp` the measurement time (a zero one
//!   takes the log time); `heading`, where the writer set it, the course.
//!
//! A schema that does not parse, or does not hold the message it names, leaves its channel
//! unreadable: each of its messages is rejected with the schema's fault, so the caller counts
//! them and says the first, as it does for a payload that does not decode.

use prost_reflect::{DescriptorPool, DynamicMessage, MessageDescriptor, ReflectMessage, Value};

use super::{ForeignError, PositionFix, Role, Translated};
use crate::messages::{AnyMessage, FixType, MessageKind};

/// The MCAP message encoding of protobuf channels.
pub const ENCODING: &str = "protobuf";

/// The schemas read here.
pub const SCHEMAS: &[&str] = &[super::foxglove::LOCATION_FIX];

type Read = fn(&DynamicMessage, u64) -> Result<Translated, ForeignError>;

/// A channel's reader: its message descriptor, or why its schema gives none.
#[derive(Debug)]
pub struct Reader {
    descriptor: Result<MessageDescriptor, String>,
    read: Read,
}

impl Reader {
    pub(super) fn translate(
        &self,
        data: &[u8],
        log_time_ns: u64,
    ) -> Result<Translated, ForeignError> {
        let descriptor = self
            .descriptor
            .as_ref()
            .map_err(|cause| ForeignError::Schema(cause.clone()))?;
        let message = DynamicMessage::decode(descriptor.clone(), data).map_err(|e| {
            ForeignError::Invalid(format!(
                "protobuf payload does not decode as {}: {e}",
                descriptor.full_name()
            ))
        })?;
        (self.read)(&message, log_time_ns)
    }
}

/// The message `name` in the FileDescriptorSet `schema_data`, or why there is none.
fn descriptor(name: &str, schema_data: &[u8]) -> Result<MessageDescriptor, String> {
    let pool = DescriptorPool::decode(schema_data).map_err(|e| {
        format!("protobuf schema {name} does not parse as a FileDescriptorSet: {e}")
    })?;
    pool.get_message_by_name(name)
        .ok_or_else(|| format!("protobuf schema {name} does not define the message {name}"))
}

/// A field of `m` by name, `None` where the schema has no such field.
fn field<'a>(m: &'a DynamicMessage, name: &str) -> Option<std::borrow::Cow<'a, Value>> {
    m.get_field_by_name(name)
}

/// A double field; a schema whose field of that name is not a double is an error.
fn f64_field(m: &DynamicMessage, name: &str) -> Result<f64, ForeignError> {
    match field(m, name).as_deref() {
        Some(v) => v.as_f64().ok_or_else(|| {
            ForeignError::Invalid(format!(
                "{}.{name} is not a double",
                m.descriptor().full_name()
            ))
        }),
        None => Err(ForeignError::Invalid(format!(
            "{} has no field {name}",
            m.descriptor().full_name()
        ))),
    }
}

/// A `google.protobuf.Timestamp` field, ns since the epoch (0 where unset).
fn timestamp_ns(m: &DynamicMessage, name: &str) -> Result<u64, ForeignError> {
    let Some(v) = field(m, name) else {
        return Ok(0);
    };
    let Some(t) = v.as_message() else {
        return Err(ForeignError::Invalid(format!(
            "{}.{name} is not a Timestamp",
            m.descriptor().full_name()
        )));
    };
    let seconds = field(t, "seconds").and_then(|v| v.as_i64()).unwrap_or(0);
    let nanos = field(t, "nanos").and_then(|v| v.as_i32()).unwrap_or(0);
    if seconds < 0 || !(0..1_000_000_000).contains(&nanos) {
        return Err(ForeignError::Invalid(format!(
            "{name} {seconds} s {nanos} ns is not a time after 1970"
        )));
    }
    Ok(seconds as u64 * 1_000_000_000 + nanos as u64)
}

fn location_fix(m: &DynamicMessage, log_time_ns: u64) -> Result<Translated, ForeignError> {
    let schema = super::foxglove::LOCATION_FIX;
    let stamp_ns = timestamp_ns(m, "timestamp")?;
    let covariance = field(m, "position_covariance");
    let listed: Vec<f64> = covariance
        .as_deref()
        .and_then(Value::as_list)
        .map(|l| l.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default();
    let covariance_type = field(m, "position_covariance_type")
        .and_then(|v| v.as_enum_number())
        .unwrap_or(0);
    // Nine values or none: a short list is no covariance, whatever its type says.
    let (covariance_enu_m2, covariance_type) = match <[f64; 9]>::try_from(listed.as_slice()) {
        Ok(c) => (c, u8::try_from(covariance_type).unwrap_or(0)),
        Err(_) => ([0.0; 9], 0),
    };
    let heading_set = m
        .descriptor()
        .get_field_by_name("heading")
        .is_some_and(|f| m.has_field(&f));
    let fix = PositionFix {
        stamp_ns: if stamp_ns == 0 { log_time_ns } else { stamp_ns },
        fix_type: FixType::Single,
        latitude_deg: f64_field(m, "latitude")?,
        longitude_deg: f64_field(m, "longitude")?,
        altitude_m: f64_field(m, "altitude")?,
        covariance_enu_m2,
        covariance_type,
        course_rad: if heading_set {
            Some(f64_field(m, "heading")?)
        } else {
            None
        },
    };
    Ok(Translated::Message {
        message: AnyMessage::GnssFix(fix.into_gnss_fix(schema)?),
        took_log_time: stamp_ns == 0,
    })
}

/// The catalogue kind and reader of a protobuf `schema` (its FileDescriptorSet in
/// `schema_data`); `Ok(None)` for a schema not read here.
pub(super) fn reader(
    schema: &str,
    schema_data: &[u8],
    role: Option<Role>,
) -> Result<Option<(MessageKind, Reader)>, String> {
    let (kind, read) = match (schema, role) {
        (super::foxglove::LOCATION_FIX, None | Some(Role::Gnss)) => {
            (MessageKind::GnssFix, location_fix as Read)
        }
        (super::foxglove::LOCATION_FIX, Some(other)) => {
            return Err(format!(
                "{schema} is a GNSS fix: its role cannot be {other:?}"
            ))
        }
        _ => return Ok(None),
    };
    let descriptor = descriptor(schema, schema_data);
    Ok(Some((kind, Reader { descriptor, read })))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::foreign::Translator;
    use prost_reflect::prost::Message;
    use prost_reflect::prost_types::{
        field_descriptor_proto::{Label, Type},
        DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
        FileDescriptorProto, FileDescriptorSet,
    };

    fn field(
        name: &str,
        number: i32,
        ty: Type,
        type_name: Option<&str>,
        repeated: bool,
    ) -> FieldDescriptorProto {
        FieldDescriptorProto {
            name: Some(name.into()),
            number: Some(number),
            r#type: Some(ty as i32),
            type_name: type_name.map(Into::into),
            label: Some(if repeated {
                Label::Repeated
            } else {
                Label::Optional
            } as i32),
            ..Default::default()
        }
    }

    /// foxglove.LocationFix as Foxglove's .proto declares it (with field numbers of its own,
    /// which the reader must take from here), and google.protobuf.Timestamp.
    fn location_fix_schema() -> Vec<u8> {
        let timestamp = FileDescriptorProto {
            name: Some("google/protobuf/timestamp.proto".into()),
            package: Some("google.protobuf".into()),
            message_type: vec![DescriptorProto {
                name: Some("Timestamp".into()),
                field: vec![
                    field("seconds", 1, Type::Int64, None, false),
                    field("nanos", 2, Type::Int32, None, false),
                ],
                ..Default::default()
            }],
            syntax: Some("proto3".into()),
            ..Default::default()
        };
        let fix = FileDescriptorProto {
            name: Some("foxglove/LocationFix.proto".into()),
            package: Some("foxglove".into()),
            dependency: vec!["google/protobuf/timestamp.proto".into()],
            message_type: vec![DescriptorProto {
                name: Some("LocationFix".into()),
                field: vec![
                    field(
                        "timestamp",
                        6,
                        Type::Message,
                        Some(".google.protobuf.Timestamp"),
                        false,
                    ),
                    field("frame_id", 7, Type::String, None, false),
                    field("latitude", 1, Type::Double, None, false),
                    field("longitude", 2, Type::Double, None, false),
                    field("altitude", 3, Type::Double, None, false),
                    field("position_covariance", 4, Type::Double, None, true),
                    field(
                        "position_covariance_type",
                        5,
                        Type::Enum,
                        Some(".foxglove.LocationFix.PositionCovarianceType"),
                        false,
                    ),
                ],
                enum_type: vec![EnumDescriptorProto {
                    name: Some("PositionCovarianceType".into()),
                    value: ["UNKNOWN", "APPROXIMATED", "DIAGONAL_KNOWN", "KNOWN"]
                        .iter()
                        .enumerate()
                        .map(|(k, n)| EnumValueDescriptorProto {
                            name: Some((*n).into()),
                            number: Some(k as i32),
                            ..Default::default()
                        })
                        .collect(),
                    ..Default::default()
                }],
                ..Default::default()
            }],
            syntax: Some("proto3".into()),
            ..Default::default()
        };
        FileDescriptorSet {
            file: vec![timestamp, fix],
        }
        .encode_to_vec()
    }

    fn encoded(schema: &[u8], lat: f64, covariance_type: i32) -> Vec<u8> {
        let pool = DescriptorPool::decode(schema).unwrap();
        let d = pool.get_message_by_name("foxglove.LocationFix").unwrap();
        let mut m = DynamicMessage::new(d.clone());
        let mut t = DynamicMessage::new(
            pool.get_message_by_name("google.protobuf.Timestamp")
                .unwrap(),
        );
        t.set_field_by_name("seconds", Value::I64(1_780_300_800));
        t.set_field_by_name("nanos", Value::I32(5));
        m.set_field_by_name("timestamp", Value::Message(t));
        m.set_field_by_name("latitude", Value::F64(lat));
        m.set_field_by_name("longitude", Value::F64(10.9));
        m.set_field_by_name("altitude", Value::F64(80.0));
        let cov = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 4.0];
        m.set_field_by_name(
            "position_covariance",
            Value::List(cov.map(Value::F64).to_vec()),
        );
        m.set_field_by_name(
            "position_covariance_type",
            Value::EnumNumber(covariance_type),
        );
        m.encode_to_vec()
    }

    #[test]
    fn a_location_fix_reads_through_its_own_descriptors() {
        let schema = location_fix_schema();
        let t = Translator::for_schema(ENCODING, "foxglove.LocationFix", &schema, None)
            .unwrap()
            .unwrap();
        let Translated::Message {
            message: AnyMessage::GnssFix(f),
            took_log_time,
        } = t.translate(&encoded(&schema, 44.6, 2), 1).unwrap()
        else {
            panic!("not a fix")
        };
        assert!(!took_log_time);
        assert_eq!(
            (f.stamp_ns, f.latitude_deg, f.altitude_m),
            (1_780_300_800_000_000_005, Some(44.6), Some(80.0))
        );
        assert_eq!(f.position_covariance_enu_m2.map(|c| c[8]), Some(4.0));
        // UNKNOWN covariance is not used.
        let Translated::Message {
            message: AnyMessage::GnssFix(f),
            ..
        } = t.translate(&encoded(&schema, 44.6, 0), 1).unwrap()
        else {
            panic!("not a fix")
        };
        assert_eq!(f.position_covariance_enu_m2, None);
    }

    #[test]
    fn bad_schemas_payloads_and_positions_are_rejected_in_words() {
        let schema = location_fix_schema();
        let t = Translator::for_schema(ENCODING, "foxglove.LocationFix", &schema, None)
            .unwrap()
            .unwrap();
        let nan = t.translate(&encoded(&schema, f64::NAN, 2), 1).unwrap_err();
        assert!(nan.to_string().contains("not on the globe"), "{nan}");
        let short = t.translate(&[0x09, 1, 2], 1).unwrap_err();
        assert!(
            short
                .to_string()
                .contains("does not decode as foxglove.LocationFix"),
            "{short}"
        );
        // A schema that does not parse: the channel's every message is rejected with why.
        let broken = Translator::for_schema(ENCODING, "foxglove.LocationFix", b"\xff\xff", None)
            .unwrap()
            .unwrap();
        let e = broken.translate(&encoded(&schema, 44.6, 2), 1).unwrap_err();
        assert!(
            e.to_string()
                .contains("does not parse as a FileDescriptorSet"),
            "{e}"
        );
        assert!(Translator::for_schema(
            ENCODING,
            "foxglove.LocationFix",
            &schema,
            Some(Role::Radar)
        )
        .is_err());
        assert!(
            Translator::for_schema(ENCODING, "foxglove.Pose", &schema, None)
                .unwrap()
                .is_none()
        );
    }
}
