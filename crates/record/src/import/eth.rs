//! The ETH-PBL "Railway-Precise-Localization" on-board node logs (ETR103 runs between Modena
//! and Formigine, 2022): one CSV line per record, `TIMESTAMP,TYPE,DATA`, with `TIMESTAMP`
//! `[h]:mm:ss.ffffff` on the node's clock since start-up.
//!
//! | TYPE | DATA | becomes |
//! |---|---|---|
//! | `I` | 12 bytes hex: gyro x, y, z then accel x, y, z, int16 | `/imu` (`Imu`, SI units) |
//! | `U` | one UBX frame as hex | NAV-PVT (+ NAV-COV of the same epoch) → `/gnss/fix` |
//! | `N` | an NMEA sentence | in a log without timed NAV-PVT: one fix per cycle → `/gnss/fix` |
//! | `BRK` | `RTCM CONNECTED` / `SARA DISCONNECTED` | `/events` correction link up / down |
//! | `ARR`, `DEP` | station name | `/events` station arrival / departure |
//!
//! IMU scale factors from the ASM330LHH datasheet at the node's full scales: ±125 dps at
//! 4.37 mdps/LSB, ±2 g at 0.061 mg/LSB. The int16 words are little-endian: the dataset's own
//! description says big-endian, but only little-endian gives the 1 g of gravity on the z axis
//! of a node lying on the cab floor (≈ 1.013 g in every sample), so that is what is decoded.
//!
//! Time: GNSS solutions carry UTC, which becomes their sensor time. The node clock drifts
//! about 1 % against it; every other record is put on UTC by the offset between the node
//! clock and the first NAV-PVT with a valid time (found in a first pass over the file), so
//! all channels share one time base. `log_time` is the node-clock time of the line on that
//! same base.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use railfuse_catalog::log::{ChannelId, LogWriter};
use railfuse_catalog::messages::{ChannelMessage, Event, EventKind, GnssFix, Imu};
use railfuse_catalog::{topics, Error, Result};

use super::{read_line_bounded, ImportReport};
use crate::decode::nmea::{self, Decoded, FixAssembler};
use crate::decode::ubx::{self, hex_into, NavCov, NavPvt, PvtCovPairing};

/// Why an NMEA line of a log with NAV-PVT solutions was not decoded.
const NMEA_BESIDE_PVT: &str =
    "NMEA sentence beside UBX NAV-PVT (the same receiver's solutions; NAV-PVT used)";

const GYRO_RADPS_PER_LSB: f64 = 4.37e-3 * std::f64::consts::PI / 180.0;
const ACCEL_MPS2_PER_LSB: f64 = 0.061e-3 * 9.806_65;

