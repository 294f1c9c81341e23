//! What an eddy-current block must be before any of it becomes speed: bounded, finite, both
//! sensors the same length, not clipped, not dead, and continuous with the block before (the
//! same sample rate and spacing D, no gap, no overlap). A refused block is counted and said
//! in the diagnostics with its reason; a gap or a change of rate or D restarts the signal
//! processing (the filters' state and the correlation windows belong to the old stream).

use railfuse_catalog::messages::EddyCurrentBlock;

/// The most samples per sensor in one block (100 s at 10 kHz): bounds memory per message.
pub const MAX_BLOCK_SAMPLES: usize = 1_000_000;
/// Sample rates and spacings a real sensor pair has.
pub const RATE_HZ: (f64, f64) = (200.0, 1_000_000.0);
pub const SPACING_M: (f64, f64) = (0.02, 5.0);

/// Why a block is not used.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    Empty,
    TooLong(usize),
    Lengths(usize, usize),
    Rate(f64),
    Spacing(f64),
    NotFinite {
        sensor: char,
        index: usize,
    },
    Dead(char),
    Clipped {
        sensor: char,
        share: f64,
        level: f32,
    },
    Overlap {
        by_ns: i64,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Empty => write!(f, "an empty block"),
            Refusal::TooLong(n) => {
                write!(f, "{n} samples, more than {MAX_BLOCK_SAMPLES} in one block")
            }
            Refusal::Lengths(a, b) => {
                write!(
                    f,
                    "sensor a has {a} samples and sensor b {b}: they must match"
                )
            }
            Refusal::Rate(r) => write!(
                f,
                "sample rate {r} Hz, outside {}–{} Hz",
                RATE_HZ.0, RATE_HZ.1
            ),
            Refusal::Spacing(d) => write!(
                f,
                "sensor spacing D = {d} m, outside {}–{} m",
                SPACING_M.0, SPACING_M.1
            ),
            Refusal::NotFinite { sensor, index } => {
                write!(f, "sensor {sensor}: sample {index} is not a number")
            }
            Refusal::Dead(s) => write!(f, "sensor {s}: every sample is zero (a dead sensor)"),
            Refusal::Clipped {
                sensor,
                share,
                level,
            } => write!(
                f,
                "sensor {sensor}: {:.1} % of the samples sit at ±{level} V (clipped)",
                100.0 * share
            ),
            Refusal::Overlap { by_ns } => write!(
                f,
                "starts {:.3} ms before the previous block ended",
                *by_ns as f64 / 1e6
            ),
        }
    }
}

/// A break in the stream: processing starts over.
#[derive(Debug, Clone, PartialEq)]
pub enum Break {
    Gap { missing_s: f64 },
    RateChanged { from: f64, to: f64 },
    SpacingChanged { from: f64, to: f64 },
}

impl std::fmt::Display for Break {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Break::Gap { missing_s } => write!(
                f,
                "a gap of {:.1} ms before this block: processing starts over",
                missing_s * 1e3
            ),
            Break::RateChanged { from, to } => write!(
                f,
                "the sample rate changed from {from} Hz to {to} Hz: processing starts over"
            ),
            Break::SpacingChanged { from, to } => write!(
                f,
                "the sensor spacing D changed from {from} m to {to} m: processing starts over"
            ),
        }
    }
}

/// The stream as far as it went: where the next block should start.
#[derive(Debug, Clone, Copy, Default)]
pub struct Continuity {
    next: Option<(u64, f64, f64)>,
}

impl Continuity {
    /// Judges `b`: refused (and the stream broken), or accepted, with a break before it when
    /// it does not continue the last one.
    pub fn judge(&mut self, b: &EddyCurrentBlock) -> Result<Option<Break>, Refusal> {
        let verdict = self.check(b);
        match &verdict {
            Err(_) => self.next = None,
            Ok(_) => {
                let n = b.sensor_a.len() as f64;
                let end = b.stamp_ns + (n * 1e9 / b.sample_rate_hz).round() as u64;
                self.next = Some((end, b.sample_rate_hz, b.spacing_m));
            }
        }
        verdict
    }

