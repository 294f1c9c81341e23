//! Accuracy against a reference trajectory (the ground-truth channel): position and speed
//! errors of every fused state, with RMSE, maximum and 95th percentile, and the filter's
//! consistency: NEES of `[s, v]` against its own covariance and NIS of its innovations, as the
//! share of epochs inside the two-sided 95 % χ² interval (ideally 95 %).
//!
//! Streaming: the reference is kept only for a few seconds behind the replay, and the 95th
//! percentile comes from a log-bucketed histogram (1 % relative resolution), so memory does
//! not grow with the length of the log.

use std::collections::VecDeque;

use railfuse_catalog::messages::FusedState;
use railfuse_catalog::reference_track::{Lookup, ReferenceSample, ReferenceTrack};

use serde::Serialize;

use crate::outages::OutageMeter;

pub use crate::error_stats::{ErrorStats, ErrorSummary};

pub use railfuse_catalog::messages::fused::{CHI2_95_1DOF, CHI2_95_2DOF};

/// Share of a normalised squared error (NEES or NIS) inside its 95 % χ² interval.
#[derive(Debug, Clone, Default)]
pub struct Consistency {
    n: u64,
    inside: u64,
    sum: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConsistencySummary {
    pub epochs: u64,
    /// Share of epochs inside the two-sided 95 % χ² interval (0.95 when consistent).
    pub inside_95: f64,
    /// Mean value (the degrees of freedom when consistent).
    pub mean: f64,
}

impl Consistency {
    pub fn add(&mut self, value: f64, bounds: (f64, f64)) {
        if !value.is_finite() {
            return;
        }
        self.n += 1;
        self.sum += value;
        if value >= bounds.0 && value <= bounds.1 {
            self.inside += 1;
        }
    }

    /// Takes in the epochs of `other` (another log's, to pool them).
    pub fn merge(&mut self, other: &Consistency) {
        self.n += other.n;
        self.inside += other.inside;
        self.sum += other.sum;
    }

    pub fn summary(&self) -> Option<ConsistencySummary> {
        (self.n > 0).then(|| ConsistencySummary {
            epochs: self.n,
            inside_95: self.inside as f64 / self.n as f64,
            mean: self.sum / self.n as f64,
        })
    }
}

/// How often an error exceeded 3σ of the estimate's own variance (σ² = `variance`; an
/// estimate without a finite positive variance is not counted).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Exceedance {
    pub checked: u64,
    pub beyond: u64,
}

impl Exceedance {
    pub fn add(&mut self, error: f64, variance: f64) {
        if !(variance.is_finite() && variance > 0.0 && error.is_finite()) {
            return;
        }
        self.checked += 1;
        if error * error > 9.0 * variance {
            self.beyond += 1;
        }
    }

    pub fn merge(&mut self, other: &Exceedance) {
        self.checked += other.checked;
        self.beyond += other.beyond;
    }

    /// The share beyond 3σ, where any was checked.
    pub fn share(&self) -> Option<f64> {
        (self.checked > 0).then(|| self.beyond as f64 / self.checked as f64)
    }
}

/// `eᵀ P⁻¹ e` for the `[s, v]` error of a fused state against its own covariance.
pub fn nees(state: &FusedState, position_error: f64, speed_error: f64) -> f64 {
    let (pss, psv, pvv) = (
        state.covariance[0],
        state.covariance[1],
        state.covariance[4],
    );
    let det = pss * pvv - psv * psv;
    if det.is_nan() || det <= 0.0 {
        return f64::NAN;
    }
    (pvv * position_error * position_error - 2.0 * psv * position_error * speed_error
        + pss * speed_error * speed_error)
        / det
}

/// What waits for its reference: a state to score, or a safe interval to check.
#[derive(Debug, Clone)]
enum Waiting {
    State(Estimate),
    /// A safe interval `[low, high]` along the track at a stamp.
    Interval {
        stamp_ns: u64,
        low_m: f64,
        high_m: f64,
        kind: Interval,
    },
}

