//! Twins of railfuse messages in Foxglove's well-known JSON schemas, written beside railfuse's
//! own channels (which stay as they are) so that a log also opens in Foxglove: GNSS fixes and
//! each pipeline's position as `foxglove.LocationFix` (its Map panel), the track map as
//! `foxglove.GeoJSON`, events as `foxglove.Log`. The twin of `/gnss/fix` is on
//! `/foxglove/gnss/fix`: every twin's topic is its source's under [`TOPIC_PREFIX`].
//!
//! A twin is in its source channel's encoding. The JSON schemas are copies of
//! `@foxglove/schemas` 2.1.0 (npm; `dist/jsonschema`), the protobuf ones (proto/foxglove/)
//! declare the fields railfuse writes with Foxglove's numbers; the interop tests validate the
//! JSON twins against the package itself and decode the protobuf ones with Foxglove's own
//! generated classes.

use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::messages::{AnyMessage, Event, FixType, FusedState, GnssFix, Severity, TrackMap};
use crate::protobuf::Encoding;

mod protobuf;

static TWINS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Whether writers add twins unless told otherwise (on, until [`set_twins_by_default`]).
pub fn twins_by_default() -> bool {
    TWINS.load(std::sync::atomic::Ordering::Relaxed)
}

/// Turns twins off (or on) for every writer this process opens from now on: the CLI's
/// `--no-foxglove`.
pub fn set_twins_by_default(on: bool) {
    TWINS.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Where twins live: `/foxglove` + the source's topic.
pub const TOPIC_PREFIX: &str = "/foxglove";

/// The twin topic of a railfuse topic.
pub fn twin_topic(topic: &str) -> String {
    format!("{TOPIC_PREFIX}{topic}")
}

/// A message in one of Foxglove's schemas.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Twin {
    LocationFix(LocationFix),
    GeoJson(GeoJson),
    Log(Log),
}

/// The Foxglove schemas railfuse writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TwinKind {
    LocationFix,
    GeoJson,
    Log,
}

impl TwinKind {
    /// The schema name Foxglove recognises.
    pub fn schema_name(self) -> &'static str {
        match self {
            TwinKind::LocationFix => "foxglove.LocationFix",
            TwinKind::GeoJson => "foxglove.GeoJSON",
            TwinKind::Log => "foxglove.Log",
        }
    }

    /// Its schema data in `encoding`: the JSON schema as the package publishes it, or the
    /// FileDescriptorSet of proto/foxglove/.
    pub fn schema_bytes(self, encoding: Encoding) -> &'static [u8] {
        match (encoding, self) {
            (Encoding::Protobuf, _) => crate::protobuf::schema_data(self.schema_name()),
            (Encoding::Json, TwinKind::LocationFix) => include_bytes!("LocationFix.json"),
            (Encoding::Json, TwinKind::GeoJson) => include_bytes!("GeoJSON.json"),
            (Encoding::Json, TwinKind::Log) => include_bytes!("Log.json"),
        }
    }
}

impl Twin {
    pub fn kind(&self) -> TwinKind {
        match self {
            Twin::LocationFix(_) => TwinKind::LocationFix,
            Twin::GeoJson(_) => TwinKind::GeoJson,
            Twin::Log(_) => TwinKind::Log,
        }
    }

    /// Its own timestamp, ns (the map has none: 0).
    pub fn stamp_ns(&self) -> u64 {
        let t = match self {
            Twin::LocationFix(f) => f.timestamp,
            Twin::Log(l) => l.timestamp,
            Twin::GeoJson(_) => return 0,
        };
        t.sec * 1_000_000_000 + t.nsec as u64
    }

    /// The twin of a railfuse message, if its kind has one (fixes without a position have
    /// none).
    pub fn of<M: 'static>(msg: &M) -> Option<Twin> {
        let any = msg as &dyn std::any::Any;
        if let Some(fix) = any.downcast_ref::<GnssFix>() {
            location_fix(fix)
        } else if let Some(map) = any.downcast_ref::<TrackMap>() {
            Some(Twin::GeoJson(geojson(map)))
        } else {
            any.downcast_ref::<Event>().map(|e| Twin::Log(log(e)))
        }
    }

    /// [`Twin::of`] a message of any kind.
    pub fn of_any(msg: &AnyMessage) -> Option<Twin> {
        match msg {
            AnyMessage::GnssFix(m) => Twin::of(m),
            AnyMessage::TrackMap(m) => Twin::of(m),
            AnyMessage::Event(m) => Twin::of(m),
            _ => None,
        }
    }

    /// The message in `encoding`.
    pub fn encode(&self, encoding: Encoding) -> Vec<u8> {
        match encoding {
            Encoding::Json => serde_json::to_vec(self).expect("a twin serialises"),
            Encoding::Protobuf => protobuf::encode(self),
        }
    }
}

