//! Fused states scored against a reference that is itself a sensor: GNSS fixes (railfuse's
//! `GnssFix`, a ROS 2 `NavSatFix`, a Foxglove `LocationFix`), with or without speed.
//!
//! Such a reference is sparse (1–20 Hz), noisy and gappy, and the states are dense, so each fix
//! is matched by interpolating the states to the fix's time, never the fix to a state's:
//! between the two states that bracket the fix, cubic Hermite on chainage with the states'
//! speeds as slopes (exact for constant acceleration),
//!
//! ```text
//! s(t) = h00(u)·s_a + h10(u)·h·v_a + h01(u)·s_b + h11(u)·h·v_b,   u = (t − t_a)/h, h = t_b − t_a
//! ```
//!
//! and its derivative for the speed. A fix whose bracketing states are more than
//! [`MAX_STATE_GAP_NS`] apart lies in a gap of the states and is not scored; one before the
//! first state or after the last is outside them. Only fixes of the stated quality count
//! ([`FixQuality`]); the rest are counted as left out.
//!
//! Streaming: states are kept for a bounded time behind the newest, fixes wait for the state
//! after them for at most as long.

use std::collections::VecDeque;

use railfuse_catalog::messages::FixType;
use serde::Serialize;

use crate::accuracy::{record_in_windows, ErrorStats, ErrorSummary, Exceedance, Span, WindowStats};
use crate::outages::{OutageEval, OutageMeter, OutageWindow};

/// States further apart than this do not bracket a fix (the pipeline was not producing
/// states, e.g. a GNSS-only pipeline in a tunnel).
pub const MAX_STATE_GAP_NS: u64 = 2_000_000_000;

/// Which fixes of a GNSS reference count.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum FixQuality {
    /// RTK fixed where the channel has any RTK fixed fix, else every fix with a position
    /// (decided at the end of the run, both kept until then).
    #[default]
    Auto,
    /// Every fix with a position.
    All,
    /// Only fixes of these types.
    Only(Vec<FixType>),
}

impl std::str::FromStr for FixQuality {
    type Err = String;