/// Which safe interval: each is counted on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interval {
    /// Source 002's U_safe, of a pipeline with safety checks.
    SafetyCheck,
    /// The min to max safe front end of a pipeline's train channel (ETCS's confidence
    /// interval, at its stated confidence).
    SafeFront,
}

impl Waiting {
    fn stamp_ns(&self) -> u64 {
        match self {
            Waiting::State(e) => e.stamp_ns,
            Waiting::Interval { stamp_ns, .. } => *stamp_ns,
        }
    }
}

/// How often safe intervals held the reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Containment {
    /// Intervals checked against the reference.
    pub checked: u64,
    /// Of those, intervals that held it.
    pub contained: u64,
    /// Intervals in a gap of the reference or outside its time span: not checked.
    pub unchecked: u64,
}

/// An estimate waiting for its reference.
#[derive(Debug, Clone)]
struct Estimate {
    stamp_ns: u64,
    chainage_m: f64,
    speed_mps: f64,
    /// (P_ss, P_sv, P_vv)
    covariance: (f64, f64, f64),
}

/// A marked stretch of the run (an injected fault, a tunnel, a correction outage): errors
/// inside it are also reported on their own.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Span {
    pub label: String,
    pub start_ns: u64,
    /// None while still open.
    pub end_ns: Option<u64>,
}

impl Span {
    pub fn contains(&self, t_ns: u64) -> bool {
        t_ns >= self.start_ns && self.end_ns.is_none_or(|e| t_ns < e)
    }
}

/// Errors inside the spans of one label.
#[derive(Debug, Clone)]
pub struct WindowStats {
    pub label: String,
    pub position: ErrorStats,
    pub speed: ErrorStats,
}

/// Adds an error at `t_ns` to the window of each label whose span holds it (a time inside two
/// spans of one label counts once).
pub fn record_in_windows(
    windows: &mut Vec<WindowStats>,
    spans: &[Span],
    t_ns: u64,
    position_error: f64,
    speed_error: Option<f64>,
) {
    for span in spans.iter().filter(|w| w.contains(t_ns)) {
        let first_of_label = spans
            .iter()
            .find(|w| w.label == span.label && w.contains(t_ns))
            .map(|w| w.start_ns)
            == Some(span.start_ns);
        if !first_of_label {
            continue;
        }
        let i = match windows.iter().position(|w| w.label == span.label) {
            Some(i) => i,
            None => {
                windows.push(WindowStats {
                    label: span.label.clone(),
                    position: ErrorStats::default(),
                    speed: ErrorStats::default(),
                });
                windows.len() - 1
            }
        };
        windows[i].position.add(position_error);
        if let Some(ve) = speed_error {
            windows[i].speed.add(ve);
        }
    }
}

/// Matches estimates to the reference interpolated at their stamps.
#[derive(Debug, Clone)]
pub struct AccuracyMeter {
    reference: ReferenceTrack,
    /// Estimates and intervals newer than the newest reference sample, waiting for it to
    /// catch up.
    waiting: VecDeque<Waiting>,
    /// Source 002's U_safe, and the train channel's safe front end interval.
    pub containment: Containment,
    pub safe_front: Containment,
    pub position: ErrorStats,
    pub speed: ErrorStats,
    pub nees: Consistency,
    /// Estimates whose position error exceeded 3σ of their own chainage variance: a filter
    /// that has diverged from the reference while sure of itself shows here in one number.
    pub beyond_3_sigma: Exceedance,
    /// Estimates that fell outside the reference's time span.
    pub unmatched: u64,
    /// Estimates inside a gap of the reference (see [`ReferenceTrack`]): not scored.
    pub in_reference_gaps: u64,
    pub windows: Vec<WindowStats>,
    /// The errors inside a withheld sensor's outages, by the states' stamps.
    pub outages: OutageMeter,
}

impl AccuracyMeter {
    /// `lag_s` must cover how far estimates may lag the replay (the reorder window).
    pub fn new(lag_s: f64) -> Self {
        Self {
            reference: ReferenceTrack::new(lag_s + 2.0),
            waiting: VecDeque::new(),
            containment: Containment::default(),
            safe_front: Containment::default(),
            position: ErrorStats::default(),
            speed: ErrorStats::default(),
            nees: Consistency::default(),
            beyond_3_sigma: Exceedance::default(),
            unmatched: 0,
            in_reference_gaps: 0,
            windows: Vec::new(),
            outages: OutageMeter::default(),
        }
    }

