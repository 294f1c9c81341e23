//! A run's dead-reckoned path tied by least squares to what it measured of its place: the
//! fixes around a gap, the receiver's course, and where the train stood, its gyro's bias.
//!
//! ```text
//! ψ(t) = ψ₀ + Σ (turn − b(τ) dτ),   p(t) = p₀ + k Σ d·(sin ψ, cos ψ)
//! ```
//!
//! p₀, ψ₀ where the path starts, k the odometer's scale, and b(τ) the gyro's bias, linear
//! between knots every [`BIAS_KNOT_S`]: a MEMS gyro's bias wanders over the minutes a
//! crossing takes, more than a bias and a drift can follow. A random-walk prior of
//! [`BIAS_WALK`] holds each knot to its neighbours, so where nothing else is measured (a
//! tunnel) the bias stays as smooth as it can between the fixes either side, and where the
//! receiver still gives its Doppler course (RTK lost, a station's multipath) that course
//! steers it. Every miss counts in metres of a tie fix of [`UNIT_M`]: the fixes across the
//! track (along it at [`ALONG_WEIGHT`]: an odometer slides when the train brakes), the
//! course for its σ at the speed, the bias at a standstill for [`STANDSTILL_WEIGHT`], the
//! knots' steps for their walk. Gauss–Newton, the Jacobian by differences.

use nalgebra::{DMatrix, DVector};

use crate::fixes::{Course, Fix};
use crate::motion::MotionStep;

/// The unknowns' places: start east, north, heading, distance scale, then the bias knots.
pub const EAST: usize = 0;
pub const NORTH: usize = 1;
pub const HEADING: usize = 2;
pub const SCALE: usize = 3;
pub const BIAS: usize = 4;

/// The gyro's bias is linear between knots this far apart, s.
pub const BIAS_KNOT_S: f64 = 10.0;

/// The walk the prior allows the bias, rad/s per √s: a MEMS gyro's, somewhat more than the
/// simulated one's 2e-5 so as not to copy it.
pub const BIAS_WALK: f64 = 3e-5;

/// The σ of a tie fix across the track, in which every miss is counted, m.
pub const UNIT_M: f64 = 0.02;

/// Along the track a tie fix counts this much of its miss.
const ALONG_WEIGHT: f64 = 0.05;

/// The receiver's velocity σ a course is taken to have (a course at speed v: this / v rad),
/// m/s: a Doppler velocity's usual 0.05–0.1 m/s, the larger.
const COURSE_SPEED_SIGMA_MPS: f64 = 0.1;

/// A standstill's bias counts as a miss of this many metres per rad/s: 1 cm for 1e-5
/// rad/s, a tenth of what a MEMS gyro's bias wanders in a minute.
const STANDSTILL_WEIGHT: f64 = 1e3;

/// A dead-reckoned position: its time and east, north.
pub type Point = (u64, f64, f64);

/// What a path is tied to.
pub struct Tie<'a> {
    pub steps: &'a [MotionStep],
    /// Where the path starts (the steps' motion is after it).
    pub start_ns: u64,
    pub fixes: &'a [Fix],
    pub courses: &'a [Course],
    /// The bias the gyro read standing (rad/s) and when (s from `start_ns`).
    pub standstill: Option<(f64, f64)>,
}

