//! The withholding protocol: a reference sensor (an RTK receiver) hidden from the pipeline in
//! chosen windows, and the pipeline scored against what was hidden, as GNSS/INS evaluations
//! of field logs do (artificial GNSS outages). The error at each outage's end, the largest
//! inside it and the drift as a share of the distance run in it say how the filter coasts on
//! its other sensors; the receiver it fused everywhere else cannot flatter it there.
//!
//! Windows are in log time, counted from the run's first message, so that the replay (which
//! hides a message) and the evaluation (which scores against it) decide alike from the same
//! message's log time, whatever the sensor's own clock.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::error_stats::{ErrorStats, ErrorSummary};

/// The standard sets, each outage of the cycle one period apart: 30 s, 60 s and 120 s.
const STANDARD_LENGTHS_S: [f64; 3] = [30.0, 60.0, 120.0];
const STANDARD_EVERY_S: f64 = 180.0;
/// Where the first outage starts by default, s after the run's first message: the filter has
/// had the reference that long to settle.
const DEFAULT_FROM_S: f64 = 60.0;

/// `LEN[:every=PERIOD][:from=T]` or `standard`: outage lengths (cycled, one per period), the
/// period and the first outage's start, s.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageSpec {
    pub lengths_s: Vec<f64>,
    /// None: one outage only.
    pub every_s: Option<f64>,
    pub from_s: f64,
    /// As written.
    pub text: String,
}

impl std::str::FromStr for OutageSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if text == "standard" {
            return Ok(Self {
                lengths_s: STANDARD_LENGTHS_S.to_vec(),
                every_s: Some(STANDARD_EVERY_S),
                from_s: DEFAULT_FROM_S,
                text: text.to_owned(),
            });
        }
        let mut fields = text.split(':');
        let seconds = |what: &str, v: &str| -> Result<f64, String> {
            let v = v.trim().trim_end_matches('s');
            match v.parse::<f64>() {
                Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
                _ => Err(format!(
                    "outages '{text}': {what} '{v}' is not a number of seconds (LEN[:every=PERIOD][:from=T], or standard)"
                )),
            }
        };
        let length = seconds("the length", fields.next().unwrap_or(""))?;
        if length <= 0.0 {
            return Err(format!("outages '{text}': an outage lasts longer than 0 s"));
        }
        let (mut every_s, mut from_s) = (None, DEFAULT_FROM_S);
        for field in fields {
            match field.split_once('=') {
                Some(("every", v)) => every_s = Some(seconds("every", v)?),
                Some(("from", v)) => from_s = seconds("from", v)?,
                _ => {
                    return Err(format!(
                        "outages '{text}': '{field}' is neither every=PERIOD nor from=T"
                    ))
                }
            }
        }
        if every_s.is_some_and(|e| e <= length) {
            return Err(format!(
                "outages '{text}': every {} s leaves no reference between outages of {length} s",
                every_s.unwrap_or(0.0)
            ));
        }
        Ok(Self {
            lengths_s: vec![length],
            every_s,
            from_s,
            text: text.to_owned(),
        })
    }
}

/// One window the reference was withheld in, log time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct OutageWindow {
    pub start_ns: u64,
    pub end_ns: u64,
}

impl OutageWindow {
    pub fn contains(&self, t_ns: u64) -> bool {
        (self.start_ns..self.end_ns).contains(&t_ns)
    }

    pub fn length_s(&self) -> f64 {
        (self.end_ns - self.start_ns) as f64 / 1e9
    }
}