    /// `auto`, `all`, or fix types separated by commas (`rtk_fixed`, `rtk_fixed,rtk_float`).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => return Ok(FixQuality::Auto),
            "all" => return Ok(FixQuality::All),
            _ => {}
        }
        let all = [
            FixType::Single,
            FixType::Dgps,
            FixType::RtkFloat,
            FixType::RtkFixed,
        ];
        let types = s
            .split(',')
            .map(|name| {
                let name = name.trim();
                all.into_iter().find(|t| t.name() == name).ok_or_else(|| {
                    format!(
                        "'{name}' is not a fix quality: auto, all, or {} (commas between several)",
                        all.map(FixType::name).join(", ")
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(FixQuality::Only(types))
    }
}

impl FixQuality {
    /// The name as the report writes it.
    pub fn label(&self) -> String {
        match self {
            FixQuality::Auto => "auto".into(),
            FixQuality::All => "all".into(),
            FixQuality::Only(t) => t.iter().map(|t| t.name()).collect::<Vec<_>>().join(","),
        }
    }
}

/// What the accuracy table is scored against: a channel, and for GNSS fixes which of them.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    pub topic: String,
    pub quality: FixQuality,
}

impl Reference {
    /// `topic`, every quality as [`FixQuality::Auto`] takes it.
    pub fn topic(topic: &str) -> Self {
        Self {
            topic: topic.to_owned(),
            quality: FixQuality::Auto,
        }
    }
}

/// A fused state as the fix meter takes it.
#[derive(Debug, Clone, Copy)]
pub struct StateAt {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
    /// Its chainage variance, m².
    pub variance_m2: f64,
    /// A pipeline in the plane: its offset from the track's centre line, m (right positive).
    pub lateral_m: Option<f64>,
}

/// A reference fix on the track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixSample {
    pub stamp_ns: u64,
    /// When it was logged: what places it in or out of a withholding outage.
    pub log_time_ns: u64,
    pub fix_type: FixType,
    pub chainage_m: f64,
    /// Over ground, where the fix carries one.
    pub speed_mps: Option<f64>,
    /// Its own variance along the track, where it carries a covariance: the error against
    /// it is the state's and the fix's, so its 3σ bound is on both variances.
    pub variance_m2: Option<f64>,
    /// Its offset from the track's centre line (right positive), m: what a pipeline in the
    /// plane is scored against across the track.
    pub lateral_m: Option<f64>,
}

#[derive(Debug, Clone, Copy)]
struct StatePoint {
    stamp_ns: u64,
    chainage_m: f64,
    speed_mps: f64,
    variance_m2: f64,
    /// A pipeline in the plane: its offset from the track's centre line.
    lateral_m: Option<f64>,
}

/// What matching a fix gave.
enum Matched {
    At {
        chainage_m: f64,
        speed_mps: f64,
        variance_m2: f64,
        lateral_m: Option<f64>,
        /// To the nearer bracketing state.
        dt_ns: u64,
    },
    Gap,
    Outside,
    /// A state after it has not come yet.
    Later,
}

/// The fixes of one quality matched against one pipeline's states.
#[derive(Debug, Clone, Default)]
struct Tally {
    position: ErrorStats,
    speed: ErrorStats,
    /// Pipelines in the plane: across the track.
    across: ErrorStats,
    beyond_3_sigma: Exceedance,
    windows: Vec<WindowStats>,
    matched: u64,
    in_state_gaps: u64,
    outside_states: u64,
    largest_dt_ns: u64,
    with_speed: u64,
    outages: OutageMeter,
    /// `½ Σ (ln 2πv + e²/v)`, v the state's variance at the fix plus the fix's own: the
    /// negative log-likelihood of the fixes as the states predicted them.
    nll: f64,
}

/// The report of one pipeline's states against a fix reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FixMatchReport {
    /// The quality counted (`rtk_fixed`, `all`, …; `auto` resolved).
    pub quality: String,
    /// Fixes of that quality on the track.
    pub fixes: u64,
    /// Fixes with a position left out for their quality.
    pub other_quality: u64,
    pub matched: u64,
    /// The largest time from a matched fix to its nearer bracketing state, s.
    pub largest_dt_s: f64,
    /// Fixes between two states further apart than [`MAX_STATE_GAP_NS`].
    pub in_state_gaps: u64,
    /// Fixes before the first state or after the last.
    pub outside_states: u64,
    /// Why speed is not scored, where it is not: the reference carries no speed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub no_speed: Option<String>,
}

/// Matches one pipeline's states to a GNSS reference by interpolating the states to each fix.
#[derive(Debug, Clone)]
pub struct FixMeter {
    quality: FixQuality,
    keep_ns: u64,
    states: VecDeque<StatePoint>,
    /// States dropped off the back: a fix older than the kept ones is not "before the first".
    dropped_before_ns: Option<u64>,
    pending: VecDeque<FixSample>,
    newest_fix_ns: u64,
    /// `Only`/`All`: the one tally; `Auto`: RTK fixed fixes here, all in `fallback`.
    tally: Tally,
    fallback: Tally,
    rtk_fixed_seen: bool,
    /// Fixes on the track of any quality, of the main quality, of the fallback's.
    seen: u64,
    fixes: u64,
    fixes_fallback: u64,
}

impl FixMeter {
    /// `lag_s`: how far states may trail the fixes in file order.
    pub fn new(quality: FixQuality, lag_s: f64) -> Self {
        Self {
            quality,
            keep_ns: ((lag_s + 2.0) * 1e9) as u64 + MAX_STATE_GAP_NS,
            states: VecDeque::new(),
            dropped_before_ns: None,
            pending: VecDeque::new(),
            newest_fix_ns: 0,
            tally: Tally::default(),
            fallback: Tally::default(),
            rtk_fixed_seen: false,
            seen: 0,
            fixes: 0,
            fixes_fallback: 0,
        }
    }

    /// Whether a fix of `fix_type` counts in the main tally, and in the fallback one.
    fn counts(&self, fix_type: FixType) -> (bool, bool) {
        match &self.quality {
            FixQuality::Auto => (fix_type == FixType::RtkFixed, true),
            FixQuality::All => (true, false),
            FixQuality::Only(types) => (types.contains(&fix_type), false),
        }
    }

    /// Scores the errors inside each of `windows` (a withheld reference's) on their own.
    pub fn set_outages(&mut self, windows: &[OutageWindow]) {
        self.tally.outages = OutageMeter::new(windows);
        self.fallback.outages = OutageMeter::new(windows);
    }

