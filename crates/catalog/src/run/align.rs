//! Each recorder's clock estimated against GNSS time from what it logged, so that the files of
//! several recorders can be read on one clock (`--align gnss`).
//!
//! A recorder that logged GNSS time beside its own clock carries its offset and drift:
//! - a **time reference** (`railfuse.TimeReference`, ROS's `sensor_msgs/TimeReference`: the
//!   recorder's clock read at a receiver's PPS edge) pairs `local_ns` with `stamp_ns` to a few
//!   microseconds; `local − gnss` is fitted by least squares, pairs beyond 5 robust σ left out;
//! - a **GNSS fix** pairs the recorder's log time with the receiver's solution time. The fix
//!   reaches the recorder a transport delay late, and that delay is never negative: the clock
//!   is the line under every pair that lies closest to them (the lower convex hull's edge over
//!   the pairs' mean time; Moon, Skelly and Towsley's linear programme for clock skew), which
//!   still holds the delay's least value.
//!
//! The run's time is then the clock of the first input that has an estimate (the reference
//! recorder): every other input is mapped onto it through GNSS time. Delays common to the
//! recorders (the same receiver's fixes) cancel; a run of one recorder is left as it is.

use std::path::{Path, PathBuf};

use super::{ClockMap, Part, Run};
use crate::error::{Error, Result};
use crate::log::{LogReader, LogRecord};
use crate::messages::{FixType, GnssFix, MessageKind, TimeReference};

/// How a run's recorders are put on one clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Align {
    /// Each file on its own clock (or the `--clock-offset` given).
    #[default]
    None,
    /// Each input's clock estimated against GNSS time and mapped onto the reference
    /// recorder's.
    Gnss,
}

impl std::str::FromStr for Align {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "none" => Ok(Self::None),
            "gnss" => Ok(Self::Gnss),
            other => Err(format!("align '{other}': use none or gnss")),
        }
    }
}

/// What gave a recorder's GNSS time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ClockSource {
    /// Time references (a PPS edge read on the recorder's clock).
    TimeReference,
    /// GNSS fixes' solution time against their log time (holds the least transport delay).
    GnssFix,
}

impl ClockSource {
    pub fn label(self) -> &'static str {
        match self {
            Self::TimeReference => "time reference",
            Self::GnssFix => "GNSS fixes",
        }
    }
}

/// One input's clock against GNSS time, as its files show it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ClockEstimate {
    pub input: PathBuf,
    pub source: ClockSource,
    /// The topics the pairs came from.
    pub topics: Vec<String>,
    /// Pairs fitted (after any left out as outliers).
    pub pairs: usize,
    pub outliers: usize,
    /// Local time − GNSS time: `offset_ns` at `origin_ns` (the input's first pair), drifting
    /// by `drift_ppm`.
    pub clock: ClockMap,
    /// The pairs about the fitted line, ns (for GNSS fixes: above it, the transport delay's
    /// spread).
    pub residual_rms_ns: f64,
    pub residual_max_ns: f64,
    /// Time between the first and last pair, s.
    pub span_s: f64,
}

/// Why an input has no estimate.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NoEstimate {
    pub input: PathBuf,
    pub cause: String,
}

/// Every input's estimate, in input order.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Alignment {
    pub estimates: Vec<std::result::Result<ClockEstimate, NoEstimate>>,
    /// The input whose clock is the run's (the first with an estimate).
    pub reference: Option<usize>,
}

/// Pairs kept per input at the most: beyond it every other pair is dropped and the stride
/// doubled, so memory does not grow with the run (100 000 pairs: 28 h of PPS, 2.8 h of 10 Hz
/// fixes before the first thinning).
const MAX_PAIRS: usize = 100_000;
/// A fit whose pairs stray further than this is no clock (a replayed file, a receiver on
/// its own RTC): 1 s.
const MAX_RESIDUAL_NS: f64 = 1e9;
/// Drift is fitted only over at least this span: 10 s.
const MIN_DRIFT_SPAN_NS: f64 = 10e9;

/// (local, local − GNSS) pairs of one input, thinned to a bound.
#[derive(Default)]
struct Pairs {
    /// (local, local − GNSS, part).
    kept: Vec<(u64, i64, usize)>,
    stride: usize,
    seen: usize,
    topics: Vec<String>,
}

