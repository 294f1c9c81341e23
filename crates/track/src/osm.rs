//! OpenStreetMap's railway lines (`railway=rail` ways) from an extract, `.osm` XML or GeoJSON
//! (as overpass-turbo exports it), to check a fitted line against: how far it lies from the
//! nearest rail way, over the stretch where one is near.
//!
//! An `.osm` file is streamed twice: first for the ways tagged `railway=rail` and the nodes
//! they name, then for those nodes' places; memory holds the rail ways only, however large
//! the extract.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use quick_xml::events::{BytesStart, Event};
use serde::Serialize;

use crate::line::Line;

/// A rail way's points, latitude and longitude in degrees.
pub type Way = Vec<(f64, f64)>;

#[derive(Debug, thiserror::Error)]
pub enum OsmError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: not OpenStreetMap XML: {cause}")]
    Xml { path: String, cause: String },
    #[error("{path}: not GeoJSON: {cause}")]
    GeoJson { path: String, cause: String },
    #[error("{path}: no railway=rail way in it")]
    NoRail { path: String },
}

/// The `railway=rail` ways of an extract: `.osm` (or `.xml`) as OSM XML, anything else as
/// GeoJSON.
pub fn read_rail(path: &Path) -> Result<Vec<Way>, OsmError> {
    let shown = path.display().to_string();
    let xml = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("osm") || e.eq_ignore_ascii_case("xml"));
    let ways = match xml {
        true => read_xml(path, &shown)?,
        false => read_geojson(path, &shown)?,
    };
    match ways.iter().any(|w| w.len() >= 2) {
        true => Ok(ways.into_iter().filter(|w| w.len() >= 2).collect()),
        false => Err(OsmError::NoRail { path: shown }),
    }
}

fn attr(e: &BytesStart, key: &[u8]) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.as_ref() == key)
        .map(|a| String::from_utf8_lossy(&a.value).into_owned())
}

/// Walks every start or empty element of an OSM XML file.
fn walk(path: &Path, shown: &str, mut each: impl FnMut(&BytesStart, bool)) -> Result<(), OsmError> {
    let file = File::open(path).map_err(|source| OsmError::Io {
        path: shown.to_owned(),
        source,
    })?;
    let mut reader = quick_xml::Reader::from_reader(BufReader::new(file));
    let mut buf = Vec::new();
    loop {
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|e| OsmError::Xml {
                path: shown.to_owned(),
                cause: format!("at byte {}: {e}", reader.buffer_position()),
            })?;
        match event {
            Event::Start(e) => each(&e, false),
            Event::Empty(e) => each(&e, true),
            Event::Eof => return Ok(()),
            _ => {}
        }
        buf.clear();
    }
}

fn read_xml(path: &Path, shown: &str) -> Result<Vec<Way>, OsmError> {
    // Pass 1: the rail ways, as node ids.
    let (mut ways, mut way, mut rail) = (Vec::<Vec<i64>>::new(), None::<Vec<i64>>, false);
    walk(path, shown, |e, empty| match e.name().as_ref() {
        b"way" => {
            if let Some(w) = way.take().filter(|_| rail) {
                ways.push(w);
            }
            rail = false;
            way = (!empty).then(Vec::new);
        }
        b"nd" => {
            if let (Some(w), Some(id)) = (way.as_mut(), attr(e, b"ref")) {
                w.extend(id.parse::<i64>().ok());
            }
        }
        b"tag" if way.is_some() => {
            rail |= attr(e, b"k").as_deref() == Some("railway")
                && attr(e, b"v").as_deref() == Some("rail");
        }
        b"relation" | b"node" => {
            if let Some(w) = way.take().filter(|_| rail) {
                ways.push(w);
            }
            rail = false;
        }
        _ => {}
    })?;
    if let Some(w) = way.filter(|_| rail) {
        ways.push(w);
    }
    // Pass 2: those nodes' places.
    let wanted: HashSet<i64> = ways.iter().flatten().copied().collect();
    let mut at: HashMap<i64, (f64, f64)> = HashMap::with_capacity(wanted.len());
    walk(path, shown, |e, _| {
        if e.name().as_ref() != b"node" {
            return;
        }
        let number = |k: &[u8]| attr(e, k).and_then(|v| v.parse::<f64>().ok());
        if let (Some(id), Some(lat), Some(lon)) = (
            attr(e, b"id").and_then(|v| v.parse::<i64>().ok()),
            number(b"lat"),
            number(b"lon"),
        ) {
            if wanted.contains(&id) {
                at.insert(id, (lat, lon));
            }
        }
    })?;
    Ok(ways
        .iter()
        .map(|w| w.iter().filter_map(|id| at.get(id).copied()).collect())
        .collect())
}