    /// The outages' errors, against the fixes reported.
    pub fn outages(&self, t0_ns: u64) -> Option<OutageEval> {
        self.reported().0.outages.report(t0_ns)
    }

    pub fn add_fix(&mut self, fix: FixSample, spans: &[Span]) {
        self.seen += 1;
        self.rtk_fixed_seen |= fix.fix_type == FixType::RtkFixed;
        let (main, fallback) = self.counts(fix.fix_type);
        self.fixes += u64::from(main);
        self.fixes_fallback += u64::from(fallback);
        if !main && !fallback {
            return;
        }
        self.newest_fix_ns = self.newest_fix_ns.max(fix.stamp_ns);
        self.pending.push_back(fix);
        self.resolve(spans, false);
    }

    /// A state: along the track, and (a pipeline in the plane) its offset from the centre line.
    pub fn add_state(&mut self, state: &StateAt, spans: &[Span]) {
        let point = StatePoint {
            stamp_ns: state.stamp_ns,
            chainage_m: state.chainage_m,
            speed_mps: state.speed_mps,
            variance_m2: state.variance_m2,
            lateral_m: state.lateral_m,
        };
        let stamp_ns = state.stamp_ns;
        // In stamp order (a reorder window keeps them so; a stray one is put in place).
        let at = self.states.partition_point(|s| s.stamp_ns <= stamp_ns);
        self.states.insert(at, point);
        let newest = self.states.back().map_or(0, |s| s.stamp_ns);
        while self
            .states
            .front()
            .is_some_and(|s| s.stamp_ns + self.keep_ns < newest)
        {
            self.dropped_before_ns = self.states.pop_front().map(|s| s.stamp_ns);
        }
        self.resolve(spans, false);
    }

    /// Scores the pending fixes that can be; at the end (`last`) every one left.
    fn resolve(&mut self, spans: &[Span], last: bool) {
        let mut waiting = VecDeque::new();
        while let Some(fix) = self.pending.pop_front() {
            let stale = fix.stamp_ns + self.keep_ns < self.newest_fix_ns;
            match self.locate(fix.stamp_ns) {
                Matched::Later if !(last || stale) => waiting.push_back(fix),
                m => self.score(fix, m, spans),
            }
        }
        self.pending = waiting;
    }

    fn locate(&self, t: u64) -> Matched {
        let after = self.states.partition_point(|s| s.stamp_ns < t);
        let Some(b) = self.states.get(after) else {
            return Matched::Later; // no state at or after it yet
        };
        if b.stamp_ns == t {
            return Matched::At {
                chainage_m: b.chainage_m,
                speed_mps: b.speed_mps,
                variance_m2: b.variance_m2,
                lateral_m: b.lateral_m,
                dt_ns: 0,
            };
        }
        let Some(a) = after.checked_sub(1).and_then(|i| self.states.get(i)) else {
            // Before every state kept: before the first, or older than those kept.
            return match self.dropped_before_ns {
                Some(_) => Matched::Gap,
                None => Matched::Outside,
            };
        };
        let h_ns = b.stamp_ns - a.stamp_ns;
        if h_ns > MAX_STATE_GAP_NS {
            return Matched::Gap;
        }
        let (chainage_m, speed_mps) = hermite(a, b, t);
        let u = (t - a.stamp_ns) as f64 / h_ns as f64;
        Matched::At {
            chainage_m,
            speed_mps,
            variance_m2: a.variance_m2 + u * (b.variance_m2 - a.variance_m2),
            lateral_m: a.lateral_m.zip(b.lateral_m).map(|(x, y)| x + u * (y - x)),
            dt_ns: (t - a.stamp_ns).min(b.stamp_ns - t),
        }
    }