impl Pairs {
    fn push(&mut self, local_ns: u64, gnss_ns: u64, topic: &str, part: usize) {
        if !self.topics.iter().any(|t| t == topic) {
            self.topics.push(topic.to_owned());
        }
        self.stride = self.stride.max(1);
        self.seen += 1;
        if !(self.seen - 1).is_multiple_of(self.stride) {
            return;
        }
        let d = local_ns as i128 - gnss_ns as i128;
        let Ok(d) = i64::try_from(d) else { return };
        self.kept.push((local_ns, d, part));
        if self.kept.len() >= MAX_PAIRS {
            let mut i = 0;
            self.kept.retain(|_| {
                i += 1;
                i % 2 == 1
            });
            self.stride *= 2;
        }
    }
}

impl Run {
    /// Estimates every input's clock against GNSS time (one pass over each input's files).
    pub fn estimate_clocks(&self) -> Result<Alignment> {
        let mut estimates = Vec::with_capacity(self.inputs.len());
        for (i, input) in self.inputs.iter().enumerate() {
            let parts = self.parts.iter().filter(|p| p.input == i);
            estimates.push(estimate_input(input, parts)?);
        }
        let reference = estimates.iter().position(|e| e.is_ok());
        Ok(Alignment {
            estimates,
            reference,
        })
    }

    /// Puts every input with an estimate on the reference recorder's clock (an input given
    /// a `--clock-offset` keeps it). Returns the estimates, for the report.
    pub fn align_gnss(&mut self, keep: &[PathBuf]) -> Result<Alignment> {
        let alignment = self.estimate_clocks()?;
        let Some(r) = alignment.reference else {
            return Ok(alignment);
        };
        let reference = match &alignment.estimates[r] {
            Ok(e) => e.clock,
            Err(_) => unreachable!("the reference has an estimate"),
        };
        for (i, estimate) in alignment.estimates.iter().enumerate() {
            let Ok(estimate) = estimate else { continue };
            let clock = onto(&estimate.clock, &reference);
            for part in self.parts.iter_mut().filter(|p| p.input == i) {
                let given = keep.iter().any(|k| {
                    super::same_file(k, &part.path) || super::same_file(k, &self.inputs[i])
                });
                if !given {
                    part.clock = clock;
                }
            }
        }
        Ok(alignment)
    }
}

/// The clock that maps an input's time onto the reference recorder's, both given against
/// GNSS time (`ClockMap::correct` takes each to GNSS time).
///
/// The input's `x` is GNSS time `g = x − off_i − d_i (x − o_i)`, and GNSS time `g` is the
/// reference's `r = o_r + (g − o_r + off_r) / (1 − d_r)`: a line in `x` of slope
/// `(1 − d_i) / (1 − d_r)`, taken through its value at the input's origin.
fn onto(input: &ClockMap, reference: &ClockMap) -> ClockMap {
    let (d_i, d_r) = (input.drift_ppm * 1e-6, reference.drift_ppm * 1e-6);
    let g0 = input.origin_ns as i128 - input.offset_ns as i128;
    // Relative to the reference's origin, so the f64 stays small (hours: 1e13 ns).
    let u = (g0 - reference.origin_ns as i128 + reference.offset_ns as i128) as f64;
    let r0 = reference.origin_ns as i128 + (u / (1.0 - d_r)).round() as i128;
    ClockMap {
        offset_ns: (input.origin_ns as i128 - r0) as i64,
        drift_ppm: (1.0 - (1.0 - d_i) / (1.0 - d_r)) * 1e6,
        origin_ns: input.origin_ns,
    }
}