fn read_geojson(path: &Path, shown: &str) -> Result<Vec<Way>, OsmError> {
    let text = std::fs::read_to_string(path).map_err(|source| OsmError::Io {
        path: shown.to_owned(),
        source,
    })?;
    let geo: geojson::GeoJson = text
        .parse()
        .map_err(|e: geojson::Error| OsmError::GeoJson {
            path: shown.to_owned(),
            cause: e.to_string(),
        })?;
    let features = match geo {
        geojson::GeoJson::FeatureCollection(c) => c.features,
        geojson::GeoJson::Feature(f) => vec![f],
        geojson::GeoJson::Geometry(_) => Vec::new(),
    };
    let mut ways = Vec::new();
    for f in features {
        let rail = f
            .properties
            .as_ref()
            .and_then(|p| p.get("railway"))
            .and_then(|v| v.as_str())
            == Some("rail");
        let Some(g) = f.geometry.filter(|_| rail) else {
            continue;
        };
        let lines = match g.value {
            geojson::GeometryValue::LineString { coordinates } => vec![coordinates],
            geojson::GeometryValue::MultiLineString { coordinates } => coordinates,
            _ => Vec::new(),
        };
        for l in lines {
            ways.push(
                l.iter()
                    .filter(|p| p.len() >= 2)
                    .map(|p| (p[1], p[0]))
                    .collect(),
            );
        }
    }
    Ok(ways)
}

/// A rail way further than this from the line is another line, not this one's, m.
pub const NEAR_M: f64 = 50.0;

/// How far the fitted line lies from OSM's rail ways.
#[derive(Debug, Clone, Serialize)]
pub struct OsmOffset {
    pub ways: usize,
    /// The share of the line's length with a rail way within [`NEAR_M`].
    pub share_near: f64,
    /// Over that share: the distance to the nearest rail way, m.
    pub rms_m: f64,
    pub p95_m: f64,
    pub max_m: f64,
}

/// A segment of a way in the plane, its two ends (east, north).
type Segment = ((f64, f64), (f64, f64));

/// Cell size of the grid the ways' segments are looked up in, m.
const CELL_M: f64 = NEAR_M;

/// The fitted `line` (in the plane) against `ways` already in the same plane.
pub fn offset(line: &Line, ways: &[Vec<(f64, f64)>]) -> OsmOffset {
    // Every segment in each grid cell its bounding box touches.
    let cell = |e: f64, n: f64| ((e / CELL_M).floor() as i64, (n / CELL_M).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<Segment>> = HashMap::new();
    for w in ways {
        for s in w.windows(2) {
            let (a, b) = (
                cell(s[0].0.min(s[1].0), s[0].1.min(s[1].1)),
                cell(s[0].0.max(s[1].0), s[0].1.max(s[1].1)),
            );
            for i in a.0..=b.0 {
                for j in a.1..=b.1 {
                    grid.entry((i, j)).or_default().push((s[0], s[1]));
                }
            }
        }
    }
    let mut near = Vec::new();
    for v in &line.vertices {
        let (ci, cj) = cell(v.east_m, v.north_m);
        let d = (ci - 1..=ci + 1)
            .flat_map(|i| (cj - 1..=cj + 1).map(move |j| (i, j)))
            .filter_map(|c| grid.get(&c))
            .flatten()
            .map(|&(a, b)| to_segment((v.east_m, v.north_m), a, b))
            .fold(f64::MAX, f64::min);
        if d <= NEAR_M {
            near.push(d);
        }
    }
    near.sort_by(f64::total_cmp);
    let n = near.len();
    OsmOffset {
        ways: ways.len(),
        share_near: n as f64 / line.vertices.len().max(1) as f64,
        rms_m: (near.iter().map(|d| d * d).sum::<f64>() / n.max(1) as f64).sqrt(),
        p95_m: near
            .get(((n as f64 * 0.95).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(0.0),
        max_m: near.last().copied().unwrap_or(0.0),
    }
}

/// Distance from `p` to the segment `a`–`b`.
fn to_segment(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (de, dn) = (b.0 - a.0, b.1 - a.1);
    let len2 = de * de + dn * dn;
    let f = if len2 > 0.0 {
        (((p.0 - a.0) * de + (p.1 - a.1) * dn) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p.0 - a.0 - f * de).hypot(p.1 - a.1 - f * dn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rail_ways_are_read_from_osm_xml_and_other_ways_left_out() {
        let d = std::env::temp_dir().join(format!("railfuse-osm-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("x.osm");
        std::fs::write(
            &p,
            r#"<?xml version="1.0"?><osm version="0.6">
<node id="1" lat="44.65" lon="10.93"/><node id="2" lat="44.66" lon="10.94"/>
<node id="3" lat="44.70" lon="10.90"/>
<way id="10"><nd ref="1"/><nd ref="2"/><tag k="railway" v="rail"/></way>
<way id="11"><nd ref="2"/><nd ref="3"/><tag k="highway" v="primary"/></way>
</osm>"#,
        )
        .unwrap();
        let ways = read_rail(&p).unwrap();
        assert_eq!(ways, vec![vec![(44.65, 10.93), (44.66, 10.94)]]);
        std::fs::write(
            &p,
            r#"<osm><way id="11"><nd ref="2"/><tag k="highway" v="x"/></way></osm>"#,
        )
        .unwrap();
        assert!(read_rail(&p)
            .unwrap_err()
            .to_string()
            .ends_with("no railway=rail way in it"));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn the_offset_is_the_distance_to_the_nearest_way() {
        let line = Line::through(&(0..=100).map(|i| (i as f64, 0.0)).collect::<Vec<_>>());
        let o = offset(
            &line,
            &[
                vec![(-10.0, 1.5), (110.0, 1.5)],
                vec![(0.0, 500.0), (1.0, 500.0)],
            ],
        );
        assert!(
            (o.rms_m - 1.5).abs() < 1e-9 && (o.max_m - 1.5).abs() < 1e-9,
            "{o:?}"
        );
        assert_eq!(o.share_near, 1.0);
    }
}
