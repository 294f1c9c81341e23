//! GPX 1.0 and 1.1: the track a phone app, a Garmin unit or a handheld GNSS logger writes,
//! read point by point into [`GnssFix`] messages on `/gnss/fix`.
//!
//! What is read, of every `trkpt` (and `rtept`; waypoints are places, not a track):
//! `lat`/`lon`, `ele`, `time` (RFC 3339 with any zone offset; no offset is UTC, as GPX
//! says), `hdop`/`vdop`/`pdop`, `sat`, `fix` (`none`, `2d`, `3d`, `dgps`, `pps`), GPX 1.0's
//! `speed` (m/s) and `course` (°), and the same two from the point's `extensions` (Garmin's
//! TrackPointExtension v2 `gpxtpx:speed`/`gpxtpx:course`, OsmAnd's `speed`), where the point
//! has no GPX 1.0 element for them. Several tracks and segments are read in file order; a
//! segment break is a gap (no fix is made across it) and is counted.
//!
//! What a point's uncertainty is, is the reader's choice, never a guess ([`HdopMeaning`]):
//! GPX's `hdop` is a dilution of precision, but most phone apps write Android's or iOS's
//! horizontal accuracy in metres into it.
//!
//! Why quick-xml and not the `gpx` crate: `gpx` reads the whole document into memory (memory
//! grows with the ride) and drops the `extensions` where Garmin and phone apps keep speed and
//! course. Here the document is streamed event by event, each event's bytes are bounded
//! ([`MAX_EVENT`]), nesting is bounded, and a document type that declares entities (the
//! billion-laughs bomb) is refused before anything is expanded: GPX declares none.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use quick_xml::events::{BytesStart, Event};

use super::{accuracy, Converted};
use crate::error::{Error, Result};
use crate::log::{LogWriter, WriterOptions};
use crate::messages::{FixType, GnssFix};
use crate::topics;

/// The longest run of bytes without `<` or `>` (one tag, one text) the reader holds; a
/// longer one is not GPX (a point's longest text is a time stamp).
pub const MAX_EVENT: usize = 64 << 10;
/// The deepest nesting of elements read (GPX's own is 5; extensions add a few).
const MAX_DEPTH: usize = 64;
/// The longest text of an element the reader keeps (a number, a time).
const MAX_TEXT: usize = 256;

/// What a point's `hdop` is.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HdopMeaning {
    /// A dilution of precision, as GPX says: kept as the fix's HDOP; the fix carries no
    /// covariance, so the pipeline's configured GNSS variance applies.
    #[default]
    Dop,
    /// A horizontal accuracy in metres, the radius that holds the position with this
    /// probability (Android's `getAccuracy` is a 68 % radius): the fix's east and north σ is
    /// r / √(−2 ln(1 − p)), the circular normal's; `vdop` is then a vertical accuracy of the
    /// same probability, else the vertical σ is taken as twice the horizontal.
    Metres { confidence: f64 },
}

impl std::str::FromStr for HdopMeaning {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = || format!("'{s}': use dop, metres (a 68 % radius) or metres:PERCENT");
        match s.split_once(':') {
            None if s == "dop" => Ok(Self::Dop),
            None if s == "metres" || s == "meters" => Ok(Self::Metres { confidence: 0.68 }),
            Some(("metres" | "meters", p)) => {
                let p: f64 = p.trim_end_matches('%').parse().map_err(|_| bad())?;
                if !(p > 0.0 && p < 100.0) {
                    return Err(format!(
                        "'{s}': the probability is a percentage in (0, 100)"
                    ));
                }
                Ok(Self::Metres {
                    confidence: p / 100.0,
                })
            }
            _ => Err(bad()),
        }
    }
}

/// What a point's `ele` is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Elevation {
    /// Above mean sea level, as Garmin units and most apps write it: the fix's MSL height.
    #[default]
    Msl,
    /// Above the WGS-84 ellipsoid (a receiver's raw height): the fix's ellipsoidal height.
    Ellipsoid,
}