    pub fn add_reference(
        &mut self,
        stamp_ns: u64,
        chainage_m: f64,
        speed_mps: f64,
        spans: &[Span],
    ) {
        if !self.reference.push(ReferenceSample {
            stamp_ns,
            chainage_m,
            speed_mps,
        }) {
            return;
        }
        while self
            .waiting
            .front()
            .is_some_and(|e| e.stamp_ns() <= stamp_ns)
        {
            match self.waiting.pop_front().expect("peeked") {
                Waiting::State(e) => self.score(e, spans),
                Waiting::Interval {
                    stamp_ns,
                    low_m,
                    high_m,
                    kind,
                } => self.check_interval(stamp_ns, low_m, high_m, kind),
            }
        }
    }

    /// The newest reference stamp seen.
    pub fn reference_newest_ns(&self) -> Option<u64> {
        self.reference.newest_ns()
    }

    pub fn add_estimate(&mut self, s: &FusedState, spans: &[Span]) {
        let c = &s.covariance;
        let e = Estimate {
            stamp_ns: s.stamp_ns,
            chainage_m: s.chainage_m,
            speed_mps: s.speed_mps,
            covariance: (c[0], c[1], c[4]),
        };
        match self.reference.newest_ns() {
            Some(newest) if newest >= s.stamp_ns => self.score(e, spans),
            _ => self.waiting.push_back(Waiting::State(e)),
        }
    }

    /// A safe interval `[low, high]` at `stamp_ns`: does it hold the reference's chainage?
    pub fn add_interval(&mut self, stamp_ns: u64, low_m: f64, high_m: f64, kind: Interval) {
        match self.reference.newest_ns() {
            Some(newest) if newest >= stamp_ns => {
                self.check_interval(stamp_ns, low_m, high_m, kind)
            }
            _ => self.waiting.push_back(Waiting::Interval {
                stamp_ns,
                low_m,
                high_m,
                kind,
            }),
        }
    }

    fn tally(&mut self, kind: Interval) -> &mut Containment {
        match kind {
            Interval::SafetyCheck => &mut self.containment,
            Interval::SafeFront => &mut self.safe_front,
        }
    }

    fn check_interval(&mut self, stamp_ns: u64, low_m: f64, high_m: f64, kind: Interval) {
        let found = self.reference.lookup(stamp_ns);
        let tally = self.tally(kind);
        match found {
            Lookup::At(s, _) => {
                tally.checked += 1;
                tally.contained += u64::from((low_m..=high_m).contains(&s));
            }
            Lookup::Gap | Lookup::Outside => tally.unchecked += 1,
        }
    }

    /// What still waits at the end of the log had no reference after it.
    pub fn finish(&mut self) {
        for w in std::mem::take(&mut self.waiting) {
            match w {
                Waiting::State(_) => self.unmatched += 1,
                Waiting::Interval { kind, .. } => self.tally(kind).unchecked += 1,
            }
        }
    }