/// `foxglove.Time`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Time {
    pub sec: u64,
    pub nsec: u32,
}

impl Time {
    pub fn from_ns(ns: u64) -> Self {
        Time {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `foxglove.Color`, components 0–1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Color {
    pub r: f64,
    pub g: f64,
    pub b: f64,
    pub a: f64,
}

/// `foxglove.LocationFix` (read too: a Foxglove SDK log's GNSS fixes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocationFix {
    pub timestamp: Time,
    #[serde(default)]
    pub frame_id: String,
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    /// East/north/up, row-major, m².
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub position_covariance_type: u8,
    /// Clockwise from north, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<Color>,
}

/// `foxglove.GeoJSON`: the GeoJSON text.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GeoJson {
    pub geojson: String,
}

/// `foxglove.Log`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Log {
    pub timestamp: Time,
    /// 2 info, 3 warning, 4 error.
    pub level: u8,
    pub message: String,
    pub name: String,
    pub file: String,
    pub line: u32,
}

/// A fix with a position, coloured by its fix type the way receivers show it.
pub fn location_fix(g: &GnssFix) -> Option<Twin> {
    let (latitude, longitude) = (g.latitude_deg?, g.longitude_deg?);
    let (r, gr, b) = match g.fix_type {
        FixType::None => return None,
        FixType::Single => (0.86, 0.2, 0.2),
        FixType::Dgps => (0.9, 0.59, 0.12),
        FixType::RtkFloat => (0.9, 0.82, 0.16),
        FixType::RtkFixed => (0.16, 0.75, 0.35),
    };
    let (position_covariance, position_covariance_type) = match g.position_covariance_enu_m2 {
        Some(c) if c.iter().all(|v| v.is_finite()) => (c, 3),
        _ => ([0.0; 9], 0),
    };
    Some(Twin::LocationFix(LocationFix {
        timestamp: Time::from_ns(g.stamp_ns),
        frame_id: format!("gnss ({})", g.fix_type.name()),
        latitude,
        longitude,
        altitude: g.altitude_m.unwrap_or(0.0),
        position_covariance,
        position_covariance_type,
        heading: g.course_rad.filter(|c| c.is_finite()),
        color: Some(Color {
            r,
            g: gr,
            b,
            a: 1.0,
        }),
    }))
}

/// A pipeline's fused position. A 2-D pipeline gives its own position, east/north covariance
/// and heading, map or no map (altitude: the map's origin's, else 0); an along-track one its
/// chainage on the map, with the along-track variance as an approximated east/north
/// covariance (nothing across the track: a 1-D pipeline knows none) and the track's heading.
pub fn fused_location(pipeline: &str, f: &FusedState, map: Option<&TrackMap>) -> Option<Twin> {
    let g = f.geodetic(map)?;
    Some(Twin::LocationFix(LocationFix {
        timestamp: Time::from_ns(f.stamp_ns),
        frame_id: pipeline.to_owned(),
        latitude: g.latitude_deg,
        longitude: g.longitude_deg,
        altitude: g.altitude_m,
        position_covariance: g.covariance_enu_m2,
        position_covariance_type: g.covariance_type,
        heading: g.heading_rad,
        color: None,
    }))
}

/// The track as a GeoJSON feature collection: the centre line, tunnels, stations and balises.
pub fn geojson(map: &TrackMap) -> GeoJson {
    let lon_lat = |east: f64, north: f64| {
        let (lat, lon, _) = map.origin.to_geodetic(east, north, 0.0);
        json!([lon, lat])
    };
    let at = |chainage: f64| map.locate(chainage).map(|(e, n, _)| lon_lat(e, n));
    let line: Vec<_> = map
        .vertices
        .iter()
        .map(|v| lon_lat(v.east_m, v.north_m))
        .collect();
    let mut features = vec![json!({
        "type": "Feature",
        "properties": { "name": map.name, "kind": "track" },
        "geometry": { "type": "LineString", "coordinates": line },
    })];
    for t in &map.tunnels {
        let inner = map
            .vertices
            .iter()
            .filter(|v| v.chainage_m > t.start_chainage_m && v.chainage_m < t.end_chainage_m)
            .map(|v| lon_lat(v.east_m, v.north_m));
        let coords: Vec<_> = at(t.start_chainage_m)
            .into_iter()
            .chain(inner)
            .chain(at(t.end_chainage_m))
            .collect();
        features.push(json!({
            "type": "Feature",
            "properties": { "name": format!("tunnel {}", t.name), "kind": "tunnel" },
            "geometry": { "type": "LineString", "coordinates": coords },
        }));
    }
    let points = map
        .stations
        .iter()
        .map(|s| (s.name.clone(), "station", s.chainage_m))
        .chain(
            map.balises
                .iter()
                .map(|b| (b.balise_id.clone(), "balise", b.chainage_m)),
        );
    for (name, kind, chainage) in points {
        if let Some(p) = at(chainage) {
            features.push(json!({
                "type": "Feature",
                "properties": { "name": name, "kind": kind, "chainage_m": chainage },
                "geometry": { "type": "Point", "coordinates": p },
            }));
        }
    }
    let collection = json!({ "type": "FeatureCollection", "features": features });
    GeoJson {
        geojson: collection.to_string(),
    }
}