impl std::str::FromStr for Elevation {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "msl" => Ok(Self::Msl),
            "ellipsoid" => Ok(Self::Ellipsoid),
            _ => Err(format!("'{s}': use msl or ellipsoid")),
        }
    }
}

/// How a GPX file's points become fixes.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct GpxOptions {
    pub hdop: HdopMeaning,
    pub elevation: Elevation,
}

/// One point of the track as read, in file order; [`Point::fix`] makes it a fix.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Point {
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    pub ele_m: Option<f64>,
    pub time: Option<String>,
    pub hdop: Option<f64>,
    pub vdop: Option<f64>,
    pub satellites: Option<f64>,
    pub fix: Option<String>,
    /// GPX 1.0's `speed` (m/s) and `course` (°), else the point's extensions'.
    pub speed_mps: Option<f64>,
    pub course_deg: Option<f64>,
    ext_speed: Option<f64>,
    ext_course: Option<f64>,
    /// 1-based: the track and its segment (a route is a track of its own).
    pub track: u32,
    pub segment: u32,
    /// The line the point's element opens on.
    pub line: u64,
    /// Why a field did not read, where one did not.
    pub fault: Option<String>,
}

/// Why a point is not a fix: the reason it is counted under, and the detail.
#[derive(Debug, Clone, PartialEq)]
pub struct Unusable {
    pub reason: &'static str,
    pub detail: String,
}

impl Point {
    /// The point as a fix, or why it cannot be one.
    pub fn to_fix(&self, options: &GpxOptions) -> std::result::Result<GnssFix, Unusable> {
        let unusable = |reason, detail: String| Unusable { reason, detail };
        if let Some(f) = &self.fault {
            return Err(unusable("a field that does not read", f.clone()));
        }
        let Some(time) = &self.time else {
            return Err(unusable("a point without <time>", String::new()));
        };
        let stamp_ns = parse_time(time).map_err(|e| unusable("a <time> that does not read", e))?;
        let fix_type = match self.fix.as_deref() {
            None | Some("2d" | "3d" | "pps") => FixType::Single,
            Some("dgps") => FixType::Dgps,
            Some("none") => FixType::None,
            Some(other) => {
                return Err(unusable(
                    "a <fix> that is not none, 2d, 3d, dgps or pps",
                    format!("'{other}'"),
                ))
            }
        };
        let position = match (self.latitude_deg, self.longitude_deg) {
            (Some(lat), Some(lon)) if lat.abs() <= 90.0 && lon.abs() <= 180.0 => (lat, lon),
            (lat, lon) => {
                return Err(unusable(
                    "lat/lon missing or off the globe",
                    format!("lat {lat:?} lon {lon:?}"),
                ))
            }
        };
        let has = fix_type.has_position();
        let (hdop, covariance) = match options.hdop {
            HdopMeaning::Dop => (self.hdop, None),
            HdopMeaning::Metres { confidence } => (None, self.accuracy_covariance(confidence)),
        };
        let (altitude_m, altitude_msl_m) = match options.elevation {
            Elevation::Msl => (None, self.ele_m),
            Elevation::Ellipsoid => (self.ele_m, None),
        };
        Ok(GnssFix {
            stamp_ns,
            fix_type,
            satellites: self.satellites.map_or(0, |s| s.clamp(0.0, 255.0) as u8),
            hdop,
            latitude_deg: has.then_some(position.0),
            longitude_deg: has.then_some(position.1),
            altitude_m: altitude_m.filter(|_| has),
            altitude_msl_m: altitude_msl_m.filter(|_| has),
            position_covariance_enu_m2: covariance.filter(|_| has),
            speed_mps: self.speed_mps.or(self.ext_speed).filter(|v| *v >= 0.0),
            course_rad: self
                .course_deg
                .or(self.ext_course)
                .map(|c| c.rem_euclid(360.0).to_radians()),
        })
    }

    /// The east/north/up covariance of an `hdop` (and `vdop`) that are accuracies in metres.
    fn accuracy_covariance(&self, confidence: f64) -> Option<[f64; 9]> {
        let radius = self.hdop.filter(|h| *h > 0.0)?;
        Some(accuracy::covariance_enu(
            radius,
            self.vdop.filter(|v| *v > 0.0),
            Some(confidence),
        ))
    }
}