    fn score(&mut self, e: Estimate, spans: &[Span]) {
        match self.reference.lookup(e.stamp_ns) {
            Lookup::At(s, v) => {
                let (de, ve) = (e.chainage_m - s, e.speed_mps - v);
                self.position.add(de);
                self.speed.add(ve);
                record_in_windows(&mut self.windows, spans, e.stamp_ns, de, Some(ve));
                self.outages.add(e.stamp_ns, s, de, None);
                let (pss, psv, pvv) = e.covariance;
                let mut cov = [0.0; 9];
                (cov[0], cov[1], cov[3], cov[4]) = (pss, psv, psv, pvv);
                let probe = FusedState {
                    stamp_ns: e.stamp_ns,
                    chainage_m: 0.0,
                    speed_mps: 0.0,
                    acceleration_mps2: 0.0,
                    covariance: cov,
                    source: String::new(),
                    sensor_states: Vec::new(),
                    plane: None,
                };
                self.nees.add(nees(&probe, de, ve), CHI2_95_2DOF);
                self.beyond_3_sigma.add(de, pss);
            }
            Lookup::Gap => self.in_reference_gaps += 1,
            Lookup::Outside => self.unmatched += 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_is_within_one_percent_and_rmse_exact() {
        let mut s = ErrorStats::default();
        for i in 1..=1000 {
            s.add(if i % 2 == 0 {
                i as f64 / 100.0
            } else {
                -(i as f64) / 100.0
            });
        }
        let m = s.summary().unwrap();
        assert!((m.p95_abs - 9.50).abs() / 9.50 < 0.011, "{}", m.p95_abs);
        assert_eq!(m.max_abs, 10.0);
        assert_eq!((m.min, m.max), (-9.99, 10.0));
        let exact = ((1..=1000).map(|i| (i as f64 / 100.0).powi(2)).sum::<f64>() / 1000.0).sqrt();
        assert!((m.rmse - exact).abs() < 1e-12);
    }

    #[test]
    fn estimates_are_scored_against_the_interpolated_reference_even_when_they_lag() {
        let mut m = AccuracyMeter::new(0.5);
        let est = |stamp_ns, chainage_m, speed_mps| FusedState {
            stamp_ns,
            chainage_m,
            speed_mps,
            acceleration_mps2: 0.0,
            covariance: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            source: String::new(),
            sensor_states: Vec::new(),
            plane: None,
        };
        let spans = [Span {
            label: "tunnel".into(),
            start_ns: 2_000_000_000,
            end_ns: Some(2_500_000_000),
        }];
        m.add_estimate(&est(1_500_000_000, 15.5, 10.0), &spans); // arrives before the reference reaches it
        for k in 0..=30 {
            let t = k as u64 * 100_000_000;
            m.add_reference(t, 10.0 * t as f64 / 1e9, 10.0, &spans);
        }
        m.add_estimate(&est(2_050_000_000, 20.5, 10.5), &spans);
        m.finish();
        let p = m.position.summary().unwrap();
        assert_eq!(p.samples, 2);
        assert!((p.max_abs - 0.5).abs() < 1e-9, "{p:?}");
        assert!((m.speed.summary().unwrap().max_abs - 0.5).abs() < 1e-9);
        assert_eq!(m.unmatched, 0);
        // e = (0.5, 0) and (0, 0.5) against unit covariance: NEES 0.25 each, both inside.
        let n = m.nees.summary().unwrap();
        assert_eq!(n.epochs, 2);
        assert!((n.mean - 0.25).abs() < 1e-9 && n.inside_95 == 1.0, "{n:?}");
        // Only the second estimate is in the tunnel.
        assert_eq!(m.windows.len(), 1);
        assert_eq!(m.windows[0].speed.summary().unwrap().samples, 1);
        assert_eq!(m.windows[0].position.summary().unwrap().max_abs, 0.0);
    }

    #[test]
    fn estimates_inside_a_gap_of_the_reference_are_counted_not_scored() {
        // A 10 Hz reference (a GNSS receiver) silent from 2 s to 29 s (a tunnel).
        let mut m = AccuracyMeter::new(0.5);
        let est = |stamp_ns: u64| FusedState {
            stamp_ns,
            chainage_m: 10.0 * stamp_ns as f64 / 1e9 + 1.0,
            speed_mps: 10.0,
            acceleration_mps2: 0.0,
            covariance: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            source: String::new(),
            sensor_states: Vec::new(),
            plane: None,
        };
        let stamps = (0..=20).chain(290..=300).map(|k| k * 100_000_000u64);
        for t in stamps {
            m.add_reference(t, 10.0 * t as f64 / 1e9, 10.0, &[]);
            // An estimate 50 ms after each sample, and every 100 ms through the gap.
            m.add_estimate(&est(t + 50_000_000), &[]);
        }
        for k in 21..290 {
            m.add_estimate(&est(k * 100_000_000 + 50_000_000), &[]);
        }
        m.finish();
        // Scored: after each sample before the gap but the last, and within the samples
        // after it (their last one has no sample after it).
        assert_eq!(m.position.summary().unwrap().samples, 20 + 10);
        assert!((m.position.summary().unwrap().max_abs - 1.0).abs() < 1e-9);
        // 2.05 s … 28.95 s: inside the gap, never scored against a line drawn across it.
        assert_eq!(m.in_reference_gaps, 270);
        assert_eq!(m.unmatched, 1);
    }
}

/// The truth in the plane at one stamp: east, north and east/north velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneSample {
    pub stamp_ns: u64,
    pub east_m: f64,
    pub north_m: f64,
    pub velocity_en_mps: (f64, f64),
}

/// East/north errors of a 2-D pipeline's states against the truth in the plane, matched by
/// stamp (the truth interpolated linearly between its samples). States may trail the truth
/// by the meter's lag; older truth is dropped, so memory stays flat over any log length.
#[derive(Debug, Clone)]
pub struct PlaneMeter {
    truth: VecDeque<PlaneSample>,
    retain_ns: u64,
    waiting: VecDeque<(u64, f64, f64, Option<[f64; 2]>)>,
    pub east: ErrorStats,
    pub north: ErrorStats,
    pub velocity_east: ErrorStats,
    pub velocity_north: ErrorStats,
}

impl PlaneMeter {
    pub fn new(lag_s: f64) -> Self {
        Self {
            truth: VecDeque::new(),
            retain_ns: ((lag_s + 2.0) * 1e9) as u64,
            waiting: VecDeque::new(),
            east: ErrorStats::default(),
            north: ErrorStats::default(),
            velocity_east: ErrorStats::default(),
            velocity_north: ErrorStats::default(),
        }
    }