/// An event as a log line.
pub fn log(e: &Event) -> Log {
    Log {
        timestamp: Time::from_ns(e.stamp_ns),
        level: match e.kind.describe().1 {
            Severity::Info => 2,
            Severity::Warning => 3,
            Severity::Error => 4,
        },
        message: e.line(),
        name: "railfuse".into(),
        file: String::new(),
        line: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{EventKind, MessageKind};

    fn example(kind: MessageKind) -> AnyMessage {
        kind.example()
    }

    #[test]
    fn a_fix_without_a_position_has_no_twin_and_one_with_has_its_colour_and_time() {
        let AnyMessage::GnssFix(mut fix) = example(MessageKind::GnssFix) else {
            panic!("a GNSS example")
        };
        fix.stamp_ns = 1_700_000_000_123_456_789;
        let Some(Twin::LocationFix(l)) = location_fix(&fix) else {
            panic!("a fix with a position has a twin")
        };
        assert_eq!(
            l.timestamp,
            Time {
                sec: 1_700_000_000,
                nsec: 123_456_789
            }
        );
        assert_eq!(Twin::LocationFix(l).stamp_ns(), fix.stamp_ns);
        fix.fix_type = FixType::None;
        assert!(location_fix(&fix).is_none());
    }

    #[test]
    fn a_2d_pipelines_twin_is_its_own_position_and_heading_map_or_no_map() {
        use crate::messages::PlanePosition;
        let AnyMessage::TrackMap(map) = example(MessageKind::TrackMap) else {
            panic!("a map example")
        };
        let (lat, lon, _) = map.origin.to_geodetic(30.0, -40.0, 0.0);
        let state = FusedState {
            stamp_ns: 7,
            // A chainage the map would put elsewhere, heading another way.
            chainage_m: 0.0,
            speed_mps: 5.0,
            acceleration_mps2: 0.0,
            covariance: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            source: "/gnss/fix".into(),
            sensor_states: Vec::new(),
            plane: Some(PlanePosition {
                east_m: 30.0,
                north_m: -40.0,
                covariance_en_m2: [4.0, 0.5, 0.5, 1.0],
                latitude_deg: lat,
                longitude_deg: lon,
                heading_rad: Some(2.5),
                ..Default::default()
            }),
        };
        for m in [Some(&map), None] {
            let Some(Twin::LocationFix(l)) = fused_location("p", &state, m) else {
                panic!("a 2-D state has a twin, map or not")
            };
            assert_eq!((l.latitude, l.longitude), (lat, lon));
            assert_eq!(l.heading, Some(2.5));
            assert_eq!(l.position_covariance[..5], [4.0, 0.5, 0.0, 0.5, 1.0]);
            assert_eq!(l.position_covariance_type, 3);
        }
        // An along-track state needs the map to be placed.
        let along = FusedState {
            plane: None,
            ..state
        };
        assert!(fused_location("p", &along, None).is_none());
        assert!(fused_location("p", &along, Some(&map)).is_some());
    }

    #[test]
    fn events_keep_their_words_and_severity() {
        let e = Event {
            stamp_ns: 5,
            kind: EventKind::DeviceFault,
            text: "radar".into(),
        };
        let l = log(&e);
        assert_eq!(
            (l.level, l.message.as_str()),
            (4, "Device reports a fault: radar")
        );
    }

    #[test]
    fn the_track_is_a_line_string_in_longitude_latitude_order() {
        let AnyMessage::TrackMap(map) = example(MessageKind::TrackMap) else {
            panic!("a map example")
        };
        let g: serde_json::Value = serde_json::from_str(&geojson(&map).geojson).unwrap();
        let line = &g["features"][0]["geometry"];
        assert_eq!(line["type"], "LineString");
        let first = &line["coordinates"][0];
        let (lon, lat, _) = {
            let (lat, lon, alt) =
                map.origin
                    .to_geodetic(map.vertices[0].east_m, map.vertices[0].north_m, 0.0);
            (lon, lat, alt)
        };
        assert!((first[0].as_f64().unwrap() - lon).abs() < 1e-9);
        assert!((first[1].as_f64().unwrap() - lat).abs() < 1e-9);
    }
}
