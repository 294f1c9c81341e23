//! The twins in protobuf: Foxglove's messages as the prost types generated from
//! proto/foxglove/ ([`crate::protobuf::foxglove_types`]).

use prost::Message;

use super::{Time, Twin};
use crate::protobuf::foxglove_types as types;

fn timestamp(t: Time) -> Option<prost_types::Timestamp> {
    Some(prost_types::Timestamp {
        seconds: t.sec as i64,
        nanos: t.nsec as i32,
    })
}

/// The twin as its Foxglove protobuf message.
pub fn encode(twin: &Twin) -> Vec<u8> {
    match twin {
        Twin::LocationFix(f) => types::LocationFix {
            timestamp: timestamp(f.timestamp),
            frame_id: f.frame_id.clone(),
            latitude: f.latitude,
            longitude: f.longitude,
            altitude: f.altitude,
            position_covariance: f.position_covariance.to_vec(),
            position_covariance_type: i32::from(f.position_covariance_type),
            heading: f.heading,
            color: f.color.map(|c| types::Color {
                r: c.r,
                g: c.g,
                b: c.b,
                a: c.a,
            }),
        }
        .encode_to_vec(),
        Twin::GeoJson(g) => types::GeoJson {
            geojson: g.geojson.clone(),
        }
        .encode_to_vec(),
        Twin::Log(l) => types::Log {
            timestamp: timestamp(l.timestamp),
            level: i32::from(l.level),
            message: l.message.clone(),
            name: l.name.clone(),
            file: l.file.clone(),
            line: l.line,
        }
        .encode_to_vec(),
    }
}
