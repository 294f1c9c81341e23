//! What every simulated sensor sees at one simulation step, and where it puts its messages.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use railfuse_catalog::messages::{
    BalisePassage, EddyCurrentBlock, Event, GnssFix, GroundTruth, Imu, LoopPosition, Odometer,
    RadarSpeed, TimeReference, Vehicle,
};

use super::ride::RideSample;
use super::track::Track;

/// The true world at one simulation step: the front end's motion along the track (its
/// chainage, speed, place), what is around it, and what each sensor's motion is taken from
/// ([`super::kinematics::motion`]: the track's exact geometry, the train as installed, the
/// body's vibration).
#[derive(Clone, Copy)]
pub struct World<'a> {
    pub t_ns: u64,
    /// Step length, s.
    pub dt: f64,
    pub chainage_m: f64,
    pub speed_mps: f64,
    pub acceleration_mps2: f64,
    pub east_m: f64,
    pub north_m: f64,
    /// Clockwise from north.
    pub heading_rad: f64,
    /// 1/m, positive turning right.
    pub curvature: f64,
    pub in_tunnel: bool,
    /// RTK correction data reaches the GNSS receiver.
    pub corrections: bool,
    /// The GNSS receiver sees no satellites (a scripted loss, as source 003's 150 s outage).
    pub gnss_outage: bool,
    /// The share of the sky the receiver sees (1 in the open; cuttings less).
    pub sky_view: f64,
    /// The pull of multipath on a fix here (east, north, m), which the receiver does not
    /// report: 0 away from buildings and cuttings.
    pub gnss_multipath: (f64, f64),
    pub track: &'a Track,
    /// The train as installed (the simulated truth, not the drawing the log carries).
    pub vehicle: &'a Vehicle,
    pub ride: RideSample,
}

impl World<'_> {
    /// The chainage of the place `along_m` from the front end (a lever arm's x).
    pub fn chainage_at(&self, along_m: f64) -> f64 {
        self.chainage_m + along_m
    }

    /// The speed along the rail `along_m` from the front end, m/s: the chainage's rate times
    /// the rail's length per metre of chainage on the gradient there.
    pub fn rail_speed_at(&self, along_m: f64) -> f64 {
        let g = self.track.gradient(self.chainage_at(along_m));
        self.speed_mps * (1.0 + g * g).sqrt()
    }

    /// The sub-step time (ns) at which the train was at `chainage` during the last step,
    /// assuming constant speed over the step: for crossing detectors.
    pub fn time_at(&self, chainage: f64) -> u64 {
        let back_s = if self.speed_mps > 1e-6 {
            ((self.chainage_m - chainage) / self.speed_mps).clamp(0.0, self.dt)
        } else {
            0.0
        };
        self.t_ns - (back_s * 1e9) as u64
    }
}

/// A message produced by the simulation, before it is written.
#[derive(Debug, Clone)]
pub enum Emit {
    Gnss(GnssFix),
    Imu(Imu),
    Radar(RadarSpeed),
    Odometer(usize, Odometer),
    Loop(LoopPosition),
    Balise(BalisePassage),
    EddyCurrent(EddyCurrentBlock),
    Truth(GroundTruth),
    Event(Event),
    /// A PPS edge for recorder `.0` of a run of several.
    TimeReference(usize, TimeReference),
}

struct Pending {
    log_time_ns: u64,
    seq: u64,
    emit: Emit,
}
impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        (self.log_time_ns, self.seq) == (o.log_time_ns, o.seq)
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Pending {
    // Reversed: the heap pops the earliest receive time first, ties in emission order.
    fn cmp(&self, o: &Self) -> Ordering {
        (o.log_time_ns, o.seq).cmp(&(self.log_time_ns, self.seq))
    }
}

/// Messages waiting for their receive time (sensor time plus latency), so the log is written
/// in receive-time order as a real recorder would write it.
#[derive(Default)]
pub struct Outbox {
    heap: BinaryHeap<Pending>,
    seq: u64,
}

impl Outbox {
    pub fn push(&mut self, log_time_ns: u64, emit: Emit) {
        self.seq += 1;
        self.heap.push(Pending {
            log_time_ns,
            seq: self.seq,
            emit,
        });
    }

    /// Takes the next message received at or before `now_ns`.
    pub fn pop_due(&mut self, now_ns: u64) -> Option<(u64, Emit)> {
        if self.heap.peek()?.log_time_ns <= now_ns {
            self.heap.pop().map(|p| (p.log_time_ns, p.emit))
        } else {
            None
        }
    }
}

/// A simulated sensor: looks at the world every step and emits what it measures.
pub trait SimSensor {
    fn step(&mut self, world: &World<'_>, out: &mut Outbox);
}

/// A fixed-rate schedule in integer nanoseconds (no drift from float accumulation).
#[derive(Debug, Clone, Copy)]
pub struct Schedule {
    next_ns: u64,
    period_ns: u64,
}

impl Schedule {
    pub fn new(start_ns: u64, rate_hz: f64) -> Self {
        Self {
            next_ns: start_ns,
            period_ns: (1e9 / rate_hz).round() as u64,
        }
    }
    /// True (and advances) when a sample is due at `t_ns`.
    pub fn due(&mut self, t_ns: u64) -> bool {
        if t_ns >= self.next_ns {
            self.next_ns += self.period_ns;
            true
        } else {
            false
        }
    }
    pub fn period_s(&self) -> f64 {
        self.period_ns as f64 / 1e9
    }
}

pub fn seconds(s: f64) -> u64 {
    (s * 1e9).round() as u64
}
