//! A track map from a GeoJSON file (RFC 7946): the surveyed centre lines as `LineString`
//! features in WGS-84 longitude/latitude, so a map drawn in any GIS can drive map matching
//! where the log carries no `/track/map`.
//!
//! ```json
//! { "type": "FeatureCollection", "features": [
//!   { "type": "Feature", "properties": { "name": "main line", "start_chainage_m": 0 },
//!     "geometry": { "type": "LineString", "coordinates": [[10.92, 44.65], [10.93, 44.66]] } },
//!   { "type": "Feature", "properties": { "name": "platform 2", "chainage_m": [480, 1510] },
//!     "geometry": { "type": "LineString", "coordinates": [[10.921, 44.651], [10.93, 44.659]] } } ] }
//! ```
//!
//! - The main line is the feature whose `role` is `"main"`, else the first; the others are
//!   tracks beside it ([`TrackMap::other_tracks`]).
//! - Chainage: `chainage_m`, one value per vertex, or `start_chainage_m` (default 0) with the
//!   chainage of each vertex after it measured along the line in the local plane.
//! - The local east/north/up frame has its origin at the main line's first vertex (height
//!   its third coordinate, else 0).
//! - Heights: the coordinates' third value (ellipsoidal height, m), on every vertex of a line
//!   or on none (then the line is flat), up in the local frame. Cant: `cant_mm`, one value per vertex (mm, the left
//!   rail's rise over the right's looking towards increasing chainage; a right-hand curve's
//!   is positive), and `cant_base_m` on the main line (1.5 unless given).
//!
//! A CSV of latitude/longitude rows is read as one such line ([`csv_to_geojson`]).
//!
//! The map is checked as [`TrackMap::check`] checks a logged one, and coordinates must be
//! finite, latitude within ±90° and longitude within ±180°.

use std::path::Path;

use geojson::{Feature, GeoJson, GeometryValue, JsonObject};

use crate::geodesy::GeodeticOrigin;
use crate::messages::{TrackLine, TrackMap, TrackVertex};

/// Why a GeoJSON track map was refused; shown after the file's name.
#[derive(Debug, thiserror::Error)]
pub enum GeoJsonMapError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not GeoJSON: {cause}")]
    NotGeoJson { path: String, cause: String },
    #[error("{path}: {cause}")]
    Invalid { path: String, cause: String },
}

/// Reads and checks a track file by its extension: a CSV (`.csv`, [`csv_to_geojson`]) or
/// GeoJSON (anything else).
pub fn read_track_file(path: &Path) -> Result<TrackMap, GeoJsonMapError> {
    let csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if !csv {
        return read_track_map(path);
    }
    let shown = path.display().to_string();
    parse_track_map(&csv_to_geojson(&read_bounded(path)?, &shown)?, &shown)
}

/// A CSV of the main line's vertices, one a row, as GeoJSON: a header naming the columns
/// `latitude` and `longitude` (degrees; `lat`, `lon` and `lng` do too) and optionally
/// `altitude_m` (ellipsoidal height of the top of rail, m), `cant_mm` and `chainage_m` (else
/// measured along the line from 0).
pub fn csv_to_geojson(text: &str, path: &str) -> Result<String, GeoJsonMapError> {
    let invalid = |cause: String| GeoJsonMapError::Invalid {
        path: path.to_owned(),
        cause,
    };
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = r.headers().map_err(|e| invalid(e.to_string()))?.clone();
    let column = |names: &[&str]| {
        header
            .iter()
            .position(|h| names.iter().any(|n| h.eq_ignore_ascii_case(n)))
    };
    let (Some(lat), Some(lon)) = (
        column(&["latitude", "lat", "latitude_deg"]),
        column(&["longitude", "lon", "lng", "longitude_deg"]),
    ) else {
        let found: Vec<&str> = header.iter().collect();
        return Err(invalid(format!(
            "a CSV track needs latitude and longitude columns (it has {})",
            found.join(", ")
        )));
    };
    let (alt, chainage, cant) = (
        column(&["altitude_m", "altitude", "height_m"]),
        column(&["chainage_m", "chainage"]),
        column(&["cant_mm", "cant"]),
    );
    let (mut coordinates, mut chainages, mut cants) = (Vec::new(), Vec::new(), Vec::new());
    for (k, row) in r.records().enumerate() {
        let row = row.map_err(|e| invalid(e.to_string()))?;
        let number = |i: usize| {
            let v = row.get(i).unwrap_or("");
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    invalid(format!(
                        "line {}: column {}: '{v}' is not a number",
                        k + 2,
                        &header[i]
                    ))
                })
        };
        let mut point = vec![number(lon)?, number(lat)?];
        if let Some(a) = alt {
            point.push(number(a)?);
        }
        coordinates.push(point);
        if let Some(c) = chainage {
            chainages.push(number(c)?);
        }
        if let Some(c) = cant {
            cants.push(number(c)?);
        }
    }
    let mut properties = serde_json::Map::new();
    properties.insert("name".into(), path.into());
    if chainage.is_some() {
        properties.insert("chainage_m".into(), chainages.into());
    }
    if cant.is_some() {
        properties.insert("cant_mm".into(), cants.into());
    }
    Ok(serde_json::json!({
        "type": "Feature",
        "properties": properties,
        "geometry": { "type": "LineString", "coordinates": coordinates },
    })
    .to_string())
}

