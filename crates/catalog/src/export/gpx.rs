//! GPX 1.1: a track per pipeline, a point per state; speed and course in Garmin's
//! TrackPointExtension v2 (which GPS tools read), the uncertainty and chainage in railfuse's
//! own extension namespace.

use std::io::Write;

use super::{xml_escape, ExportPoint, ExportWriter};

pub(super) struct Gpx<'w> {
    out: Box<dyn Write + 'w>,
    started: bool,
}

impl<'w> Gpx<'w> {
    pub(super) fn new(out: Box<dyn Write + 'w>) -> Self {
        Self {
            out,
            started: false,
        }
    }

    fn start(&mut self) -> std::io::Result<()> {
        if !self.started {
            self.started = true;
            writeln!(
                self.out,
                r#"<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.1" creator="railfuse" xmlns="http://www.topografix.com/GPX/1/1" xmlns:gpxtpx="http://www.garmin.com/xmlschemas/TrackPointExtension/v2" xmlns:railfuse="https://railfuse.invalid/gpx/1">"#
            )?;
        }
        Ok(())
    }
}

impl ExportWriter for Gpx<'_> {
    fn begin(&mut self, pipeline: &str) -> std::io::Result<()> {
        self.start()?;
        writeln!(
            self.out,
            "<trk><name>{}</name><src>railfuse fused state</src><trkseg>",
            xml_escape(pipeline)
        )
    }

    fn point(&mut self, p: &ExportPoint) -> std::io::Result<()> {
        let course = p
            .geo
            .heading_rad
            .map(|h| {
                format!(
                    "<gpxtpx:course>{:.2}</gpxtpx:course>",
                    h.to_degrees().rem_euclid(360.0)
                )
            })
            .unwrap_or_default();
        writeln!(
            self.out,
            "<trkpt lat=\"{:.9}\" lon=\"{:.9}\"><ele>{:.3}</ele><time>{}</time><extensions>\
             <gpxtpx:TrackPointExtension><gpxtpx:speed>{:.3}</gpxtpx:speed>{course}</gpxtpx:TrackPointExtension>\
             <railfuse:sigma_east_m>{:.4}</railfuse:sigma_east_m><railfuse:sigma_north_m>{:.4}</railfuse:sigma_north_m>\
             <railfuse:sigma_major_m>{:.4}</railfuse:sigma_major_m><railfuse:uncertainty>{}</railfuse:uncertainty>\
             <railfuse:chainage_m>{:.3}</railfuse:chainage_m><railfuse:speed_sigma_mps>{:.4}</railfuse:speed_sigma_mps>\
             </extensions></trkpt>",
            p.geo.latitude_deg,
            p.geo.longitude_deg,
            p.geo.altitude_m,
            p.time(),
            p.speed_mps.abs(),
            p.sigma_east_m(),
            p.sigma_north_m(),
            p.sigma_major_m(),
            p.uncertainty_kind(),
            p.chainage_m,
            p.speed_sigma_mps,
        )
    }

    fn end(&mut self) -> std::io::Result<()> {
        writeln!(self.out, "</trkseg></trk>")
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.start()?;
        writeln!(self.out, "</gpx>")?;
        self.out.flush()
    }
}
