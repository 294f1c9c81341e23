//! A simulated run written by two or three recorders, each on its own clock, as a train
//! carries them: the GNSS/INS box, the odometry rack, a laptop on the radar. Each recorder
//! writes its own file, stamps what it records on its own clock (an offset and a drift against
//! GNSS time), and logs a time reference each second from the receiver's PPS, so that its
//! clock can be recovered from the file alone (`railfuse info` / `--align gnss`).

use railfuse_catalog::messages::TimeReference;
use railfuse_catalog::run::{ClockMap, ClockOffset};
use railfuse_catalog::topics;
use rand_chacha::ChaCha8Rng;

use super::sensors::{gauss, rng_stream};
use super::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

/// At most this many recorders: GNSS/INS box, odometry rack, radar laptop.
pub const MAX_RECORDERS: usize = 3;
/// The PPS edge read on a recorder's clock: its interrupt latency's jitter, σ 2 µs.
const PPS_JITTER_NS: f64 = 2_000.0;
/// The ZDA sentence naming the edge arrives this long after it (its log time).
const ZDA_DELAY_S: f64 = 0.1;

/// One recorder: its name (its file is `<name>.mcap`) and its clock against GNSS time.
#[derive(Debug, Clone, PartialEq)]
pub struct SimRecorder {
    pub name: String,
    /// A positive offset is a clock ahead of GNSS time; the drift counts from the run's start.
    pub offset_s: f64,
    pub drift_ppm: f64,
}

impl std::str::FromStr for SimRecorder {
    type Err = String;
    /// `NAME`, `NAME=+0.35` or `NAME=-1.2,+20ppm`.
    fn from_str(s: &str) -> Result<Self, String> {
        let given = match s.contains('=') {
            true => s.to_owned(),
            false => format!("{s}=0"),
        };
        let c: ClockOffset = given.parse()?;
        let name = c.file.to_string_lossy().into_owned();
        let fine = |ch: char| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-';
        if name.is_empty() || !name.chars().all(fine) {
            return Err(format!(
                "recorder '{name}': a name of letters, digits, '_' and '-' (it names its file)"
            ));
        }
        Ok(Self {
            name,
            offset_s: c.clock.offset_s(),
            drift_ppm: c.clock.drift_ppm,
        })
    }
}

impl SimRecorder {
    /// Its clock at GNSS time `t_ns`, from the run's start.
    pub fn clock(&self, start_ns: u64) -> SimClock {
        SimClock {
            offset_ns: (self.offset_s * 1e9).round() as i64,
            drift_ppm: self.drift_ppm,
            start_ns,
        }
    }
}

/// A recorder's clock: GNSS time `t` reads `t + offset + drift·(t − start)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimClock {
    offset_ns: i64,
    drift_ppm: f64,
    start_ns: u64,
}

impl SimClock {
    pub fn local(&self, t_ns: u64) -> u64 {
        let drift = (t_ns as f64 - self.start_ns as f64) * self.drift_ppm * 1e-6;
        (t_ns as i128 + self.offset_ns as i128 + drift.round() as i128).max(0) as u64
    }

    /// The same clock as a reader models it ([`ClockMap`]: local time to GNSS time), for
    /// comparing an estimate with the truth.
    pub fn as_clock_map(&self) -> ClockMap {
        let origin = self.local(self.start_ns);
        ClockMap {
            offset_ns: self.offset_ns,
            drift_ppm: self.drift_ppm / (1.0 + self.drift_ppm * 1e-6),
            origin_ns: origin,
        }
    }
}

/// Which recorder logs `topic` in a run of `n`: the first has the GNSS receiver, the IMU,
/// the map, the events and the truth; the second the odometry (and the radar where there is
/// no third); the third the radar.
pub fn recorder_of(topic: &str, n: usize) -> usize {
    let odometry = [
        topics::ODOMETER_1,
        topics::ODOMETER_2,
        topics::LOOP_POSITION,
        topics::BALISE,
        topics::EDDY_CURRENT,
    ];
    match (n, topic) {
        (0 | 1, _) => 0,
        (_, t) if odometry.contains(&t) => 1,
        (2, topics::RADAR_SPEED) => 1,
        (_, topics::RADAR_SPEED) => 2,
        _ => 0,
    }
}

/// The receiver's PPS as recorder `index` reads it: each second of GNSS time, a time
/// reference whose `local_ns` the writer moves onto the recorder's clock.
pub struct PpsReference {
    index: usize,
    schedule: Schedule,
}

impl PpsReference {
    pub fn new(index: usize, start_ns: u64) -> Self {
        Self {
            index,
            schedule: Schedule::new(start_ns, 1.0),
        }
    }
}

impl SimSensor for PpsReference {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        if !self.schedule.due(w.t_ns) {
            return;
        }
        let edge = w.t_ns;
        out.push(
            edge + seconds(ZDA_DELAY_S),
            Emit::TimeReference(
                self.index,
                TimeReference {
                    stamp_ns: edge,
                    local_ns: edge,
                    source: "pps".into(),
                },
            ),
        );
    }
}

/// Recorder `index`'s PPS, as a sensor of the simulation.
pub fn pps(index: usize, start_ns: u64) -> Box<dyn SimSensor> {
    Box::new(PpsReference::new(index, start_ns))
}

/// The jitter of each recorder's PPS reading, each its own random stream.
pub fn pps_jitter(seed: u64, index: usize) -> ChaCha8Rng {
    rng_stream(seed, 40 + index as u64)
}

/// A PPS edge at GNSS time `edge_ns` as `clock` reads it.
pub fn read_pps(clock: &SimClock, edge_ns: u64, rng: &mut ChaCha8Rng) -> u64 {
    let jitter = gauss(rng, PPS_JITTER_NS).round() as i64;
    (clock.local(edge_ns) as i64 + jitter).max(0) as u64
}