    fn score(&mut self, fix: FixSample, m: Matched, spans: &[Span]) {
        let (main, fallback) = self.counts(fix.fix_type);
        for (tally, counts) in [(&mut self.tally, main), (&mut self.fallback, fallback)] {
            if !counts {
                continue;
            }
            match m {
                Matched::At {
                    chainage_m,
                    speed_mps,
                    variance_m2,
                    lateral_m,
                    dt_ns,
                } => {
                    let de = chainage_m - fix.chainage_m;
                    let across = lateral_m.zip(fix.lateral_m).map(|(s, f)| s - f);
                    if let Some(x) = across {
                        tally.across.add(x);
                    }
                    let ve = fix.speed_mps.map(|v| speed_mps - v);
                    tally.position.add(de);
                    if let Some(ve) = ve {
                        tally.speed.add(ve);
                        tally.with_speed += 1;
                    }
                    let v = variance_m2 + fix.variance_m2.unwrap_or(0.0);
                    tally.beyond_3_sigma.add(de, v);
                    if v > 0.0 && v.is_finite() {
                        tally.nll += 0.5 * ((std::f64::consts::TAU * v).ln() + de * de / v);
                    }
                    record_in_windows(&mut tally.windows, spans, fix.stamp_ns, de, ve);
                    tally
                        .outages
                        .add(fix.log_time_ns, fix.chainage_m, de, across);
                    tally.matched += 1;
                    tally.largest_dt_ns = tally.largest_dt_ns.max(dt_ns);
                }
                Matched::Gap => tally.in_state_gaps += 1,
                Matched::Outside | Matched::Later => tally.outside_states += 1,
            }
        }
    }

    /// Ends the run: fixes still waiting had no state after them.
    pub fn finish(&mut self, spans: &[Span]) {
        self.resolve(spans, true);
    }

    /// The tally reported: `auto` falls back to every fix where there was no RTK fixed one.
    fn reported(&self) -> (&Tally, u64, String) {
        match &self.quality {
            FixQuality::Auto if !self.rtk_fixed_seen => {
                (&self.fallback, self.fixes_fallback, "all".into())
            }
            FixQuality::Auto => (&self.tally, self.fixes, FixType::RtkFixed.name().into()),
            q => (&self.tally, self.fixes, q.label()),
        }
    }

    /// The position errors of the fixes reported, to pool with another log's.
    pub fn position_stats(&self) -> &ErrorStats {
        &self.reported().0.position
    }

    pub fn speed_stats(&self) -> &ErrorStats {
        &self.reported().0.speed
    }

    /// Pipelines in the plane: their error across the track at the fixes.
    pub fn across(&self) -> Option<ErrorSummary> {
        self.reported().0.across.summary()
    }

    pub fn position(&self) -> Option<ErrorSummary> {
        self.reported().0.position.summary()
    }

    pub fn speed(&self) -> Option<ErrorSummary> {
        self.reported().0.speed.summary()
    }

    /// The negative log-likelihood of the matched fixes under the states interpolated to
    /// them (state and fix variances), and how many: of fixes withheld from the pipeline, its
    /// predictive likelihood.
    pub fn nll(&self) -> (f64, u64) {
        let t = self.reported().0;
        (t.nll, t.matched)
    }

    pub fn beyond_3_sigma(&self) -> Option<f64> {
        self.reported().0.beyond_3_sigma.share()
    }

    pub fn windows(&self) -> &[WindowStats] {
        &self.reported().0.windows
    }

    /// The counts of the match, for the report.
    pub fn report(&self) -> FixMatchReport {
        let (tally, fixes, quality) = self.reported();
        FixMatchReport {
            quality,
            fixes,
            other_quality: self.seen - fixes,
            matched: tally.matched,
            largest_dt_s: tally.largest_dt_ns as f64 / 1e9,
            in_state_gaps: tally.in_state_gaps,
            outside_states: tally.outside_states,
            no_speed: (tally.matched > 0 && tally.with_speed == 0)
                .then(|| "the reference carries no speed".to_owned()),
        }
    }
}

