//! The IMU's readings beside what the train's motion gives at the IMU's place, low-passed
//! alike and taken once a second.
//!
//! The IMU is averaged over 0.1 s; each such mean is paired with the motion over the same
//! 0.1 s (the reference's smoothed chainage, speed and acceleration through the track map's
//! geometry and the train's drawing, [`railfuse_catalog::train_motion::point_motion`]). Both
//! go through the same low-pass (Butterworth, order 4, 0.1 Hz), which takes out the body's
//! vibration (its modes are at 0.8 Hz and above and would otherwise leak through any
//! average) and, being linear and the same on both sides, leaves the model
//! `f = Mᵀ f_b + b` as it was. A gap (no IMU, no reference state) restarts the filters, and
//! their first 20 s are not used.
//!
//! Memory: one small record per 0.1 s of IMU data and per 50 ms of smoothed states (about
//! 2 MB an hour); the IMU's own messages are streamed.

use std::path::Path;

use nalgebra::Vector3;
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{FusedState, Imu, SensorMount, TrackMap, Vehicle};
use railfuse_catalog::train_motion::{point_motion, AlongTrack};
use railfuse_catalog::{seconds_between, topics};
use railfuse_refuse::eddy_current::butterworth::Butterworth;
use railfuse_refuse::spec::Pipelines;

use crate::error::{Error, Result};
use crate::mounting::Bin;
use crate::reference::{ReferenceReplay, REFERENCE_PIPELINE};

/// The IMU's means, ns.
const BIN_NS: u64 = 100_000_000;
/// Fewer IMU samples than this in a mean (a gap): it is left out.
const MIN_SAMPLES: u32 = 2;
/// The low-pass's corner, Hz: below the ride's modes (0.8 Hz and up), above the changes of
/// acceleration and curvature the angles are seen through.
const LOW_PASS_HZ: f64 = 0.1;
/// One filtered sample in this many means is used (1 s).
const DECIMATE: usize = 10;
/// After a (re)start the filters' first means are not used (20 s: their transient).
const SETTLE: usize = 200;
/// Smoothed states kept at most this often, ns.
const STATE_EVERY_NS: u64 = 50_000_000;
/// A bin whose middle is further than this from a smoothed state either side is left out, s.
const MAX_STATE_GAP_S: f64 = 1.0;

/// How far the track is shifted to take the model's change with the reference's chainage
/// error, m (beside the map's 10 m curvature span, so the change is smooth).
const SHIFT_M: f64 = 2.0;
/// The signals low-passed alike: the IMU's force and rate, the model's, and the model's change
/// per metre of chainage error.
const SIGNALS: usize = 6;

/// The low-passes of the signals' eighteen components.
struct LowPass {
    filters: Vec<Butterworth>,
    since_start: usize,
}

impl LowPass {
    fn new() -> Result<Self> {
        let f = Butterworth::lowpass(LOW_PASS_HZ, 1e9 / BIN_NS as f64).map_err(Error::Config)?;
        Ok(LowPass {
            filters: vec![f; 3 * SIGNALS],
            since_start: 0,
        })
    }

    fn restart(&mut self) {
        self.filters.iter_mut().for_each(Butterworth::reset);
        self.since_start = 0;
    }

    /// The signals through the filters; the filtered values when due.
    fn step(&mut self, x: [Vector3<f64>; SIGNALS]) -> Option<[Vector3<f64>; SIGNALS]> {
        let mut out = [Vector3::zeros(); SIGNALS];
        for (k, v) in x.iter().enumerate() {
            for i in 0..3 {
                out[k][i] = self.filters[3 * k + i].step(v[i]);
            }
        }
        self.since_start += 1;
        (self.since_start > SETTLE && self.since_start.is_multiple_of(DECIMATE)).then_some(out)
    }
}