/// An ISO 8601 / RFC 3339 time in ns since the Unix epoch: any zone offset, `Z`, or none
/// (UTC, as GPX says).
pub fn parse_time(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let timestamp = match t.parse::<jiff::Timestamp>() {
        Ok(ts) => ts,
        Err(_) => t
            .parse::<jiff::civil::DateTime>()
            .and_then(|dt| dt.to_zoned(jiff::tz::TimeZone::UTC))
            .map(|z| z.timestamp())
            .map_err(|_| format!("'{t}' is not an ISO 8601 time"))?,
    };
    u64::try_from(timestamp.as_nanosecond()).map_err(|_| format!("'{t}' is before 1970"))
}

/// Counts lines as they pass and refuses a run of more than [`MAX_EVENT`] bytes without `<`
/// or `>`: no event quick-xml buffers can then grow without bound.
struct Guard<R> {
    inner: R,
    lines: u64,
    run: usize,
    /// A run went past the bound: every further read fails.
    flooded: bool,
}

impl<R: BufRead> Read for Guard<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let available = self.fill_buf()?;
        let n = available.len().min(out.len());
        out[..n].copy_from_slice(&available[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl<R: BufRead> BufRead for Guard<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        if self.flooded {
            return Err(std::io::Error::other(format!(
                "more than {} KiB without markup: not GPX",
                MAX_EVENT >> 10
            )));
        }
        self.inner.fill_buf()
    }
    fn consume(&mut self, n: usize) {
        if let Ok(bytes) = self.inner.fill_buf() {
            for &b in &bytes[..n.min(bytes.len())] {
                match b {
                    b'<' | b'>' => self.run = 0,
                    b'\n' => {
                        self.lines += 1;
                        self.run += 1;
                    }
                    _ => self.run += 1,
                }
                self.flooded |= self.run > MAX_EVENT;
            }
        }
        self.inner.consume(n);
    }
}

/// A GPX document read point by point.
pub struct GpxReader<R: BufRead> {
    xml: quick_xml::Reader<Guard<R>>,
    path: PathBuf,
    buf: Vec<u8>,
    /// Local names of the open elements.
    stack: Vec<String>,
    text: String,
    point: Option<Point>,
    track: u32,
    segment: u32,
    /// Segment breaks seen (a new segment or track after the first that held points).
    pub breaks: u64,
    /// Points in the current segment.
    in_segment: u64,
    root_seen: bool,
    /// The document's `version` attribute.
    pub version: Option<String>,
    /// Where the document stops being well-formed or is cut off (the points before are read).
    pub damage: Option<String>,
    done: bool,
}

impl GpxReader<BufReader<std::fs::File>> {
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        Ok(Self::new(BufReader::with_capacity(64 << 10, file), path))
    }
}

impl<R: BufRead> GpxReader<R> {
    pub fn new(reader: R, path: &Path) -> Self {
        let guard = Guard {
            inner: reader,
            lines: 0,
            run: 0,
            flooded: false,
        };
        let mut xml = quick_xml::Reader::from_reader(guard);
        xml.config_mut().trim_text(true);
        Self {
            xml,
            path: path.to_owned(),
            buf: Vec::new(),
            stack: Vec::new(),
            text: String::new(),
            point: None,
            track: 0,
            segment: 0,
            breaks: 0,
            in_segment: 0,
            root_seen: false,
            version: None,
            damage: None,
            done: false,
        }
    }

    /// The line the reader is on (1-based).
    fn line(&self) -> u64 {
        self.xml.get_ref().lines + 1
    }

    fn fault(&self, cause: impl std::fmt::Display) -> Error {
        Error::run(&self.path, format!("line {}: {cause}", self.line()))
    }

    /// The next point, None at the document's end.
    pub fn next_point(&mut self) -> Result<Option<Point>> {
        while !self.done {
            if let Some(point) = self.step()? {
                return Ok(Some(point));
            }
        }
        Ok(None)
    }