impl OutageSpec {
    /// The windows inside a run spanning `start_ns..end_ns` (log time); an outage that would
    /// run past the end is left out. An error, naming the spec, when none fits.
    pub fn windows(&self, start_ns: u64, end_ns: u64) -> Result<Vec<OutageWindow>, String> {
        let ns = |s: f64| (s * 1e9).round() as u64;
        let mut out = Vec::new();
        for k in 0u64.. {
            let length = self.lengths_s[k as usize % self.lengths_s.len()];
            let start = start_ns + ns(self.from_s + k as f64 * self.every_s.unwrap_or(0.0));
            let end = start + ns(length);
            if start >= end_ns {
                break;
            }
            if end <= end_ns {
                out.push(OutageWindow {
                    start_ns: start,
                    end_ns: end,
                });
            }
            if self.every_s.is_none() {
                break;
            }
        }
        if out.is_empty() {
            let run_s = end_ns.saturating_sub(start_ns) as f64 / 1e9;
            return Err(format!(
                "outages '{}': no outage fits in the run ({run_s:.1} s long; the first would \
                 start {} s in and last {} s)",
                self.text, self.from_s, self.lengths_s[0]
            ));
        }
        Ok(out)
    }
}

/// A topic to withhold from a pipeline: inside the outages of a spec, or for the whole run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Withhold {
    pub topic: String,
    pub outages: Option<OutageSpec>,
}

impl Withhold {
    /// The windows in a run whose messages span `span` (log time, from its summaries); an
    /// error in words (naming the topic) when the outages cannot be placed.
    pub fn place(&self, span: Option<(u64, u64)>) -> Result<Withheld, String> {
        let placed = match (&self.outages, span) {
            (Some(_), None) => Err(
                "the run's span is unknown (a file without a summary), so its \
                 outages cannot be placed: rewrite it first with railfuse merge"
                    .to_owned(),
            ),
            (_, span) => {
                let (start, end) = span.unwrap_or((0, 0));
                self.in_run(start, end)
            }
        };
        placed.map_err(|e| format!("withhold {}: {e}", self.topic))
    }

    /// The windows in a run spanning `start_ns..end_ns` (log time).
    pub fn in_run(&self, start_ns: u64, end_ns: u64) -> Result<Withheld, String> {
        Ok(Withheld {
            topic: self.topic.clone(),
            spec: self.outages.as_ref().map(|o| o.text.clone()),
            windows: match &self.outages {
                Some(o) => o.windows(start_ns, end_ns)?,
                None => Vec::new(),
            },
        })
    }
}

/// What was withheld: the topic and the windows, as the fused log's `railfuse.withheld`
/// metadata record holds them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Withheld {
    pub topic: String,
    /// None: withheld for the whole run.
    pub spec: Option<String>,
    pub windows: Vec<OutageWindow>,
}

impl Withheld {
    /// The metadata record's fields.
    pub fn to_metadata(&self) -> BTreeMap<String, String> {
        let windows: Vec<String> = self
            .windows
            .iter()
            .map(|w| format!("{}-{}", w.start_ns, w.end_ns))
            .collect();
        BTreeMap::from([
            ("topic".to_owned(), self.topic.clone()),
            (
                "outages".to_owned(),
                self.spec.clone().unwrap_or_else(|| "all".into()),
            ),
            ("windows_log_time_ns".to_owned(), windows.join(",")),
        ])
    }

