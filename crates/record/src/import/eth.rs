//! The ETH-PBL "Railway-Precise-Localization" on-board node logs (ETR103 runs between Modena
//! and Formigine, 2022): one CSV line per record, `TIMESTAMP,TYPE,DATA`, with `TIMESTAMP`
//! `[h]:mm:ss.ffffff` on the node's clock since start-up.
//!
//! | TYPE | DATA | becomes |
//! |---|---|---|
//! | `I` | 12 bytes hex: gyro x, y, z then accel x, y, z, int16 | `/imu` (`Imu`, SI units) |
//! | `U` | one UBX frame as hex | NAV-PVT (+ NAV-COV of the same epoch) → `/gnss/fix` |
//! | `N` | an NMEA sentence | GGA (+ RMC/VTG/GSA/GST) → `/gnss/fix` |
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

struct Out {
    writer: LogWriter,
    imu: ChannelId,
    gnss: ChannelId,
    events: ChannelId,
}

impl Out {
    fn write<M: ChannelMessage>(
        &mut self,
        report: &mut ImportReport,
        channel: ChannelId,
        topic: &str,
        log_time: u64,
        m: &M,
    ) -> Result<()> {
        self.writer.write(channel, log_time, m)?;
        report.messages += 1;
        *report.per_topic.entry(topic.to_owned()).or_insert(0) += 1;
        Ok(())
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
    let mut report = ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: "eth".into(),
        ..Default::default()
    };
    let offset = utc_offset(input)?;
    report.time_base = match offset {
        Some(_) => "UTC, from the first NAV-PVT with a valid time; other records by their node-clock offset to it".into(),
        None => "node clock since start-up (no NAV-PVT with a valid time in the file)".into(),
    };
    let to_utc =
        |board: u64| -> u64 { offset.map_or(board, |o| (board as i128 + o).max(0) as u64) };
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
    let imu = writer.add_channel::<Imu>(topics::IMU)?;
    let gnss = writer.add_channel::<GnssFix>(topics::GNSS_FIX)?;
    let events = writer.add_channel::<Event>(topics::EVENTS)?;
    let mut out = Out {
        writer,
        imu,
        gnss,
        events,
    };