/// Chainage and speed at `t` between states `a` and `b` (cubic Hermite, speeds as slopes).
fn hermite(a: &StatePoint, b: &StatePoint, t: u64) -> (f64, f64) {
    let h = (b.stamp_ns - a.stamp_ns) as f64 / 1e9;
    let u = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
    let (u2, u3) = (u * u, u * u * u);
    let s = (2.0 * u3 - 3.0 * u2 + 1.0) * a.chainage_m
        + (u3 - 2.0 * u2 + u) * h * a.speed_mps
        + (-2.0 * u3 + 3.0 * u2) * b.chainage_m
        + (u3 - u2) * h * b.speed_mps;
    let v = ((6.0 * u2 - 6.0 * u) * a.chainage_m
        + (3.0 * u2 - 4.0 * u + 1.0) * h * a.speed_mps
        + (-6.0 * u2 + 6.0 * u) * b.chainage_m
        + (3.0 * u2 - 2.0 * u) * h * b.speed_mps)
        / h;
    (s, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(t_s: f64, s: f64, v: Option<f64>, fix_type: FixType) -> FixSample {
        FixSample {
            stamp_ns: (t_s * 1e9) as u64,
            log_time_ns: (t_s * 1e9) as u64,
            fix_type,
            chainage_m: s,
            speed_mps: v,
            variance_m2: None,
            lateral_m: None,
        }
    }

    /// States of a train at 2 m/s² from rest every 0.25 s from `from_s` to `to_s`.
    fn states(m: &mut FixMeter, from_s: f64, to_s: f64) {
        let mut t = from_s;
        while t <= to_s + 1e-9 {
            let state = StateAt {
                stamp_ns: (t * 1e9).round() as u64,
                chainage_m: t * t,
                speed_mps: 2.0 * t,
                variance_m2: 0.01,
                lateral_m: None,
            };
            m.add_state(&state, &[]);
            t += 0.25;
        }
    }

    #[test]
    fn states_are_interpolated_to_the_fix_exactly_under_constant_acceleration() {
        let mut m = FixMeter::new(FixQuality::All, 1.0);
        // Fixes arrive first (the states trail them in file order), between state stamps.
        for k in 0..20 {
            let t = 0.1 + 0.2 * k as f64;
            m.add_fix(fix(t, t * t, Some(2.0 * t), FixType::RtkFixed), &[]);
        }
        states(&mut m, 0.0, 5.0);
        m.finish(&[]);
        let p = m.position().unwrap();
        assert_eq!(p.samples, 20);
        assert!(p.max_abs < 1e-9, "{p:?}");
        assert!(m.speed().unwrap().max_abs < 1e-9);
        let r = m.report();
        assert_eq!((r.matched, r.outside_states, r.in_state_gaps), (20, 0, 0));
        assert!((r.largest_dt_s - 0.1).abs() < 1e-6, "{r:?}");
        // Nearest-neighbour matching would be off by up to v·0.125 s here.
    }

    #[test]
    fn quality_gaps_and_a_reference_without_speed() {
        let mut m = FixMeter::new(FixQuality::Auto, 1.0);
        states(&mut m, 0.0, 2.0);
        states(&mut m, 5.0, 6.0); // 3 s without states
        m.add_fix(fix(1.0, 1.5, None, FixType::RtkFixed), &[]); // 0.5 m ahead of the state
        m.add_fix(fix(1.5, 0.0, None, FixType::Single), &[]); // not RTK fixed: left out
        m.add_fix(fix(3.0, 9.0, None, FixType::RtkFixed), &[]); // in the states' gap
        m.add_fix(fix(9.0, 81.0, None, FixType::RtkFixed), &[]); // after the last state
        m.finish(&[]);
        let r = m.report();
        assert_eq!(r.quality, "rtk_fixed");
        assert_eq!((r.fixes, r.other_quality, r.matched), (3, 1, 1));
        assert_eq!((r.in_state_gaps, r.outside_states), (1, 1));
        assert_eq!(
            r.no_speed.as_deref(),
            Some("the reference carries no speed")
        );
        assert!((m.position().unwrap().rmse - 0.5).abs() < 1e-9);
        assert!(m.speed().is_none());
        // Without any RTK fixed fix, auto counts them all.
        let mut m = FixMeter::new(FixQuality::Auto, 1.0);
        states(&mut m, 0.0, 2.0);
        m.add_fix(fix(1.5, 0.0, None, FixType::Single), &[]);
        m.finish(&[]);
        assert_eq!(m.report().quality, "all");
        assert_eq!(m.report().matched, 1);
    }

    #[test]
    fn quality_names_parse_and_a_wrong_one_says_what_would() {
        assert_eq!(
            "rtk_fixed".parse(),
            Ok(FixQuality::Only(vec![FixType::RtkFixed]))
        );
        assert_eq!(
            "rtk_fixed, rtk_float".parse(),
            Ok(FixQuality::Only(vec![FixType::RtkFixed, FixType::RtkFloat]))
        );
        let e = "rtk".parse::<FixQuality>().unwrap_err();
        assert!(
            e.contains("'rtk' is not a fix quality") && e.contains("rtk_float"),
            "{e}"
        );
    }
}
