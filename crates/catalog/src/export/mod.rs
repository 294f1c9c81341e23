//! A pipeline's fused positions written for people who do not run railfuse: GPX (any GPS
//! tool), KML (Google Earth), GeoJSON (QGIS, web maps) and CSV (a spreadsheet, pandas). Each
//! state keeps its time and its uncertainty: the east and north σ, their covariance and the
//! error ellipse's 1σ semi-major axis, with the kind of uncertainty it is (a 2-D pipeline's
//! own, or an along-track pipeline's variance along the track, nothing known across it).
//!
//! Writers are streaming: one point at a time, pipeline after pipeline; KML, which lists a
//! track's times before its coordinates, spools the latter to temporary files.

mod csv;
mod geojson;
mod gpx;
mod kml;

use std::io::Write;
use std::path::Path;

use crate::messages::FusedGeodetic;

/// One fused state, placed on the globe.
#[derive(Debug, Clone, Copy)]
pub struct ExportPoint {
    pub stamp_ns: u64,
    pub geo: FusedGeodetic,
    pub chainage_m: f64,
    pub speed_mps: f64,
    /// The speed's σ.
    pub speed_sigma_mps: f64,
}

impl ExportPoint {
    pub fn sigma_east_m(&self) -> f64 {
        self.geo.covariance_enu_m2[0].max(0.0).sqrt()
    }
    pub fn sigma_north_m(&self) -> f64 {
        self.geo.covariance_enu_m2[4].max(0.0).sqrt()
    }
    pub fn covariance_en_m2(&self) -> f64 {
        self.geo.covariance_enu_m2[1]
    }
    /// The 1σ error ellipse's semi-major axis: the root of the east/north covariance's larger
    /// eigenvalue.
    pub fn sigma_major_m(&self) -> f64 {
        let c = &self.geo.covariance_enu_m2;
        let (a, b, d) = (c[0], c[1], c[4]);
        ((a + d) / 2.0 + ((a - d) / 2.0).hypot(b)).max(0.0).sqrt()
    }
    /// What the uncertainty is: `plane` (a 2-D pipeline's own) or `along_track`.
    pub fn uncertainty_kind(&self) -> &'static str {
        match self.geo.covariance_type {
            3 => "plane",
            _ => "along_track",
        }
    }
    /// The time as RFC 3339 UTC to the millisecond.
    pub fn time(&self) -> String {
        rfc3339_ms(self.stamp_ns)
    }
}

/// A time in ns since the epoch as RFC 3339 UTC to the millisecond: `2021-07-26T04:40:01.250Z`.
pub fn rfc3339_ms(stamp_ns: u64) -> String {
    let (s, ms) = (stamp_ns / 1_000_000_000, (stamp_ns / 1_000_000) % 1000);
    let t = jiff::Timestamp::from_second(s as i64).unwrap_or(jiff::Timestamp::UNIX_EPOCH);
    format!("{}.{ms:03}Z", t.strftime("%Y-%m-%dT%H:%M:%S"))
}

/// The formats, told from the output's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    Gpx,
    Kml,
    GeoJson,
    Csv,
}

impl ExportFormat {
    pub fn of_name(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "gpx" => Some(Self::Gpx),
            "kml" => Some(Self::Kml),
            "geojson" | "json" => Some(Self::GeoJson),
            "csv" => Some(Self::Csv),
            _ => None,
        }
    }

    /// A writer of this format onto `out`.
    pub fn writer<'w>(self, out: Box<dyn Write + 'w>) -> Box<dyn ExportWriter + 'w> {
        match self {
            Self::Gpx => Box::new(gpx::Gpx::new(out)),
            Self::Kml => Box::new(kml::Kml::new(out)),
            Self::GeoJson => Box::new(geojson::GeoJson::new(out)),
            Self::Csv => Box::new(csv::Csv::new(out)),
        }
    }
}

/// A format's writer: a document, then each pipeline's points in time order.
pub trait ExportWriter {
    fn begin(&mut self, pipeline: &str) -> std::io::Result<()>;
    fn point(&mut self, p: &ExportPoint) -> std::io::Result<()>;
    fn end(&mut self) -> std::io::Result<()>;
    /// Closes the document and flushes it.
    fn finish(&mut self) -> std::io::Result<()>;
}

/// Text for XML content or attributes.
fn xml_escape(s: &str) -> std::borrow::Cow<'_, str> {
    quick_xml::escape::escape(s)
}

#[cfg(test)]
mod tests;