/// Reads and checks a GeoJSON track map.
pub fn read_track_map(path: &Path) -> Result<TrackMap, GeoJsonMapError> {
    parse_track_map(&read_bounded(path)?, &path.display().to_string())
}

/// A track file's text, bounded (a map is small; anything much larger is not one).
fn read_bounded(path: &Path) -> Result<String, GeoJsonMapError> {
    let shown = path.display().to_string();
    // A map is small; anything past this is not a track map.
    const MAX_BYTES: u64 = 256 << 20;
    let size = std::fs::metadata(path)
        .map_err(|source| GeoJsonMapError::Io {
            path: shown.clone(),
            source,
        })?
        .len();
    if size > MAX_BYTES {
        return Err(GeoJsonMapError::Invalid {
            path: shown,
            cause: format!("{size} bytes, more than a track map's limit of {MAX_BYTES}"),
        });
    }
    std::fs::read_to_string(path).map_err(|source| GeoJsonMapError::Io {
        path: shown.clone(),
        source,
    })
}

/// Parses and checks a GeoJSON track map; `path` names it in errors.
pub fn parse_track_map(text: &str, path: &str) -> Result<TrackMap, GeoJsonMapError> {
    let invalid = |cause: String| GeoJsonMapError::Invalid {
        path: path.to_owned(),
        cause,
    };
    let doc: GeoJson = text
        .parse()
        .map_err(|e: geojson::Error| GeoJsonMapError::NotGeoJson {
            path: path.to_owned(),
            cause: e.to_string(),
        })?;
    let features: Vec<Feature> = match doc {
        GeoJson::FeatureCollection(c) => c.features,
        GeoJson::Feature(f) => vec![f],
        GeoJson::Geometry(g) => vec![Feature {
            geometry: Some(g),
            ..Feature::default()
        }],
    };
    let mut lines = Vec::new();
    for (i, f) in features.iter().enumerate() {
        let Some(GeometryValue::LineString { coordinates }) = f.geometry.as_ref().map(|g| &g.value)
        else {
            continue; // stations, balises drawn as points: not track
        };
        let props = f.properties.clone().unwrap_or_default();
        let name = props
            .get("name")
            .and_then(|v| v.as_str())
            .map_or_else(|| format!("feature {i}"), str::to_owned);
        let points = wgs84_points(coordinates, &name).map_err(invalid)?;
        let main = props.get("role").and_then(|v| v.as_str()) == Some("main");
        lines.push((name, points, props, main));
    }
    if lines.is_empty() {
        return Err(invalid(
            "no LineString feature: a track map needs its centre line".into(),
        ));
    }
    let main = lines.iter().position(|l| l.3).unwrap_or(0);
    let first = lines[main].1.first().copied().ok_or_else(|| {
        invalid(format!(
            "track '{}': no vertices, at least 2 are needed",
            lines[main].0
        ))
    })?;
    let origin = GeodeticOrigin {
        latitude_deg: first.0,
        longitude_deg: first.1,
        altitude_m: first.2.unwrap_or(0.0),
    };
    let mut tracks = Vec::new();
    for (name, points, props, _) in &lines {
        let vertices = vertices(&origin, points, props)
            .map_err(|c| invalid(format!("track '{name}': {c}")))?;
        tracks.push(TrackLine {
            name: name.clone(),
            vertices,
        });
    }
    let main_line = tracks.remove(main);
    let cant_base_m = match lines[main].2.get("cant_base_m") {
        Some(v) => Some(
            v.as_f64()
                .filter(|b| (0.5..=2.0).contains(b))
                .ok_or_else(|| {
                    invalid("cant_base_m must be a number of metres, 0.5 to 2".into())
                })?,
        ),
        None => None,
    };
    let map = TrackMap {
        other_tracks: tracks,
        cant_base_m,
        ..TrackMap::line(&main_line.name, origin, main_line.vertices)
    };
    map.check().map_err(|e| invalid(e.to_string()))?;
    Ok(map)
}