/// One input's estimate from its files' time references, else its GNSS fixes.
fn estimate_input<'a>(
    input: &Path,
    parts: impl Iterator<Item = &'a Part>,
) -> Result<std::result::Result<ClockEstimate, NoEstimate>> {
    let (mut references, mut fixes) = (Pairs::default(), Pairs::default());
    let parts: Vec<&Part> = parts.collect();
    for (p, part) in parts.iter().enumerate() {
        let mut reader = LogReader::open(&part.path)?;
        while let Some(record) = reader.next() {
            let LogRecord::Message(m) = record? else {
                continue;
            };
            match m.channel.kind() {
                Some(MessageKind::TimeReference) => {
                    let r: TimeReference = m.decode(&part.path)?;
                    references.push(r.local_ns, r.stamp_ns, &m.channel.topic, p);
                }
                // Only a fix with a solution has the receiver's time (without one, a
                // receiver may send its real-time clock's).
                Some(MessageKind::GnssFix) if references.kept.is_empty() => {
                    let f: GnssFix = m.decode(&part.path)?;
                    if f.fix_type != FixType::None && f.stamp_ns > 0 {
                        fixes.push(m.log_time_ns, f.stamp_ns, &m.channel.topic, p);
                    }
                }
                _ => {}
            }
        }
    }
    let (pairs, source) = match references.kept.is_empty() {
        false => (references, ClockSource::TimeReference),
        true => (fixes, ClockSource::GnssFix),
    };
    let no = |cause: String| {
        Ok(Err(NoEstimate {
            input: input.to_owned(),
            cause,
        }))
    };
    if pairs.kept.len() < 3 {
        return no(match pairs.kept.len() {
            0 => "no GNSS time: no time reference and no GNSS fix with a solution".into(),
            n => format!("{n} GNSS time pairs: too few to fit a clock"),
        });
    }
    let fitted = fit(&pairs.kept, source);
    if let Some((a, b, apart)) = clocks_apart(&pairs.kept, &fitted, source) {
        return Err(Error::run(
            &parts[b].path,
            format!(
                "on another clock than {} ({:.3} s apart): the files of several recorders in one \
                 input; give each recorder's files as an input of its own",
                parts[a].path.display(),
                apart / 1e9
            ),
        ));
    }
    if fitted.residual_max_ns > MAX_RESIDUAL_NS {
        return no(format!(
            "its {} stray {:.3} s from any one clock: not GNSS time on a recorder's clock",
            source.label(),
            fitted.residual_max_ns / 1e9
        ));
    }
    Ok(Ok(ClockEstimate {
        input: input.to_owned(),
        source,
        topics: pairs.topics,
        ..fitted
    }))
}

/// Parts of one input whose pairs sit apart about the input's clock line (medians further
/// apart than a time reference's 1 ms or a fix's 50 ms of transport delay): two recorders'
/// files read as one. Returns the two parts and how far apart, ns.
fn clocks_apart(
    pairs: &[(u64, i64, usize)],
    fitted: &ClockEstimate,
    source: ClockSource,
) -> Option<(usize, usize, f64)> {
    let tolerance = match source {
        ClockSource::TimeReference => 1e6,
        ClockSource::GnssFix => 50e6,
    };
    let mut by_part: std::collections::BTreeMap<usize, Vec<f64>> = Default::default();
    for &(x, d, part) in pairs {
        let line = fitted.clock.offset_ns as f64
            + fitted.clock.drift_ppm * 1e-6 * (x as f64 - fitted.clock.origin_ns as f64);
        by_part.entry(part).or_default().push(d as f64 - line);
    }
    let medians: Vec<(usize, f64)> = by_part
        .into_iter()
        .map(|(part, mut r)| {
            r.sort_unstable_by(f64::total_cmp);
            (part, r[r.len() / 2])
        })
        .collect();
    let low = medians.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let high = medians.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    (high.1 - low.1 > tolerance).then(|| (low.0.min(high.0), low.0.max(high.0), high.1 - low.1))
}

/// The clock line of `pairs` (local, local − GNSS, part).
fn fit(pairs: &[(u64, i64, usize)], source: ClockSource) -> ClockEstimate {
    let mut pairs: Vec<(u64, i64)> = pairs.iter().map(|&(x, d, _)| (x, d)).collect();
    pairs.sort_unstable();
    let origin = pairs[0].0;
    let xy: Vec<(f64, f64)> = pairs
        .iter()
        .map(|&(x, d)| ((x - origin) as f64, (d - pairs[0].1) as f64))
        .collect();
    let span = xy.last().map_or(0.0, |p| p.0);
    let with_drift = span >= MIN_DRIFT_SPAN_NS;
    let (line, used, outliers) = match source {
        ClockSource::TimeReference => least_squares_robust(&xy, with_drift),
        ClockSource::GnssFix => (lower_envelope(&xy, with_drift), xy.len(), 0),
    };
    let residuals = xy.iter().map(|&(x, y)| y - (line.0 + line.1 * x));
    let (mut sum2, mut max) = (0.0, 0.0f64);
    let mut n = 0usize;
    for r in residuals {
        if source == ClockSource::TimeReference && r.abs() > line.2 {
            continue;
        }
        sum2 += r * r;
        max = max.max(r.abs());
        n += 1;
    }
    ClockEstimate {
        input: PathBuf::new(),
        source,
        topics: Vec::new(),
        pairs: used,
        outliers,
        clock: ClockMap {
            offset_ns: pairs[0].1 + line.0.round() as i64,
            drift_ppm: line.1 * 1e6,
            origin_ns: origin,
        },
        residual_rms_ns: (sum2 / n.max(1) as f64).sqrt(),
        residual_max_ns: max,
        span_s: span / 1e9,
    }
}

