//! KML 2.2 for Google Earth: a Placemark per pipeline holding a `gx:Track` (its states' times
//! and coordinates, drawn as a line with a time slider) with each state's uncertainty, speed
//! and chainage as `gx:SimpleArrayData` (shown in the elevation profile and the balloon).
//! A track lists every `when` before every `gx:coord` and then the arrays: those are spooled
//! to temporary files while the times are written, so memory stays flat.

use std::fs::File;
use std::io::{BufWriter, Seek, Write};

use super::{xml_escape, ExportPoint, ExportWriter};

/// The per-state values written as arrays, with their names.
const ARRAYS: [&str; 5] = [
    "sigma_east_m",
    "sigma_north_m",
    "sigma_major_m",
    "speed_mps",
    "chainage_m",
];

/// One pipeline's colours (aabbggrr), in turn.
const COLOURS: [&str; 6] = [
    "ff0000ff", "ffff0000", "ff00aa00", "ff00aaff", "ffaa00aa", "ffaaaa00",
];

pub(super) struct Kml<'w> {
    out: Box<dyn Write + 'w>,
    started: bool,
    pipelines: usize,
    /// gx:coord, then each array, spooled for the open track.
    spools: Vec<BufWriter<File>>,
}

impl<'w> Kml<'w> {
    pub(super) fn new(out: Box<dyn Write + 'w>) -> Self {
        Self {
            out,
            started: false,
            pipelines: 0,
            spools: Vec::new(),
        }
    }

    fn start(&mut self) -> std::io::Result<()> {
        if self.started {
            return Ok(());
        }
        self.started = true;
        writeln!(
            self.out,
            r#"<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:gx="http://www.google.com/kml/ext/2.2">
<Document><name>railfuse fused positions</name>"#
        )?;
        // KML's order: a Document's styles before its schemas before its features.
        for (i, colour) in COLOURS.iter().enumerate() {
            writeln!(
                self.out,
                "<Style id=\"p{i}\"><IconStyle><color>{colour}</color><scale>0.5</scale></IconStyle>\
                 <LineStyle><color>{colour}</color><width>3</width></LineStyle></Style>"
            )?;
        }
        writeln!(self.out, "<Schema id=\"fused\" name=\"fused\">")?;
        for name in ARRAYS {
            writeln!(
                self.out,
                "<gx:SimpleArrayField name=\"{name}\" type=\"float\"><displayName>{name}</displayName></gx:SimpleArrayField>"
            )?;
        }
        writeln!(self.out, "</Schema>")?;
        Ok(())
    }
}

impl ExportWriter for Kml<'_> {
    fn begin(&mut self, pipeline: &str) -> std::io::Result<()> {
        self.start()?;
        let style = self.pipelines % COLOURS.len();
        self.pipelines += 1;
        writeln!(
            self.out,
            "<Placemark><name>{}</name><styleUrl>#p{style}</styleUrl><gx:Track><altitudeMode>clampToGround</altitudeMode>",
            xml_escape(pipeline)
        )?;
        self.spools = (0..=ARRAYS.len())
            .map(|_| tempfile::tempfile().map(BufWriter::new))
            .collect::<std::io::Result<_>>()?;
        Ok(())
    }

    fn point(&mut self, p: &ExportPoint) -> std::io::Result<()> {
        writeln!(self.out, "<when>{}</when>", p.time())?;
        writeln!(
            self.spools[0],
            "<gx:coord>{:.9} {:.9} {:.3}</gx:coord>",
            p.geo.longitude_deg, p.geo.latitude_deg, p.geo.altitude_m
        )?;
        let values = [
            p.sigma_east_m(),
            p.sigma_north_m(),
            p.sigma_major_m(),
            p.speed_mps,
            p.chainage_m,
        ];
        for (spool, v) in self.spools[1..].iter_mut().zip(values) {
            writeln!(spool, "<gx:value>{v:.4}</gx:value>")?;
        }
        Ok(())
    }

    fn end(&mut self) -> std::io::Result<()> {
        let mut spools = std::mem::take(&mut self.spools);
        let copy = |spool: BufWriter<File>, out: &mut dyn Write| -> std::io::Result<()> {
            let mut file = spool.into_inner().map_err(|e| e.into_error())?;
            file.rewind()?;
            std::io::copy(&mut file, out)?;
            Ok(())
        };
        let arrays = spools.split_off(1);
        for coords in spools {
            copy(coords, &mut self.out)?;
        }
        writeln!(self.out, "<ExtendedData><SchemaData schemaUrl=\"#fused\">")?;
        for (name, spool) in ARRAYS.iter().zip(arrays) {
            writeln!(self.out, "<gx:SimpleArrayData name=\"{name}\">")?;
            copy(spool, &mut self.out)?;
            writeln!(self.out, "</gx:SimpleArrayData>")?;
        }
        writeln!(
            self.out,
            "</SchemaData></ExtendedData></gx:Track></Placemark>"
        )
    }

    fn finish(&mut self) -> std::io::Result<()> {
        self.start()?;
        writeln!(self.out, "</Document></kml>")?;
        self.out.flush()
    }
}
