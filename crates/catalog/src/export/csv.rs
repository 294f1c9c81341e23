//! CSV: one row per state, every pipeline in one table (its name a column), SI units named
//! in the header.

use std::io::Write;

use super::{ExportPoint, ExportWriter};

pub(super) struct Csv<'w> {
    out: csv::Writer<Box<dyn Write + 'w>>,
    pipeline: String,
    header: bool,
}

const HEADER: [&str; 14] = [
    "pipeline",
    "time",
    "stamp_ns",
    "latitude_deg",
    "longitude_deg",
    "altitude_m",
    "sigma_east_m",
    "sigma_north_m",
    "covariance_en_m2",
    "sigma_major_m",
    "uncertainty",
    "chainage_m",
    "speed_mps",
    "speed_sigma_mps",
];

impl<'w> Csv<'w> {
    pub(super) fn new(out: Box<dyn Write + 'w>) -> Self {
        Self {
            out: csv::Writer::from_writer(out),
            pipeline: String::new(),
            header: false,
        }
    }

    fn header(&mut self) -> std::io::Result<()> {
        if !self.header {
            self.header = true;
            self.out.write_record(HEADER)?;
        }
        Ok(())
    }
}

impl ExportWriter for Csv<'_> {
    fn begin(&mut self, pipeline: &str) -> std::io::Result<()> {
        self.header()?;
        self.pipeline = pipeline.to_owned();
        Ok(())
    }

    fn point(&mut self, p: &ExportPoint) -> std::io::Result<()> {
        self.out.write_record([
            self.pipeline.clone(),
            p.time(),
            p.stamp_ns.to_string(),
            format!("{:.9}", p.geo.latitude_deg),
            format!("{:.9}", p.geo.longitude_deg),
            format!("{:.3}", p.geo.altitude_m),
            format!("{:.4}", p.sigma_east_m()),
            format!("{:.4}", p.sigma_north_m()),
            format!("{:.6}", p.covariance_en_m2()),
            format!("{:.4}", p.sigma_major_m()),
            p.uncertainty_kind().to_owned(),
            format!("{:.3}", p.chainage_m),
            format!("{:.4}", p.speed_mps),
            format!("{:.4}", p.speed_sigma_mps),
        ])?;
        Ok(())
    }

    fn end(&mut self) -> std::io::Result<()> {
        Ok(())
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.header()?;
        self.out.flush()
    }
}