/// One run's bins, and what they were made with.
pub struct RunBins {
    pub bins: Vec<Bin>,
    /// The train the motion was taken on (the configuration's `[vehicle]`, else the log's).
    pub vehicle: Vehicle,
    /// The IMU's place and drawing mounting.
    pub mount: SensorMount,
    pub imu_messages: u64,
    /// Bins left out: too few samples, or no reference state near them.
    pub left_out: usize,
}

#[derive(Default)]
struct Accumulator {
    start_ns: u64,
    force: Vector3<f64>,
    rate: Vector3<f64>,
    samples: u32,
}

struct MeanBin {
    mid_ns: u64,
    force: Vector3<f64>,
    rate: Vector3<f64>,
}

/// What is read from the replay's fused log.
#[derive(Default)]
struct Read {
    means: Vec<MeanBin>,
    states: Vec<(u64, f64, f64, f64)>,
    map: Option<TrackMap>,
    vehicle: Option<Vehicle>,
    imu_messages: u64,
    short_bins: usize,
}

impl Read {
    fn imu(&mut self, acc: &mut Option<Accumulator>, m: &Imu) {
        self.imu_messages += 1;
        if let Some(a) = acc.as_mut().filter(|a| m.stamp_ns >= a.start_ns + BIN_NS) {
            self.close(a);
            *acc = None;
        }
        let a = acc.get_or_insert_with(|| Accumulator {
            start_ns: m.stamp_ns,
            ..Default::default()
        });
        let (f, w) = (m.specific_force_mps2, m.angular_rate_radps);
        if f.iter().chain(&w).all(|v| v.is_finite()) {
            a.force += Vector3::from(f);
            a.rate += Vector3::from(w);
            a.samples += 1;
        }
    }

    fn close(&mut self, a: &Accumulator) {
        if a.samples < MIN_SAMPLES {
            self.short_bins += 1;
            return;
        }
        let n = a.samples as f64;
        self.means.push(MeanBin {
            mid_ns: a.start_ns + BIN_NS / 2,
            force: a.force / n,
            rate: a.rate / n,
        });
    }

    fn state(&mut self, s: &FusedState) {
        let finite = [s.chainage_m, s.speed_mps, s.acceleration_mps2]
            .iter()
            .all(|v| v.is_finite());
        let due = self
            .states
            .last()
            .is_none_or(|l| s.stamp_ns >= l.0 + STATE_EVERY_NS);
        if finite && due {
            self.states
                .push((s.stamp_ns, s.chainage_m, s.speed_mps, s.acceleration_mps2));
        }
    }
}

fn read(path: &Path, imu: &str) -> Result<Read> {
    let smoothed = topics::fused_smoothed(REFERENCE_PIPELINE);
    let mut reader = LogReader::open(path)?;
    let mut r = Read::default();
    let mut acc = None;
    while let Some(record) = reader.next() {
        let LogRecord::Message(m) = record? else {
            continue;
        };
        let topic = m.channel.topic.as_str();
        if topic == imu && m.is::<Imu>() {
            r.imu(&mut acc, &m.decode(path)?);
        } else if topic == smoothed && m.is::<FusedState>() {
            r.state(&m.decode(path)?);
        } else if r.map.is_none() && m.is::<TrackMap>() {
            r.map = Some(m.decode(path)?);
        } else if r.vehicle.is_none() && m.is::<Vehicle>() {
            r.vehicle = Some(m.decode(path)?);
        }
    }
    if let Some(a) = acc {
        r.close(&a);
    }
    // The smoother writes its states at the end, in time order; a log may interleave.
    r.states.sort_by_key(|s| s.0);
    Ok(r)
}