impl Tie<'_> {
    /// The number of bias knots the steps need.
    pub fn knots(&self) -> usize {
        let end = self.steps.last().map_or(self.start_ns, |s| s.stamp_ns);
        let span = (end - self.start_ns) as f64 / 1e9;
        (span / BIAS_KNOT_S).ceil() as usize + 1
    }

    /// A first guess: at `(east, north)` facing `heading`, scale 1, no bias.
    pub fn start(&self, east: f64, north: f64, heading: f64) -> Vec<f64> {
        let mut x = vec![0.0; BIAS + self.knots()];
        (x[EAST], x[NORTH], x[HEADING], x[SCALE]) = (east, north, heading, 1.0);
        x
    }

    /// The dead-reckoned positions at the start and each step's end.
    pub fn reckon(&self, x: &[f64]) -> Vec<Point> {
        let (mut p, mut turn, mut last_ns) = ((x[EAST], x[NORTH]), 0.0, self.start_ns);
        let mut out = Vec::with_capacity(self.steps.len() + 1);
        out.push((self.start_ns, p.0, p.1));
        for s in self.steps {
            let dt = (s.stamp_ns - last_ns) as f64 / 1e9;
            let mid = ((last_ns + s.stamp_ns) / 2 - self.start_ns) as f64 / 1e9;
            last_ns = s.stamp_ns;
            let step_turn = s.turn_rad - bias_at(x, mid) * dt;
            let psi = x[HEADING] + turn + step_turn / 2.0;
            turn += step_turn;
            let len = x[SCALE] * s.distance_m;
            p = (p.0 + len * psi.sin(), p.1 + len * psi.cos());
            out.push((s.stamp_ns, p.0, p.1));
        }
        out
    }

    /// Every miss for `x`, in metres of [`UNIT_M`]: the fixes' (along, across), the
    /// standstill's, the courses', the knots' steps.
    fn misses(&self, x: &[f64]) -> Vec<f64> {
        let path = self.reckon(x);
        let fixes = self.fixes.iter().flat_map(|f| {
            let (e, n, ue, un) = at(&path, f.stamp_ns);
            let (me, mn) = (e - f.east_m, n - f.north_m);
            [ALONG_WEIGHT * (me * ue + mn * un), me * un - mn * ue]
        });
        let standstill = self
            .standstill
            .map(|(bias, t)| STANDSTILL_WEIGHT * (bias_at(x, t) - bias));
        let courses = self.courses.iter().map(|c| {
            let (_, _, ue, un) = at(&path, c.stamp_ns);
            let sigma = COURSE_SPEED_SIGMA_MPS / c.speed_mps;
            UNIT_M * wrap(ue.atan2(un) - c.course_rad) / sigma
        });
        // A steady drift is free (a bias that wanders one way for a minute); only its
        // changes from knot to knot are held, as a walk's second differences.
        let change_sigma = BIAS_WALK * (2.0 * BIAS_KNOT_S).sqrt();
        let walk = x[BIAS..]
            .windows(3)
            .map(move |w| UNIT_M * (w[2] - 2.0 * w[1] + w[0]) / change_sigma);
        fixes.chain(standstill).chain(courses).chain(walk).collect()
    }

    /// Gauss–Newton from `x`, the unknowns not `free` kept as they are; the unknowns and the
    /// fixes' misses across the track (RMS), `None` where the normal equations are singular.
    pub fn solve(&self, mut x: Vec<f64>, free: &[bool]) -> Option<(Vec<f64>, f64)> {
        let unknowns: Vec<usize> = (0..x.len()).filter(|&k| free[k]).collect();
        for _ in 0..8 {
            let r = DVector::from_vec(self.misses(&x));
            let mut j = DMatrix::zeros(r.len(), unknowns.len());
            for (c, &k) in unknowns.iter().enumerate() {
                let h = match k {
                    EAST | NORTH => 1e-3,
                    HEADING | SCALE => 1e-6,
                    _ => 1e-8,
                };
                let mut xh = x.clone();
                xh[k] += h;
                let rh = DVector::from_vec(self.misses(&xh));
                j.set_column(c, &((rh - &r) / h));
            }
            let dx = (j.transpose() * &j)
                .cholesky()?
                .solve(&(-j.transpose() * r));
            for (c, &k) in unknowns.iter().enumerate() {
                x[k] += dx[c];
            }
        }
        let r = self.misses(&x);
        let n = self.fixes.len().max(1);
        let across = r[..2 * self.fixes.len()].iter().skip(1).step_by(2);
        let rms = (across.map(|e| e * e).sum::<f64>() / n as f64).sqrt();
        Some((x, rms))
    }
}

/// The bias at `t` s from the start, linear between the knots.
pub fn bias_at(x: &[f64], t: f64) -> f64 {
    let knots = &x[BIAS..];
    let u = (t / BIAS_KNOT_S).max(0.0);
    let j = (u.floor() as usize).min(knots.len().saturating_sub(2));
    let f = (u - j as f64).clamp(0.0, 1.0);
    match knots.len() {
        0 => 0.0,
        1 => knots[0],
        _ => knots[j] * (1.0 - f) + knots[j + 1] * f,
    }
}

/// The reckoned position at `t_ns`, between the points around it, and the unit direction of
/// travel there.
pub fn at(path: &[Point], t_ns: u64) -> (f64, f64, f64, f64) {
    let i = path
        .partition_point(|p| p.0 < t_ns)
        .clamp(1, path.len() - 1);
    let (a, b) = (path[i - 1], path[i]);
    let f = if b.0 > a.0 {
        ((t_ns.saturating_sub(a.0)) as f64 / (b.0 - a.0) as f64).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (de, dn) = (b.1 - a.1, b.2 - a.2);
    let len = de.hypot(dn).max(1e-9);
    (a.1 + f * de, a.2 + f * dn, de / len, dn / len)
}

/// An angle in (−π, π].
pub fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let a = a.rem_euclid(TAU);
    if a > PI {
        a - TAU
    } else {
        a
    }
}

/// The gyro's mean rate over the steps where the train stood, and their mean time (s from
/// `start_ns`), if it stood at least `min_s`.
pub fn standstill_bias(steps: &[MotionStep], start_ns: u64, min_s: f64) -> Option<(f64, f64)> {
    let (mut turn, mut time, mut when, mut last) = (0.0, 0.0, 0.0, start_ns);
    for s in steps {
        let dt = (s.stamp_ns - last) as f64 / 1e9;
        if s.distance_m == 0.0 {
            turn += s.turn_rad;
            time += dt;
            when += dt * ((s.stamp_ns - start_ns) as f64 / 1e9 - dt / 2.0);
        }
        last = s.stamp_ns;
    }
    (time >= min_s).then(|| (turn / time, when / time))
}