    let mut r = open(input)?;
    let (mut line, mut bytes) = (Vec::new(), Vec::new());
    let mut nmea = FixAssembler::default();
    // A NAV-PVT waits for the NAV-COV of its epoch (the receiver sends it right after).
    let mut pairing = PvtCovPairing::default();
    // The node clock of the last line: the time of a solution left waiting at the end.
    let mut last_now = None;
    let mut n = 0u64;
    let io = |source| Error::Io {
        path: input.to_owned(),
        source,
    };
    let mut consumed = 0u64;
    while let Some(ok) = read_line_bounded(&mut r, &mut line).map_err(io)? {
        n += 1;
        report.lines += 1;
        consumed += line.len() as u64 + 1;
        if n.is_multiple_of(4096) {
            progress(consumed);
        }
        if !ok {
            report.skip(
                n,
                "line too long",
                format!("over {} bytes", super::MAX_LINE),
            );
            continue;
        }
        let Ok(text) = std::str::from_utf8(&line) else {
            report.skip(n, "not UTF-8 text", "binary bytes");
            continue;
        };
        if text.trim().is_empty() {
            continue;
        }
        let mut f = text.splitn(3, ',');
        let (t, kind, data) = (
            f.next().unwrap_or(""),
            f.next().unwrap_or(""),
            f.next().unwrap_or(""),
        );
        let Some(board) = board_ns(t) else {
            report.skip(n, "bad timestamp", t);
            continue;
        };
        let now = to_utc(board);
        last_now = Some(now);
        match kind {
            "I" => {
                if data.len() != 24 || !hex_into(data, &mut bytes) {
                    report.skip(n, "bad IMU sample", data);
                    continue;
                }
                let w = |i: usize| i16::from_le_bytes([bytes[2 * i], bytes[2 * i + 1]]) as f64;
                let m = Imu {
                    stamp_ns: now,
                    sensor_id: format!("asm330lhh-{node}"),
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
                };
                out.write(&mut report, out.imu, topics::IMU, now, &m)?;
            }
            "U" => {
                if !hex_into(data, &mut bytes) {
                    report.skip(n, "UBX frame not hex", data);
                    continue;
                }
                let frame = match ubx::parse_frame(&bytes) {
                    Ok((frame, used)) if used == bytes.len() => frame,
                    Ok(_) => {
                        report.skip(n, "UBX trailing bytes", data);
                        continue;
                    }
                    Err(e) => {
                        report.skip(n, "UBX frame rejected", e);
                        continue;
                    }
                };
                match (frame.class, frame.id) {
                    NavPvt::CLASS_ID => match NavPvt::decode(&frame) {
                        Ok(pvt) => {
                            if let Some(prev) = pairing.pvt(pvt) {
                                let fix = prev.to_fix(prev.utc_ns.unwrap_or(now), None);
                                out.write(&mut report, out.gnss, topics::GNSS_FIX, now, &fix)?;
                            }
                        }
                        Err(e) => report.skip(n, "UBX NAV-PVT rejected", e),
                    },
                    NavCov::CLASS_ID => match NavCov::decode(&frame) {
                        Ok(cov) => match pairing.cov(&cov) {
                            Some((pvt, cov)) => {
                                let fix = pvt.to_fix(pvt.utc_ns.unwrap_or(now), cov);
                                out.write(&mut report, out.gnss, topics::GNSS_FIX, now, &fix)?;
                            }
                            None => report.skip(n, "UBX NAV-COV without its NAV-PVT", cov.itow_ms),
                        },
                        Err(e) => report.skip(n, "UBX NAV-COV rejected", e),
                    },
                    (0x05, _) => {
                        *report
                            .skipped
                            .entry("UBX ACK/NAK (not data)".into())
                            .or_insert(0) += 1
                    }
                    (c, i) => {
                        *report
                            .skipped
                            .entry(format!("UBX {c:02x}/{i:02x} (not decoded)"))
                            .or_insert(0) += 1
                    }
                }
            }
            // With the node clock on UTC, a GGA before any RMC takes the day nearest it.
            "N" => match nmea::parse(data).and_then(|s| nmea.feed(&s, offset.map(|_| now))) {
                Ok(Decoded::Fix) => {
                    while let Some(fix) = nmea.next_fix() {
                        out.write(&mut report, out.gnss, topics::GNSS_FIX, now, &fix)?;
                    }
                }
                Ok(Decoded::Context | Decoded::Held) => {}
                Ok(Decoded::Skipped) => {
                    *report
                        .skipped
                        .entry("NMEA sentence type not used (GSV, GLL, …)".into())
                        .or_insert(0) += 1
                }
                Err(e) => report.skip(n, "NMEA sentence rejected", e),
            },
            "BRK" | "ARR" | "DEP" => {
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
                out.write(&mut report, out.events, topics::EVENTS, now, &e)?;
            }
            other => report.skip(n, "unknown line type", other),
        }
    }
    if let (Some(pvt), Some(now)) = (pairing.finish(), last_now) {
        let fix = pvt.to_fix(pvt.utc_ns.unwrap_or(now), None);
        out.write(&mut report, out.gnss, topics::GNSS_FIX, now, &fix)?;
    }
    let run = BTreeMap::from([
        ("run_id".to_owned(), stem.clone()),
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
        ("time_base".to_owned(), report.time_base.clone()),
        ("tool_version".to_owned(), crate::TOOL_VERSION.to_owned()),
    ]);
    out.writer.write_metadata(topics::metadata::RUN, run)?;
    out.writer.finish()?;
    Ok(report)
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