/// `[h]:mm:ss.ffffff` → nanoseconds on the node clock.
fn board_ns(t: &str) -> Option<u64> {
    let mut parts = t.split(':');
    let (h, m, s) = (parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() {
        return None;
    }
    let (h, m): (u64, u64) = (h.parse().ok()?, m.parse().ok()?);
    let (whole, frac) = s.split_once('.').unwrap_or((s, "0"));
    let whole: u64 = whole.parse().ok()?;
    if m > 59 || whole > 59 || frac.len() > 9 || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let frac_ns: u64 = format!("{frac:0<9}").parse().ok()?;
    Some(((h * 60 + m) * 60 + whole) * 1_000_000_000 + frac_ns)
}

fn open(path: &Path) -> Result<BufReader<File>> {
    Ok(BufReader::with_capacity(
        1 << 16,
        File::open(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?,
    ))
}

/// First pass: node-clock time minus UTC of the first NAV-PVT with a valid time.
fn utc_offset(path: &Path) -> Result<Option<i128>> {
    let mut r = open(path)?;
    let mut line = Vec::new();
    let mut bytes = Vec::new();
    while let Some(ok) = read_line_bounded(&mut r, &mut line).map_err(|source| Error::Io {
        path: path.to_owned(),
        source,
    })? {
        if !ok {
            continue;
        }
        let Ok(text) = std::str::from_utf8(&line) else {
            continue;
        };
        let mut f = text.splitn(3, ',');
        let (Some(t), Some("U"), Some(data)) = (f.next(), f.next(), f.next()) else {
            continue;
        };
        let (Some(board), true) = (board_ns(t), hex_into(data, &mut bytes)) else {
            continue;
        };
        if let Ok((frame, _)) = ubx::parse_frame(&bytes) {
            if let Ok(pvt) = NavPvt::decode(&frame) {
                if let Some(utc) = pvt.utc_ns {
                    return Ok(Some(utc as i128 - board as i128));
                }
            }
        }
    }
    Ok(None)
}

/// An import in progress: the output channels, the report, and what decoding carries from
/// one line to the next.
struct EthImport {
    writer: LogWriter,
    imu: ChannelId,
    gnss: ChannelId,
    events: ChannelId,
    report: ImportReport,
    /// The IMU's sensor id (the node's serial number in it).
    imu_id: String,
    /// Node clock to UTC, when the file has a NAV-PVT with a valid time.
    offset: Option<i128>,
    nmea: FixAssembler,
    /// A NAV-PVT waits for the NAV-COV of its epoch (the receiver sends it right after).
    pairing: PvtCovPairing,
    /// The node clock of the last line: the time of a solution left waiting at the end.
    last_now: Option<u64>,
    bytes: Vec<u8>,
}

impl EthImport {
    fn write<M: ChannelMessage>(
        &mut self,
        channel: ChannelId,
        topic: &str,
        log_time: u64,
        m: &M,
    ) -> Result<()> {
        self.writer.write(channel, log_time, m)?;
        self.report.messages += 1;
        *self.report.per_topic.entry(topic.to_owned()).or_insert(0) += 1;
        Ok(())
    }

    fn fix(&mut self, now: u64, fix: &GnssFix) -> Result<()> {
        self.write(self.gnss, topics::GNSS_FIX, now, fix)
    }

    /// Line `n`: `TIME,KIND,DATA`.
    fn line(&mut self, n: u64, text: &str) -> Result<()> {
        let mut f = text.splitn(3, ',');
        let (t, kind, data) = (
            f.next().unwrap_or(""),
            f.next().unwrap_or(""),
            f.next().unwrap_or(""),
        );
        let Some(board) = board_ns(t) else {
            self.report.skip(n, "bad timestamp", t);
            return Ok(());
        };
        let now = self
            .offset
            .map_or(board, |o| (board as i128 + o).max(0) as u64);
        self.last_now = Some(now);
        match kind {
            "I" => self.imu_sample(n, now, data),
            "U" => self.ubx_frame(n, now, data),
            "N" => self.nmea_sentence(n, now, data),
            "BRK" | "ARR" | "DEP" => self.event(now, kind, data),
            other => {
                self.report.skip(n, "unknown line type", other);
                Ok(())
            }
        }
    }

    /// `I`: six little-endian i16 (gyro x, y, z, then accelerometer x, y, z) in hex.
    fn imu_sample(&mut self, n: u64, now: u64, data: &str) -> Result<()> {
        if data.len() != 24 || !hex_into(data, &mut self.bytes) {
            self.report.skip(n, "bad IMU sample", data);
            return Ok(());
        }
        let b = &self.bytes;
        let w = |i: usize| i16::from_le_bytes([b[2 * i], b[2 * i + 1]]) as f64;
        let m = Imu {
            stamp_ns: now,
            sensor_id: self.imu_id.clone(),
            angular_rate_radps: [
                w(0) * GYRO_RADPS_PER_LSB,
                w(1) * GYRO_RADPS_PER_LSB,
                w(2) * GYRO_RADPS_PER_LSB,
            ],
            specific_force_mps2: [
                w(3) * ACCEL_MPS2_PER_LSB,
                w(4) * ACCEL_MPS2_PER_LSB,
                w(5) * ACCEL_MPS2_PER_LSB,
            ],
            // The sensor's own counts: they travel as counts again in protobuf.
            accel_lsb_mps2: Some(ACCEL_MPS2_PER_LSB),
            gyro_lsb_radps: Some(GYRO_RADPS_PER_LSB),
        };
        self.write(self.imu, topics::IMU, now, &m)
    }

    /// `U`: one UBX frame in hex; NAV-PVT and NAV-COV make fixes.
    fn ubx_frame(&mut self, n: u64, now: u64, data: &str) -> Result<()> {
        if !hex_into(data, &mut self.bytes) {
            self.report.skip(n, "UBX frame not hex", data);
            return Ok(());
        }
        let bytes = std::mem::take(&mut self.bytes);
        let result = self.ubx_bytes(n, now, data, &bytes);
        self.bytes = bytes;
        result
    }

    fn ubx_bytes(&mut self, n: u64, now: u64, data: &str, bytes: &[u8]) -> Result<()> {
        let frame = match ubx::parse_frame(bytes) {
            Ok((frame, used)) if used == bytes.len() => frame,
            Ok(_) => {
                self.report.skip(n, "UBX trailing bytes", data);
                return Ok(());
            }
            Err(e) => {
                self.report.skip(n, "UBX frame rejected", e);
                return Ok(());
            }
        };
        match (frame.class, frame.id) {
            NavPvt::CLASS_ID => match NavPvt::decode(&frame) {
                Ok(pvt) => {
                    if let Some((prev, cov)) = self.pairing.pvt(pvt) {
                        self.fix(now, &prev.to_fix(prev.utc_ns.unwrap_or(now), cov))?;
                    }
                }
                Err(e) => self.report.skip(n, "UBX NAV-PVT rejected", e),
            },
            NavCov::CLASS_ID => match NavCov::decode(&frame) {
                Ok(cov) => match self.pairing.cov(&cov) {
                    Some((pvt, cov)) => {
                        self.fix(now, &pvt.to_fix(pvt.utc_ns.unwrap_or(now), cov))?;
                    }
                    None => self
                        .report
                        .skip(n, "UBX NAV-COV without its NAV-PVT", cov.itow_ms),
                },
                Err(e) => self.report.skip(n, "UBX NAV-COV rejected", e),
            },
            (0x05, _) => self.count("UBX ACK/NAK (not data)".into()),
            (c, i) => self.count(format!("UBX {c:02x}/{i:02x} (not decoded)")),
        }
        Ok(())
    }

    /// `N`: one NMEA sentence. The node's receiver also logs UBX NAV-PVT: where the log has a
    /// timed one, its NMEA sentences are the same solutions again and make no second fix.
    /// Without one the node clock is not on UTC, so fixes take their date from RMC or ZDA.
    fn nmea_sentence(&mut self, n: u64, now: u64, data: &str) -> Result<()> {
        if self.offset.is_some() {
            self.count(NMEA_BESIDE_PVT.into());
            return Ok(());
        }
        match nmea::parse(data).and_then(|s| {
            if s.junk > 0 {
                self.count(nmea::JUNK_REASON.into());
            }
            self.nmea.feed(&s, None)
        }) {
            Ok(Decoded::Used) => {}
            Ok(Decoded::Skipped) => self.count(Decoded::SKIPPED_REASON.into()),
            Err(e) => self.report.skip(n, e.reason(), e),
        }
        while let Some(fix) = self.nmea.next_fix() {
            self.fix(now, &fix)?;
        }
        Ok(())
    }

    /// `BRK` (correction link and operator notes), `ARR`, `DEP`: events.
    fn event(&mut self, now: u64, kind: &str, data: &str) -> Result<()> {
        let kind = match (kind, data.trim()) {
            ("ARR", _) => EventKind::StationArrival,
            ("DEP", _) => EventKind::StationDeparture,
            (_, d) if d.contains("CONNECTED") && !d.contains("DISCONNECTED") => {
                EventKind::CorrectionLinkUp
            }
            (_, d) if d.contains("DISCONNECTED") => EventKind::CorrectionLinkDown,
            _ => EventKind::OperatorNote,
        };
        let e = Event {
            stamp_ns: now,
            kind,
            text: data.trim().to_owned(),
        };
        self.write(self.events, topics::EVENTS, now, &e)
    }

    /// A line of a kind not imported, counted.
    fn count(&mut self, what: String) {
        *self.report.skipped.entry(what).or_insert(0) += 1;
    }
}

/// Imports one node log into a railfuse MCAP log.
pub fn import(input: &Path, output: &Path) -> Result<ImportReport> {
    import_with_progress(input, output, &|_| {})
}

/// [`import`], telling `progress` the bytes of the input read so far.
pub fn import_with_progress(
    input: &Path,
    output: &Path,
    progress: &dyn Fn(u64),
) -> Result<ImportReport> {
    let offset = utc_offset(input)?;
    let time_base = match offset {
        Some(_) => {
            "UTC, from the first NAV-PVT with a valid time; other records by their \
                    node-clock offset to it"
        }
        None => "node clock since start-up (no NAV-PVT with a valid time in the file)",
    };
    let stem = input
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("eth")
        .to_owned();
    let node = stem
        .split('_')
        .find(|p| p.starts_with("SN"))
        .unwrap_or("SN?")
        .to_owned();
    let mut writer = LogWriter::create(output)?;
    let mut im = EthImport {
        imu: writer.add_channel::<Imu>(topics::IMU)?,
        gnss: writer.add_channel::<GnssFix>(topics::GNSS_FIX)?,
        events: writer.add_channel::<Event>(topics::EVENTS)?,
        writer,
        report: ImportReport {
            input: input.to_owned(),
            output: output.to_owned(),
            format: "eth".into(),
            time_base: time_base.into(),
            ..Default::default()
        },
        imu_id: format!("asm330lhh-{node}"),
        offset,
        nmea: FixAssembler::default(),
        pairing: PvtCovPairing::default(),
        last_now: None,
        bytes: Vec::new(),
    };

    im.read(input, progress)?;
    im.finish_cycles()?;
    let run = run_metadata(input, &stem, node, &im.report.time_base);
    im.writer.write_metadata(topics::metadata::RUN, run)?;
    im.writer.finish()?;
    Ok(im.report)
}

impl EthImport {
    /// Every line of the file, each read within a bound; a line too long or not text is
    /// skipped and counted.
    fn read(&mut self, input: &Path, progress: &dyn Fn(u64)) -> Result<()> {
        let mut r = open(input)?;
        let mut line = Vec::new();
        let (mut n, mut consumed) = (0u64, 0u64);
        let io = |source| Error::Io {
            path: input.to_owned(),
            source,
        };
        while let Some(ok) = read_line_bounded(&mut r, &mut line).map_err(io)? {
            n += 1;
            self.report.lines += 1;
            consumed += line.len() as u64 + 1;
            if n.is_multiple_of(4096) {
                progress(consumed);
            }
            if !ok {
                let limit = format!("over {} bytes", super::MAX_LINE);
                self.report.skip(n, "line too long", limit);
                continue;
            }
            let Ok(text) = std::str::from_utf8(&line) else {
                self.report.skip(n, "not UTF-8 text", "binary bytes");
                continue;
            };
            if !text.trim().is_empty() {
                self.line(n, text)?;
            }
        }
        Ok(())
    }

    /// The last PVT's fix, and the last NMEA reporting cycle, which ends with the file.
    fn finish_cycles(&mut self) -> Result<()> {
        if let (Some((pvt, cov)), Some(now)) = (self.pairing.finish(), self.last_now) {
            self.fix(now, &pvt.to_fix(pvt.utc_ns.unwrap_or(now), cov))?;
        }
        // The last NMEA reporting cycle ends with the file.
        let clock = self.offset.and(self.last_now);
        let undated = self.nmea.finish(clock);
        while let (Some(fix), Some(now)) = (self.nmea.next_fix(), self.last_now) {
            self.fix(now, &fix)?;
        }
        if undated > 0 {
            *self
                .report
                .skipped
                .entry("NMEA fixes with no date".to_owned())
                .or_insert(0) += undated;
        }
        Ok(())
    }
}

/// The run's metadata record: the file's run id, node and train, and the time base.
fn run_metadata(
    input: &Path,
    stem: &str,
    node: String,
    time_base: &str,
) -> BTreeMap<String, String> {
    BTreeMap::from([
        ("run_id".to_owned(), stem.to_owned()),
        (
            "source".to_owned(),
            "ETH-PBL Railway-Precise-Localization (imported)".to_owned(),
        ),
        ("input".to_owned(), input.display().to_string()),
        ("node".to_owned(), node),
        (
            "train".to_owned(),
            stem.split('_')
                .find(|p| p.starts_with('R'))
                .unwrap_or("")
                .to_owned(),
        ),
        ("time_base".to_owned(), time_base.to_owned()),
        ("tool_version".to_owned(), crate::TOOL_VERSION.to_owned()),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_clock_times_parse() {
        assert_eq!(board_ns("00:00:21.016375"), Some(21_016_375_000));
        assert_eq!(board_ns("1:02:03.5"), Some(3_723_500_000_000));
        assert_eq!(board_ns("00:61:00.0"), None);
        assert_eq!(board_ns("x"), None);
    }
}