    /// Read back from the metadata record; `None` if it does not read.
    pub fn from_metadata(m: &BTreeMap<String, String>) -> Option<Self> {
        let windows = m
            .get("windows_log_time_ns")?
            .split(',')
            .filter(|w| !w.is_empty())
            .map(|w| {
                let (a, b) = w.split_once('-')?;
                Some(OutageWindow {
                    start_ns: a.parse().ok()?,
                    end_ns: b.parse().ok()?,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        Some(Self {
            topic: m.get("topic")?.clone(),
            spec: m.get("outages").filter(|s| *s != "all").cloned(),
            windows,
        })
    }

    /// Whether a message of the topic at `log_time_ns` is hidden from the pipeline.
    pub fn hides(&self, log_time_ns: u64) -> bool {
        self.spec.is_none() || self.windows.iter().any(|w| w.contains(log_time_ns))
    }
}

/// One outage's errors as they come: along the track, against the withheld reference.
#[derive(Debug, Clone)]
struct OutageTally {
    window: OutageWindow,
    samples: u64,
    max_abs_m: f64,
    /// (reference chainage, error) at the first and the last sample inside.
    first: Option<(f64, f64)>,
    last: Option<(f64, f64)>,
    /// Across the track at the last sample (pipelines in the plane against fixes).
    last_across: Option<f64>,
}

/// The errors inside each outage of one pipeline.
#[derive(Debug, Clone, Default)]
pub struct OutageMeter {
    tallies: Vec<OutageTally>,
}

/// One outage in the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageReport {
    /// From the run's first message, s.
    pub start_s: f64,
    pub length_s: f64,
    /// Reference samples scored inside it.
    pub samples: u64,
    /// Along the track at its last reference sample, signed (fused − reference), m.
    pub end_error_m: Option<f64>,
    /// Across the track there (pipelines in the plane against GNSS fixes), m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub end_across_m: Option<f64>,
    pub max_abs_error_m: Option<f64>,
    /// The distance run inside it (by the reference), m.
    pub distance_m: Option<f64>,
    /// |end error| as a share of the distance run, %.
    pub drift_percent: Option<f64>,
}

/// The outages of one length over the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageTable {
    pub length_s: f64,
    pub outages: usize,
    /// |error at the end| over the outages: RMS, 95th percentile, maximum.
    pub end_error_m: Option<ErrorSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub end_across_m: Option<ErrorSummary>,
    pub max_abs_error_m: Option<ErrorSummary>,
    pub drift_percent: Option<ErrorSummary>,
}

/// A pipeline's outages: each, and the table by length.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageEval {
    pub each: Vec<OutageReport>,
    pub by_length: Vec<OutageTable>,
}

impl OutageMeter {
    pub fn new(windows: &[OutageWindow]) -> Self {
        Self {
            tallies: windows
                .iter()
                .map(|&window| OutageTally {
                    window,
                    samples: 0,
                    max_abs_m: 0.0,
                    first: None,
                    last: None,
                    last_across: None,
                })
                .collect(),
        }
    }

    /// A scored sample: at `t_ns` (log time of the withheld message, or a state's stamp
    /// against a truth reference), the reference at `reference_m` along the track, the error
    /// `error_m`.
    pub fn add(&mut self, t_ns: u64, reference_m: f64, error_m: f64, across_m: Option<f64>) {
        let Some(o) = self.tallies.iter_mut().find(|o| o.window.contains(t_ns)) else {
            return;
        };
        o.samples += 1;
        o.max_abs_m = o.max_abs_m.max(error_m.abs());
        o.first.get_or_insert((reference_m, error_m));
        o.last = Some((reference_m, error_m));
        o.last_across = across_m;
    }

