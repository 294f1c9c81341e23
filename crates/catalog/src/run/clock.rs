//! Each recorder's clock against the run's time: an offset and a drift, given by the engineer
//! (`--clock-offset FILE=+0.120`) or estimated from the GNSS fixes the recorder logged.

use std::path::{Path, PathBuf};

use super::Part;
use crate::error::{Error, Result};

/// A recorder's clock: its time `t` is run time `t − offset − drift·(t − origin)`.
///
/// A positive offset is a clock ahead of the run's (its log times late); a positive drift a
/// clock that runs fast, in parts per million, measured from `origin_ns`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ClockMap {
    pub offset_ns: i64,
    pub drift_ppm: f64,
    pub origin_ns: u64,
}

impl ClockMap {
    pub fn is_identity(&self) -> bool {
        self.offset_ns == 0 && self.drift_ppm == 0.0
    }

    /// `t` of this clock in run time (saturating at 0).
    pub fn correct(&self, t_ns: u64) -> u64 {
        if self.is_identity() {
            return t_ns;
        }
        let drift = (t_ns as f64 - self.origin_ns as f64) * self.drift_ppm * 1e-6;
        let corrected = t_ns as i128 - self.offset_ns as i128 - drift.round() as i128;
        corrected.clamp(0, u64::MAX as i128) as u64
    }

    /// The offset in seconds, as said to a person.
    pub fn offset_s(&self) -> f64 {
        self.offset_ns as f64 / 1e9
    }
}

/// One `FILE=OFFSET_S[,DRIFT_PPMppm]` given for a run.
#[derive(Debug, Clone, PartialEq)]
pub struct ClockOffset {
    pub file: PathBuf,
    pub clock: ClockMap,
}

impl std::str::FromStr for ClockOffset {
    type Err = String;
    /// `run-b.mcap=+0.120` (s) or `run-b.mcap=-1.2,+20ppm`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (file, value) = s
            .rsplit_once('=')
            .ok_or_else(|| format!("'{s}': give FILE=OFFSET_S, e.g. run-b.mcap=+0.120"))?;
        let (offset, drift) = match value.split_once(',') {
            Some((o, d)) => (o, Some(d)),
            None => (value, None),
        };
        let offset_s: f64 = offset
            .trim()
            .parse()
            .map_err(|_| format!("'{s}': offset '{offset}' is not a number of seconds"))?;
        if !offset_s.is_finite() || offset_s.abs() > 86_400.0 {
            return Err(format!("'{s}': offset {offset_s} s is not within a day"));
        }
        let drift_ppm = match drift {
            None => 0.0,
            Some(d) => {
                let d = d.trim();
                let number = d
                    .strip_suffix("ppm")
                    .ok_or_else(|| format!("'{s}': drift '{d}' needs its unit, e.g. +20ppm"))?;
                let ppm: f64 = number
                    .parse()
                    .map_err(|_| format!("'{s}': drift '{d}' is not a number of ppm"))?;
                if !ppm.is_finite() || ppm.abs() > 1000.0 {
                    return Err(format!(
                        "'{s}': drift {ppm} ppm is not a clock's (|drift| ≤ 1000)"
                    ));
                }
                ppm
            }
        };
        Ok(Self {
            file: PathBuf::from(file),
            clock: ClockMap {
                offset_ns: (offset_s * 1e9).round() as i64,
                drift_ppm,
                origin_ns: 0,
            },
        })
    }
}

impl ClockOffset {
    /// Sets the clock of the parts this offset names: a part itself, or every part of an
    /// input. A drift is measured from the first time of the input (set when the run is read).
    pub(super) fn apply(&self, run: &Path, inputs: &[PathBuf], parts: &mut [Part]) -> Result<()> {
        // A bare file name (as a configuration gives it) names the run's file of that name.
        let bare = self.file.components().count() == 1;
        let named = |p: &Path| {
            super::same_file(p, &self.file)
                || (bare && p.file_name() == Some(self.file.as_os_str()))
        };
        let input = inputs.iter().position(|i| named(i));
        let mut matched = false;
        for part in parts.iter_mut() {
            if Some(part.input) == input || named(&part.path) {
                part.clock = self.clock;
                matched = true;
            }
        }
        match matched {
            true => Ok(()),
            false => Err(Error::run(
                run,
                format!(
                    "--clock-offset names {}, which is not a file or input of the run",
                    self.file.display()
                ),
            )),
        }
    }
}
