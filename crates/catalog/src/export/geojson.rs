//! GeoJSON (RFC 7946): a FeatureCollection of one Point feature per state, its time,
//! pipeline and uncertainty as properties (QGIS styles and filters by them; its "points to
//! path" draws the track).

use std::io::Write;

use super::{ExportPoint, ExportWriter};

pub(super) struct GeoJson<'w> {
    out: Box<dyn Write + 'w>,
    pipeline: String,
    features: u64,
}

impl<'w> GeoJson<'w> {
    pub(super) fn new(out: Box<dyn Write + 'w>) -> Self {
        Self {
            out,
            pipeline: String::new(),
            features: 0,
        }
    }
}

impl ExportWriter for GeoJson<'_> {
    fn begin(&mut self, pipeline: &str) -> std::io::Result<()> {
        if self.features == 0 {
            write!(self.out, "{{\"type\":\"FeatureCollection\",\"features\":[")?;
        }
        self.pipeline = serde_json::to_string(pipeline).expect("a string serialises");
        Ok(())
    }

    fn point(&mut self, p: &ExportPoint) -> std::io::Result<()> {
        let sep = if self.features == 0 { "\n" } else { ",\n" };
        self.features += 1;
        let heading = p.geo.heading_rad.map_or("null".to_owned(), |h| {
            format!("{:.3}", h.to_degrees().rem_euclid(360.0))
        });
        write!(
            self.out,
            "{sep}{{\"type\":\"Feature\",\"geometry\":{{\"type\":\"Point\",\"coordinates\":[{:.9},{:.9},{:.3}]}},\
             \"properties\":{{\"pipeline\":{},\"time\":\"{}\",\"stamp_ns\":{},\"sigma_east_m\":{:.4},\
             \"sigma_north_m\":{:.4},\"covariance_en_m2\":{:.6},\"sigma_major_m\":{:.4},\"uncertainty\":\"{}\",\
             \"chainage_m\":{:.3},\"speed_mps\":{:.4},\"speed_sigma_mps\":{:.4},\"heading_deg\":{heading}}}}}",
            p.geo.longitude_deg,
            p.geo.latitude_deg,
            p.geo.altitude_m,
            self.pipeline,
            p.time(),
            p.stamp_ns,
            p.sigma_east_m(),
            p.sigma_north_m(),
            p.covariance_en_m2(),
            p.sigma_major_m(),
            p.uncertainty_kind(),
            p.chainage_m,
            p.speed_mps,
            p.speed_sigma_mps,
        )
    }

    fn end(&mut self) -> std::io::Result<()> {
        Ok(())
    }

    fn finish(&mut self) -> std::io::Result<()> {
        if self.features == 0 && self.pipeline.is_empty() {
            write!(self.out, "{{\"type\":\"FeatureCollection\",\"features\":[")?;
        }
        writeln!(self.out, "\n]}}")?;
        self.out.flush()
    }
}