    /// The report; times from `t0_ns`.
    pub fn report(&self, t0_ns: u64) -> Option<OutageEval> {
        if self.tallies.is_empty() {
            return None;
        }
        let each: Vec<OutageReport> = self
            .tallies
            .iter()
            .map(|o| {
                let distance = o.first.zip(o.last).map(|(a, b)| (b.0 - a.0).abs());
                let end = o.last.map(|l| l.1);
                OutageReport {
                    start_s: o.window.start_ns.saturating_sub(t0_ns) as f64 / 1e9,
                    length_s: o.window.length_s(),
                    samples: o.samples,
                    end_error_m: end,
                    end_across_m: o.last_across,
                    max_abs_error_m: (o.samples > 0).then_some(o.max_abs_m),
                    distance_m: distance,
                    drift_percent: end
                        .zip(distance)
                        .filter(|(_, d)| *d > 0.0)
                        .map(|(e, d)| 100.0 * e.abs() / d),
                }
            })
            .collect();
        let mut lengths: Vec<f64> = each.iter().map(|o| o.length_s).collect();
        lengths.sort_by(f64::total_cmp);
        lengths.dedup();
        let by_length = lengths
            .into_iter()
            .map(|length_s| {
                let of: Vec<&OutageReport> =
                    each.iter().filter(|o| o.length_s == length_s).collect();
                let stats = |f: fn(&OutageReport) -> Option<f64>| {
                    let mut s = ErrorStats::default();
                    of.iter().filter_map(|o| f(o)).for_each(|x| s.add(x.abs()));
                    s.summary()
                };
                OutageTable {
                    length_s,
                    outages: of.len(),
                    end_error_m: stats(|o| o.end_error_m),
                    end_across_m: stats(|o| o.end_across_m),
                    max_abs_error_m: stats(|o| o.max_abs_error_m),
                    drift_percent: stats(|o| o.drift_percent),
                }
            })
            .collect();
        Some(OutageEval { each, by_length })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_into_windows_that_fit_the_run() {
        let s: OutageSpec = "30:every=180:from=10".parse().unwrap();
        let w = s.windows(1_000, 1_000 + 400_000_000_000).unwrap();
        let starts: Vec<u64> = w
            .iter()
            .map(|w| (w.start_ns - 1_000) / 1_000_000_000)
            .collect();
        assert_eq!(starts, [10, 190, 370]);
        assert!(w.iter().all(|w| w.length_s() == 30.0));
        // The standard sets: 30, 60 and 120 s in turn, one every 180 s from 60 s; the one
        // that would run past the end is left out.
        let s: OutageSpec = "standard".parse().unwrap();
        let w = s.windows(0, 600_000_000_000).unwrap();
        let got: Vec<(f64, f64)> = w
            .iter()
            .map(|w| (w.start_ns as f64 / 1e9, w.length_s()))
            .collect();
        assert_eq!(got, [(60.0, 30.0), (240.0, 60.0), (420.0, 120.0)]);
        assert_eq!(s.windows(0, 500_000_000_000).unwrap().len(), 2);
        // One outage without every=.
        let s: OutageSpec = "45".parse().unwrap();
        assert_eq!(s.windows(0, 1_000_000_000_000).unwrap().len(), 1);
    }

    #[test]
    fn bad_specs_and_an_outage_longer_than_the_run_are_one_line_each() {
        for (spec, says) in [
            ("abc", "the length 'abc' is not a number"),
            ("30:each=60", "'each=60' is neither every=PERIOD nor from=T"),
            ("60:every=30", "leaves no reference between outages"),
            ("0", "longer than 0 s"),
        ] {
            let e = spec.parse::<OutageSpec>().unwrap_err();
            assert!(e.contains(says), "{spec}: {e}");
        }
        let s: OutageSpec = "600".parse().unwrap();
        let e = s.windows(0, 300_000_000_000).unwrap_err();
        assert!(e.contains("no outage fits in the run (300.0 s long"), "{e}");
    }

    #[test]
    fn each_outage_gives_its_end_error_maximum_and_drift() {
        let windows = [
            OutageWindow {
                start_ns: 10_000_000_000,
                end_ns: 40_000_000_000,
            },
            OutageWindow {
                start_ns: 100_000_000_000,
                end_ns: 130_000_000_000,
            },
        ];
        let mut m = OutageMeter::new(&windows);
        // 20 m/s; the error grows to 3 m at the end of the first, 1 m in the second.
        for k in 0..=300u64 {
            let t = 10_000_000_000 + k * 100_000_000;
            m.add(t, 20.0 * (t as f64 / 1e9), 3.0 * k as f64 / 300.0, None);
        }
        m.add(5_000_000_000, 100.0, 9.0, None); // outside both: not counted
        m.add(100_000_000_000, 2000.0, -0.5, None);
        m.add(129_900_000_000, 2598.0, -1.0, Some(0.2));
        let r = m.report(0).unwrap();
        assert_eq!(r.each[0].samples, 300); // the window ends before t = 40 s
        let e0 = &r.each[0];
        assert!((e0.end_error_m.unwrap() - 2.99).abs() < 1e-9, "{e0:?}");
        assert!((e0.distance_m.unwrap() - 598.0).abs() < 1e-6, "{e0:?}");
        assert!((e0.drift_percent.unwrap() - 100.0 * 2.99 / 598.0).abs() < 1e-9);
        assert_eq!(r.each[1].max_abs_error_m, Some(1.0));
        let t = &r.by_length[0];
        assert_eq!((t.length_s, t.outages), (30.0, 2));
        assert!((t.end_error_m.unwrap().max_abs - 2.99).abs() < 1e-9);
    }
}