    fn check(&self, b: &EddyCurrentBlock) -> Result<Option<Break>, Refusal> {
        let (na, nb) = (b.sensor_a.len(), b.sensor_b.len());
        if na == 0 && nb == 0 {
            return Err(Refusal::Empty);
        }
        if na.max(nb) > MAX_BLOCK_SAMPLES {
            return Err(Refusal::TooLong(na.max(nb)));
        }
        if na != nb {
            return Err(Refusal::Lengths(na, nb));
        }
        if !(b.sample_rate_hz >= RATE_HZ.0 && b.sample_rate_hz <= RATE_HZ.1) {
            return Err(Refusal::Rate(b.sample_rate_hz));
        }
        if !(b.spacing_m >= SPACING_M.0 && b.spacing_m <= SPACING_M.1) {
            return Err(Refusal::Spacing(b.spacing_m));
        }
        for (sensor, x) in [('a', &b.sensor_a), ('b', &b.sensor_b)] {
            if let Some(index) = x.iter().position(|v| !v.is_finite()) {
                return Err(Refusal::NotFinite { sensor, index });
            }
            if x.iter().all(|&v| v == 0.0) {
                return Err(Refusal::Dead(sensor));
            }
            let level = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let at = x.iter().filter(|v| v.abs() == level).count();
            let share = at as f64 / x.len() as f64;
            // A real pulse peaks at one or two samples; a converter at its end of range
            // holds there.
            if at >= 5 && share >= 0.005 {
                return Err(Refusal::Clipped {
                    sensor,
                    share,
                    level,
                });
            }
        }
        let Some((next, rate, spacing)) = self.next else {
            return Ok(None);
        };
        if b.sample_rate_hz != rate {
            return Ok(Some(Break::RateChanged {
                from: rate,
                to: b.sample_rate_hz,
            }));
        }
        if b.spacing_m != spacing {
            return Ok(Some(Break::SpacingChanged {
                from: spacing,
                to: b.spacing_m,
            }));
        }
        let period = 1e9 / rate;
        let off = b.stamp_ns as i64 - next as i64;
        if (off as f64) < -1.5 * period {
            return Err(Refusal::Overlap { by_ns: -off });
        }
        if off as f64 > 1.5 * period {
            return Ok(Some(Break::Gap {
                missing_s: off as f64 / 1e9,
            }));
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(stamp_ns: u64, n: usize) -> EddyCurrentBlock {
        EddyCurrentBlock {
            stamp_ns,
            sample_rate_hz: 10_000.0,
            spacing_m: 0.25,
            sensor_a: (0..n).map(|k| (k as f32 * 0.3).sin()).collect(),
            sensor_b: (0..n).map(|k| (k as f32 * 0.3).cos()).collect(),
            volts_per_count: None,
        }
    }

    #[test]
    fn each_kind_of_bad_block_is_refused_or_breaks_the_stream_with_its_reason() {
        let mut c = Continuity::default();
        assert_eq!(c.judge(&block(0, 1000)), Ok(None));
        // Continues exactly: 1000 samples at 10 kHz is 100 ms.
        assert_eq!(c.judge(&block(100_000_000, 1000)), Ok(None));
        let gap = c.judge(&block(250_000_000, 1000)).unwrap().unwrap();
        assert_eq!(gap, Break::Gap { missing_s: 0.05 });
        assert!(gap.to_string().contains("gap of 50.0 ms"));
        let mut b = block(350_000_000, 1000);
        b.sample_rate_hz = 20_000.0;
        assert!(matches!(c.judge(&b), Ok(Some(Break::RateChanged { .. }))));
        let mut b = block(400_000_000, 1000);
        b.sample_rate_hz = 20_000.0;
        b.spacing_m = 0.3;
        assert!(c
            .judge(&b)
            .unwrap()
            .unwrap()
            .to_string()
            .contains("D changed from 0.25 m"));
        let mut c = Continuity::default();
        c.judge(&block(0, 1000)).unwrap();
        assert_eq!(
            c.judge(&block(50_000_000, 1000)),
            Err(Refusal::Overlap { by_ns: 50_000_000 })
        );
        let mut b = block(0, 1000);
        b.sensor_b[17] = f32::NAN;
        let e = c.judge(&b).unwrap_err();
        assert_eq!(e.to_string(), "sensor b: sample 17 is not a number");
        let mut b = block(0, 1000);
        b.sensor_a.iter_mut().for_each(|v| *v = 0.0);
        assert_eq!(c.judge(&b), Err(Refusal::Dead('a')));
        let mut b = block(0, 1000);
        b.sensor_a
            .iter_mut()
            .for_each(|v| *v = (3.0 * *v).clamp(-2.5, 2.5));
        assert!(c.judge(&b).unwrap_err().to_string().contains("(clipped)"));
        let mut b = block(0, 1000);
        b.sensor_b.pop();
        assert_eq!(c.judge(&b), Err(Refusal::Lengths(1000, 999)));
        let mut b = block(0, 10);
        b.spacing_m = 0.0;
        assert!(matches!(c.judge(&b), Err(Refusal::Spacing(_))));
    }
}