    /// Reads one event; a point where it ends one.
    fn step(&mut self) -> Result<Option<Point>> {
        self.buf.clear();
        let event = match self.xml.read_event_into(&mut self.buf) {
            Ok(e) => e.into_owned(),
            Err(quick_xml::Error::Io(e)) => return Err(self.fault(e)),
            Err(e) if self.root_seen => {
                self.damage = Some(format!("line {}: not well-formed XML: {e}", self.line()));
                self.done = true;
                return Ok(None);
            }
            Err(e) => return Err(self.fault(format!("not well-formed XML: {e}"))),
        };
        match event {
            Event::DocType(d) => {
                if String::from_utf8_lossy(&d)
                    .to_ascii_uppercase()
                    .contains("<!ENTITY")
                {
                    return Err(self.fault(
                        "the document type declares entities (refused: GPX declares none, and \
                         an entity expansion can make a small file gigabytes)",
                    ));
                }
            }
            Event::Start(e) => self.open_element(&e)?,
            Event::Empty(e) => {
                self.open_element(&e)?;
                return Ok(self.close());
            }
            Event::End(_) => return Ok(self.close()),
            Event::Text(t) => {
                let t = t
                    .decode()
                    .map_err(|e| self.fault(format!("text that is not UTF-8: {e}")))?;
                self.push_text(&t);
            }
            Event::CData(t) => {
                let t = String::from_utf8_lossy(&t).into_owned();
                self.push_text(&t);
            }
            Event::GeneralRef(r) => {
                let c = match (r.resolve_char_ref(), &*r) {
                    (Ok(Some(c)), _) => c,
                    (_, b"amp") => '&',
                    (_, b"lt") => '<',
                    (_, b"gt") => '>',
                    (_, b"quot") => '"',
                    (_, b"apos") => '\'',
                    (_, other) => {
                        return Err(self.fault(format!(
                            "entity &{}; is not defined (GPX uses none)",
                            String::from_utf8_lossy(other)
                        )))
                    }
                };
                self.push_text(c.encode_utf8(&mut [0; 4]));
            }
            Event::Eof => {
                self.done = true;
                if !self.root_seen {
                    return Err(Error::run(&self.path, "no <gpx> element: not a GPX file"));
                }
                if !self.stack.is_empty() {
                    self.damage = Some(format!(
                        "line {}: the file ends inside <{}>: cut off",
                        self.line(),
                        self.stack.join("><")
                    ));
                }
            }
            Event::Decl(_) | Event::PI(_) | Event::Comment(_) => {}
        }
        Ok(None)
    }

    fn push_text(&mut self, t: &str) {
        if self.text.len() + t.len() <= MAX_TEXT {
            self.text.push_str(t);
        } else {
            // Longer than any GPX value: the field then reads as not a number, and says so.
            self.text = "…".into();
        }
    }

    /// An element opens.
    fn open_element(&mut self, e: &BytesStart<'_>) -> Result<()> {
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        if !self.root_seen {
            if name != "gpx" {
                return Err(self.fault(format!(
                    "the document is <{name}>, not <gpx>: not a GPX file"
                )));
            }
            self.root_seen = true;
            self.version = attribute(e, b"version");
        }
        if self.stack.len() >= MAX_DEPTH {
            return Err(self.fault(format!("elements nested deeper than {MAX_DEPTH}")));
        }
        match name.as_str() {
            // A route is one segment of a track of its own.
            "trk" | "rte" => {
                self.new_segment();
                self.track += 1;
                self.segment = u32::from(name == "rte");
            }
            "trkseg" => {
                self.new_segment();
                self.segment += 1;
            }
            "trkpt" | "rtept" if self.point.is_none() => {
                let number = |key: &[u8]| attribute(e, key).and_then(|v| v.trim().parse().ok());
                self.point = Some(Point {
                    latitude_deg: number(b"lat"),
                    longitude_deg: number(b"lon"),
                    track: self.track.max(1),
                    segment: self.segment.max(1),
                    line: self.line(),
                    ..Point::default()
                });
            }
            _ => {}
        }
        self.stack.push(name);
        self.text.clear();
        Ok(())
    }