/// A LineString's positions as (latitude, longitude, altitude) in degrees and metres, each
/// checked to be a WGS-84 position (altitude 0 where not given).
fn wgs84_points(
    coordinates: &[geojson::Position],
    name: &str,
) -> Result<Vec<(f64, f64, Option<f64>)>, String> {
    let mut points = Vec::with_capacity(coordinates.len());
    for (k, p) in coordinates.iter().enumerate() {
        let c = p.as_slice();
        let lon = c.first().copied().unwrap_or(f64::NAN);
        let (lat, alt) = (c.get(1).copied().unwrap_or(f64::NAN), c.get(2).copied());
        if !(lat.is_finite() && lon.is_finite() && alt.is_none_or(f64::is_finite))
            || lat.abs() > 90.0
            || lon.abs() > 180.0
        {
            return Err(format!(
                "track '{name}': vertex {k} is not a WGS-84 position ({c:?}: longitude within ±180°, latitude within ±90°)"
            ));
        }
        points.push((lat, lon, alt));
    }
    Ok(points)
}

/// The vertices in the local plane, with their chainage, heights and cant.
fn vertices(
    origin: &GeodeticOrigin,
    points: &[(f64, f64, Option<f64>)],
    props: &JsonObject,
) -> Result<Vec<TrackVertex>, String> {
    let enu: Vec<(f64, f64, f64)> = points
        .iter()
        .map(|&(lat, lon, alt)| origin.to_enu(lat, lon, alt.unwrap_or(origin.altitude_m)))
        .collect();
    let plane: Vec<(f64, f64)> = enu.iter().map(|&(e, n, _)| (e, n)).collect();
    let heights = points.iter().filter(|p| p.2.is_some()).count();
    if heights > 0 && heights < points.len() {
        return Err(format!(
            "{heights} of {} vertices have a height: give every vertex one, or none",
            points.len()
        ));
    }
    let cant = per_vertex(props, "cant_mm", plane.len())?;
    let chainage: Vec<f64> = match per_vertex(props, "chainage_m", plane.len())? {
        Some(given) => given,
        None => {
            let start = match props.get("start_chainage_m") {
                Some(v) => v.as_f64().ok_or("start_chainage_m must be a number")?,
                None => 0.0,
            };
            let mut s = start;
            let mut out = Vec::with_capacity(plane.len());
            for (k, &(e, n)) in plane.iter().enumerate() {
                if k > 0 {
                    let (pe, pn) = plane[k - 1];
                    s += (e - pe).hypot(n - pn);
                }
                out.push(s);
            }
            out
        }
    };
    Ok(plane
        .iter()
        .zip(chainage)
        .enumerate()
        .map(|(k, (&(east_m, north_m), chainage_m))| TrackVertex {
            height_m: points[k].2.map(|_| enu[k].2),
            cant_m: cant.as_ref().map(|c| c[k] / 1e3),
            ..TrackVertex::at(chainage_m, east_m, north_m)
        })
        .collect())
}