/// Least squares `y = a + b x` (b = 0 without drift), refitted once without the pairs
/// beyond 5 robust σ (1.4826 × the median absolute residual, at least 1 µs). Returns
/// (a, b, the cut), the pairs used and those left out.
fn least_squares_robust(xy: &[(f64, f64)], with_drift: bool) -> ((f64, f64, f64), usize, usize) {
    let first = least_squares(xy.iter().copied(), with_drift);
    let mut abs: Vec<f64> = xy
        .iter()
        .map(|&(x, y)| (y - first.0 - first.1 * x).abs())
        .collect();
    abs.sort_unstable_by(f64::total_cmp);
    let cut = (5.0 * 1.4826 * abs[abs.len() / 2]).max(1e3);
    let kept = xy
        .iter()
        .copied()
        .filter(|&(x, y)| (y - first.0 - first.1 * x).abs() <= cut);
    let used = kept.clone().count();
    let (a, b) = least_squares(kept, with_drift);
    ((a, b, cut), used, xy.len() - used)
}

fn least_squares(xy: impl Iterator<Item = (f64, f64)>, with_drift: bool) -> (f64, f64) {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (x, y) in xy {
        n += 1.0;
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    let denominator = n * sxx - sx * sx;
    if !with_drift || denominator <= 0.0 {
        return (sy / n, 0.0);
    }
    let b = (n * sxy - sx * sy) / denominator;
    ((sy - b * sx) / n, b)
}

/// The line under every pair that minimises the sum of their heights above it: an edge of
/// the lower convex hull, the one over the pairs' mean x (or the lowest pair without drift).
/// Returns (a, b, unused).
fn lower_envelope(xy: &[(f64, f64)], with_drift: bool) -> (f64, f64, f64) {
    if !with_drift {
        let low = xy.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        return (low, 0.0, 0.0);
    }
    // Andrew's monotone chain, lower half; xy is sorted by x.
    let mut hull: Vec<(f64, f64)> = Vec::new();
    for &p in xy {
        while hull.len() >= 2 {
            let (o, a) = (hull[hull.len() - 2], hull[hull.len() - 1]);
            let cross = (a.0 - o.0) * (p.1 - o.1) - (a.1 - o.1) * (p.0 - o.0);
            if cross > 0.0 {
                break;
            }
            hull.pop();
        }
        hull.push(p);
    }
    let mean_x = xy.iter().map(|p| p.0).sum::<f64>() / xy.len() as f64;
    let edge = hull
        .windows(2)
        .find(|w| w[0].0 <= mean_x && mean_x <= w[1].0 && w[1].0 > w[0].0);
    match edge {
        Some(w) => {
            let b = (w[1].1 - w[0].1) / (w[1].0 - w[0].0);
            (w[0].1 - b * w[0].0, b, 0.0)
        }
        None => (hull[0].1, 0.0, 0.0),
    }
}

impl Alignment {
    /// An input that has no estimate while others do: it stays on its own clock.
    pub fn unaligned(&self) -> impl Iterator<Item = &NoEstimate> {
        self.estimates.iter().filter_map(|e| e.as_ref().err())
    }
}

/// An estimate that cannot be used to align anything is still worth naming: the error a
/// command gives where `--align gnss` finds no GNSS time in any input.
pub fn no_gnss_time(run: &Run, alignment: &Alignment) -> Error {
    let causes: Vec<String> = alignment
        .unaligned()
        .map(|n| format!("{}: {}", n.input.display(), n.cause))
        .collect();
    Error::run(
        run.name(),
        format!(
            "--align gnss: no input carries GNSS time ({})",
            causes.join("; ")
        ),
    )
}