    /// A segment (or track) begins: a break where the one before held points.
    fn new_segment(&mut self) {
        if self.in_segment > 0 {
            self.breaks += 1;
        }
        self.in_segment = 0;
    }

    /// The innermost element closes: its text is a point's field, or the point ends.
    fn close(&mut self) -> Option<Point> {
        let name = self.stack.pop()?;
        let text = std::mem::take(&mut self.text);
        if name == "trkpt" || name == "rtept" {
            self.in_segment += 1;
            return self.point.take();
        }
        let point = self.point.as_mut()?;
        // A point's own children are its fields; in its extensions, any speed or course.
        let direct = self
            .stack
            .last()
            .is_some_and(|p| p == "trkpt" || p == "rtept");
        let in_extensions = self.stack.iter().any(|n| n == "extensions");
        let mut number = |field: &str| -> Option<f64> {
            match text.trim().parse::<f64>() {
                Ok(v) if v.is_finite() => Some(v),
                _ => {
                    let why = format!("<{field}> '{}' is not a number", text.trim());
                    point.fault.get_or_insert(why);
                    None
                }
            }
        };
        match (name.as_str(), direct, in_extensions) {
            ("ele", true, _) => point.ele_m = number("ele"),
            ("time", true, _) => point.time = Some(text.trim().to_owned()),
            ("hdop", true, _) => point.hdop = number("hdop"),
            ("vdop", true, _) => point.vdop = number("vdop"),
            ("sat", true, _) => point.satellites = number("sat"),
            ("fix", true, _) => point.fix = Some(text.trim().to_owned()),
            ("speed", true, _) => point.speed_mps = number("speed"),
            ("course", true, _) => point.course_deg = number("course"),
            ("speed", false, true) => point.ext_speed = number("speed"),
            ("course", false, true) => point.ext_course = number("course"),
            _ => {}
        }
        None
    }
}

fn attribute(e: &BytesStart<'_>, key: &[u8]) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.local_name().as_ref() == key)
        .and_then(|a| a.unescape_value().ok().map(|v| v.into_owned()))
}

/// Converts a GPX file to MCAP at `output`, streaming: every usable point a fix on
/// `/gnss/fix`, in time order (a point not after the one before it is counted, not written).
/// A file with points but no usable time is refused: a track without times is not a run.
pub fn convert(
    input: &Path,
    output: &Path,
    options: &GpxOptions,
    writer: &WriterOptions,
) -> Result<Converted> {
    let mut reader = GpxReader::open(input)?;
    let mut writer = LogWriter::create_with(output, writer)?;
    let channel = writer.add_channel::<GnssFix>(topics::GNSS_FIX)?;
    let mut report = Converted::default();
    let mut last: Option<u64> = None;
    while let Some(point) = reader.next_point()? {
        report.rows += 1;
        let fix = match point.to_fix(options) {
            Ok(f) => f,
            Err(u) => {
                report.skip(u.reason, format!("line {}: {}", point.line, u.detail));
                continue;
            }
        };
        match last {
            Some(t) if fix.stamp_ns == t => {
                report.skip(
                    "a point at the time of the one before",
                    format!("line {}", point.line),
                );
                continue;
            }
            Some(t) if fix.stamp_ns < t => {
                report.skip(
                    "a point earlier than the one before",
                    format!("line {}", point.line),
                );
                continue;
            }
            _ => {}
        }
        last = Some(fix.stamp_ns);
        writer.write(channel, fix.stamp_ns, &fix)?;
        report.count(topics::GNSS_FIX);
    }
    report.gaps = reader.breaks;
    report.damage = reader.damage.take();
    if report.messages == 0 {
        let why = match (&report.damage, report.rows) {
            (Some(d), _) => d.clone(),
            (None, 0) => "no track or route point".to_owned(),
            (None, n) => format!("none of its {n} points is a fix: {}", report.reasons()),
        };
        return Err(Error::run(input, why));
    }
    writer.finish()?;
    Ok(report)
}

#[cfg(test)]
mod tests;