    pub fn add_truth(&mut self, s: PlaneSample) {
        if self.truth.back().is_some_and(|b| b.stamp_ns >= s.stamp_ns) {
            return;
        }
        self.truth.push_back(s);
        while self
            .truth
            .front()
            .is_some_and(|f| f.stamp_ns + self.retain_ns < s.stamp_ns)
        {
            self.truth.pop_front();
        }
        while self.waiting.front().is_some_and(|w| w.0 <= s.stamp_ns) {
            let w = self.waiting.pop_front().expect("peeked");
            self.score(w);
        }
    }

    pub fn add_state(&mut self, state: &FusedState) {
        let Some(p) = &state.plane else { return };
        let w = (state.stamp_ns, p.east_m, p.north_m, p.velocity_en_mps);
        match self.truth.back() {
            Some(b) if b.stamp_ns >= state.stamp_ns => self.score(w),
            _ => self.waiting.push_back(w),
        }
    }

    fn score(&mut self, (t, e, n, v): (u64, f64, f64, Option<[f64; 2]>)) {
        let i = self.truth.partition_point(|s| s.stamp_ns < t);
        let (Some(a), Some(b)) = (
            i.checked_sub(1).and_then(|j| self.truth.get(j)),
            self.truth.get(i),
        ) else {
            return;
        };
        let w = (t - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns).max(1) as f64;
        let lerp = |x: f64, y: f64| x + w * (y - x);
        self.east.add(e - lerp(a.east_m, b.east_m));
        self.north.add(n - lerp(a.north_m, b.north_m));
        if let Some([ve, vn]) = v {
            self.velocity_east
                .add(ve - lerp(a.velocity_en_mps.0, b.velocity_en_mps.0));
            self.velocity_north
                .add(vn - lerp(a.velocity_en_mps.1, b.velocity_en_mps.1));
        }
    }

    pub fn summary(&self) -> Option<PlaneSummary> {
        Some(PlaneSummary {
            east_error_m: self.east.summary()?,
            north_error_m: self.north.summary()?,
            velocity_east_error_mps: self.velocity_east.summary(),
            velocity_north_error_mps: self.velocity_north.summary(),
        })
    }
}

/// A 2-D pipeline's errors in the plane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlaneSummary {
    pub east_error_m: ErrorSummary,
    pub north_error_m: ErrorSummary,
    pub velocity_east_error_mps: Option<ErrorSummary>,
    pub velocity_north_error_mps: Option<ErrorSummary>,
}
