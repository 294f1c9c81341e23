//! Foxglove's well-known schemas in JSON, as a Foxglove SDK log writes them:
//! `foxglove.LocationFix` → GNSS fix (a single fix: the schema says no more; its covariance
//! used unless its type is unknown). The timestamp is the measurement time; a zero one takes
//! the log time.

use super::{Decode, ForeignError, PositionFix, Role, Translated};
use crate::foxglove::LocationFix;
use crate::messages::{AnyMessage, FixType, MessageKind};

pub const ENCODING: &str = "json";
pub const LOCATION_FIX: &str = "foxglove.LocationFix";

fn location_fix(
    data: &[u8],
    _: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: LocationFix = serde_json::from_slice(data)
        .map_err(|e| ForeignError::Invalid(format!("not a {LOCATION_FIX}: {e}")))?;
    let stamp_ns = m.timestamp.sec * 1_000_000_000 + u64::from(m.timestamp.nsec);
    let fix = PositionFix {
        stamp_ns: if stamp_ns == 0 { log_time_ns } else { stamp_ns },
        fix_type: FixType::Single,
        latitude_deg: m.latitude,
        longitude_deg: m.longitude,
        altitude_m: m.altitude,
        covariance_enu_m2: m.position_covariance,
        covariance_type: m.position_covariance_type,
        course_rad: m.heading,
    };
    Ok(Translated::Message {
        message: AnyMessage::GnssFix(fix.into_gnss_fix(LOCATION_FIX)?),
        took_log_time: stamp_ns == 0,
    })
}

/// The catalogue kind and reader of a Foxglove `schema`; `Ok(None)` for one not read here.
pub(super) fn reader(
    schema: &str,
    role: Option<Role>,
) -> Result<Option<(MessageKind, Decode)>, String> {
    match (schema, role) {
        (LOCATION_FIX, None | Some(Role::Gnss)) => Ok(Some((MessageKind::GnssFix, location_fix))),
        (LOCATION_FIX, Some(other)) => Err(format!(
            "{schema} is a GNSS fix: its role cannot be {other:?}"
        )),
        _ => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::foreign::Translator;

    #[test]
    fn a_location_fix_reads_as_a_gnss_fix() {
        let t = Translator::for_schema("json", LOCATION_FIX, b"", None)
            .unwrap()
            .unwrap();
        let json = br#"{"timestamp":{"sec":1780300800,"nsec":5},"frame_id":"rx","latitude":44.6,
            "longitude":10.9,"altitude":80.0,"position_covariance":[1,0,0,0,1,0,0,0,4],
            "position_covariance_type":2}"#;
        let Translated::Message {
            message: AnyMessage::GnssFix(f),
            ..
        } = t.translate(json, 1).unwrap()
        else {
            panic!("not a fix")
        };
        assert_eq!(
            (f.stamp_ns, f.latitude_deg),
            (1_780_300_800_000_000_005, Some(44.6))
        );
        assert_eq!(f.position_covariance_enu_m2.map(|c| c[8]), Some(4.0));
        assert!(t.translate(br#"{"latitude": "x"}"#, 1).is_err());
    }
}