/// A property holding one number per vertex, if the feature has it.
fn per_vertex(props: &JsonObject, key: &str, n: usize) -> Result<Option<Vec<f64>>, String> {
    let Some(v) = props.get(key) else {
        return Ok(None);
    };
    let numbers = v
        .as_array()
        .and_then(|a| a.iter().map(|x| x.as_f64()).collect::<Option<Vec<f64>>>())
        .ok_or_else(|| format!("{key} must be an array of numbers"))?;
    if numbers.len() != n {
        return Err(format!(
            "{key} has {} values for {n} vertices",
            numbers.len()
        ));
    }
    Ok(Some(numbers))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collection(features: &str) -> String {
        format!(r#"{{"type":"FeatureCollection","features":[{features}]}}"#)
    }

    fn line(props: &str, coords: &str) -> String {
        format!(
            r#"{{"type":"Feature","properties":{{{props}}},"geometry":{{"type":"LineString","coordinates":{coords}}}}}"#
        )
    }

    #[test]
    fn a_line_due_north_gets_its_chainage_along_the_ground() {
        // 0.01° of latitude is about 1.11 km.
        let text = collection(&line(
            r#""name":"north line","start_chainage_m":1000"#,
            "[[10.9, 44.6], [10.9, 44.61]]",
        ));
        let m = parse_track_map(&text, "m.geojson").unwrap();
        assert_eq!(m.name, "north line");
        let v = &m.vertices;
        assert_eq!(v[0].chainage_m, 1000.0);
        assert!(
            (v[1].chainage_m - 1000.0 - 1111.0).abs() < 5.0,
            "{}",
            v[1].chainage_m
        );
        assert!(
            v[1].east_m.abs() < 1e-6 && (v[1].north_m - (v[1].chainage_m - 1000.0)).abs() < 1e-6
        );
        let (lat, lon) = m.lat_lon_at(v[1].chainage_m).unwrap();
        assert!((lat - 44.61).abs() < 1e-9 && (lon - 10.9).abs() < 1e-9);
    }

    #[test]
    fn the_feature_marked_main_is_the_main_line_and_the_rest_are_other_tracks() {
        let text = collection(&format!(
            "{},{},{}",
            line(
                r#""name":"siding","chainage_m":[10,500]"#,
                "[[10.9001, 44.6], [10.9001, 44.6045]]"
            ),
            r#"{"type":"Feature","properties":{"name":"station"},"geometry":{"type":"Point","coordinates":[10.9,44.6]}}"#,
            line(
                r#""name":"main","role":"main""#,
                "[[10.9, 44.6], [10.9, 44.61]]"
            ),
        ));
        let m = parse_track_map(&text, "m.geojson").unwrap();
        assert_eq!(m.name, "main");
        assert_eq!(m.other_tracks.len(), 1);
        assert_eq!(m.other_tracks[0].vertices[1].chainage_m, 500.0);
        assert!((m.other_tracks[0].vertices[0].east_m - 7.9).abs() < 0.1);
    }

    #[test]
    fn bad_maps_name_the_file_and_the_cause() {
        let cases = [
            ("not json", "not GeoJSON"),
            (&collection(""), "no LineString feature"),
            (&collection(&line("", "[[10.9, 44.6]]")), "at least 2 are needed"),
            (&collection(&line("", "[[10.9, 44.6], [10.9, 95.0]]")), "vertex 1 is not a WGS-84 position"),
            (&collection(&line(r#""chainage_m":[0]"#, "[[10.9, 44.6], [10.9, 44.7]]")), "1 values for 2 vertices"),
            (&collection(&line(r#""chainage_m":[5, 5]"#, "[[10.9, 44.6], [10.9, 44.7]]")), "chainage does not increase"),
            (
                &collection(&line(
                    "",
                    "[[10.9, 44.6], [10.91, 44.6], [10.91, 44.61], [10.905, 44.61], [10.905, 44.59]]",
                )),
                "crosses itself",
            ),
        ];
        for (text, want) in cases {
            let e = parse_track_map(text, "bad.geojson")
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("bad.geojson: ") && e.contains(want), "{e}");
        }
    }
}