/// The front end's motion at `t_ns`, interpolated between the smoothed states around it.
fn motion_at(states: &[(u64, f64, f64, f64)], t_ns: u64) -> Option<AlongTrack> {
    let i = states.partition_point(|s| s.0 <= t_ns);
    let (a, b) = (states.get(i.checked_sub(1)?)?, states.get(i)?);
    let span = seconds_between(a.0, b.0);
    if span > 2.0 * MAX_STATE_GAP_S || span <= 0.0 {
        return None;
    }
    let f = seconds_between(a.0, t_ns) / span;
    let lerp = |x: f64, y: f64| x + (y - x) * f;
    Some(AlongTrack {
        chainage_m: lerp(a.1, b.1),
        speed_mps: lerp(a.2, b.2),
        acceleration_mps2: lerp(a.3, b.3),
    })
}

/// What the model says the IMU reads over a bin with the front end moving as `along`: the
/// body's specific force and rate at the IMU's place, and their change per metre of chainage
/// (what a chainage error of the reference turns into).
fn modelled(
    map: &TrackMap,
    vehicle: &Vehicle,
    mount: &SensorMount,
    along: AlongTrack,
) -> [Vector3<f64>; 4] {
    let span = BIN_NS as f64 / 1e9;
    let m = point_motion(map, vehicle, along, mount, span);
    let shifted = |ds: f64| {
        let at = AlongTrack {
            chainage_m: along.chainage_m + ds,
            ..along
        };
        point_motion(map, vehicle, at, mount, span)
    };
    let (ahead, behind) = (shifted(SHIFT_M), shifted(-SHIFT_M));
    let per_m = |a: Vector3<f64>, b: Vector3<f64>| (a - b) / (2.0 * SHIFT_M);
    [
        m.specific_force,
        m.angular_rate,
        per_m(ahead.specific_force, behind.specific_force),
        per_m(ahead.angular_rate, behind.angular_rate),
    ]
}

/// The bins of one replayed run (`run`: its index among the runs calibrated together).
pub fn run_bins(replay: &ReferenceReplay, config: &Pipelines, run: usize) -> Result<RunBins> {
    let read = read(&replay.fused, &replay.imu)?;
    let fail = |message: String| Error::Run {
        input: replay.input.clone(),
        message,
    };
    let map = config.track.clone().or(read.map).ok_or_else(|| {
        fail(
            "has no track map (and the configuration names none): the IMU's mounting is \
              found through the track's gradient, cant and curves"
                .into(),
        )
    })?;
    if read.states.is_empty() {
        return Err(fail(format!(
            "the reference replay without {} gave no smoothed state",
            replay.imu
        )));
    }
    let vehicle = config
        .vehicle
        .clone()
        .or(read.vehicle)
        .unwrap_or_else(Vehicle::point);
    let mount = vehicle.mount_or_front(&replay.imu);
    let first_ns = read.means.first().map_or(0, |b| b.mid_ns);
    let mut bins = Vec::with_capacity(read.means.len() / DECIMATE);
    let mut low_pass = LowPass::new()?;
    let mut last_ns: Option<u64> = None;
    for b in &read.means {
        let Some(along) = motion_at(&read.states, b.mid_ns) else {
            low_pass.restart();
            continue;
        };
        // The means must follow each other without a gap for the filters to run on.
        if last_ns.is_some_and(|l| b.mid_ns > l + BIN_NS + BIN_NS / 2) {
            low_pass.restart();
        }
        last_ns = Some(b.mid_ns);
        let model = modelled(&map, &vehicle, &mount, along);
        let Some([force, rate, body_force, body_rate, force_per_m, rate_per_m]) =
            low_pass.step([b.force, b.rate, model[0], model[1], model[2], model[3]])
        else {
            continue;
        };
        bins.push(Bin {
            time_s: seconds_between(first_ns, b.mid_ns),
            run,
            specific_force: force,
            angular_rate: rate,
            body_force,
            body_rate,
            body_force_per_m: force_per_m,
            body_rate_per_m: rate_per_m,
        });
    }
    Ok(RunBins {
        left_out: read.short_bins,
        bins,
        vehicle,
        mount,
        imu_messages: read.imu_messages,
    })
}
