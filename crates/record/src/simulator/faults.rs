//! Fault injection: make one device fail for a window of the run, as a working-state detector
//! must see it — it goes silent (`dropout`), freezes its last output (`stuck`), or its output
//! jumps by a constant (`bias=B`, in the quantity's SI unit: m for GNSS position along the
//! direction of travel, m/s for radar and odometer speed, m/s² for IMU specific force, m for
//! loop position). The log gets `fault_injected` / `fault_cleared` events at the window's
//! edges: markers for evaluation, not signals for the filters.
//!
//! Written on the command line as `DEVICE:MODE:START:END[:reported]` (seconds from the start of
//! the run), e.g. `radar:dropout:200:260`, `gnss:bias=30:150:250`, `imu:stuck:100:160`. With
//! `:reported` the device also says so itself: `device_fault` / `device_recovered` events
//! naming its topic, which federated detectors honour.
//!
//! The track map is a device too: `map:offset=D:START:END` publishes the stretch of line the
//! train covers between START and END shifted D m to the left (a survey blunder, a map of the
//! wrong track), which a map check must catch.

use railfuse_catalog::messages::{Event, EventKind};
use serde::{Deserialize, Serialize};

use super::world::{seconds, Emit};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultMode {
    Dropout,
    Stuck,
    Bias(f64),
    /// The map only: a stretch published this far to the left, m.
    Offset(f64),
    /// Its stamps this many seconds late (a driver that stamps a message when it arrives,
    /// not when it was measured): the measurement is older than its stamp says.
    Late(f64),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultSpec {
    /// gnss, imu, radar, odometer1, odometer2, loop, balise, eddy_current, map or
    /// corrections (the RTK correction link).
    pub device: String,
    pub mode: FaultMode,
    pub start_s: f64,
    pub end_s: f64,
    /// The device reports its fault and recovery in the log.
    #[serde(default)]
    pub reported: bool,
}

pub const DEVICES: &[&str] = &[
    "gnss",
    "imu",
    "radar",
    "odometer1",
    "odometer2",
    "loop",
    "balise",
    "eddy_current",
    "map",
    "corrections",
];

/// A `--fault DEVICE:MODE:START:END[:reported]` that does not parse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FaultSpecError {
    #[error("'{0}': a fault is DEVICE:MODE:START:END[:reported], e.g. radar:dropout:200:260")]
    Shape(String),
    #[error("'{spec}': unknown device '{device}' (devices: {})", DEVICES.join(", "))]
    UnknownDevice { spec: String, device: String },
    #[error(
        "'{spec}': unknown mode '{mode}' (dropout, stuck, bias=VALUE, late=SECONDS; the map: offset=METRES; corrections: dropout)"
    )]
    UnknownMode { spec: String, mode: String },
    #[error("'{0}': START and END are seconds from the start of the run")]
    Times(String),
    #[error("'{0}': the window ends before it starts")]
    EmptyWindow(String),
}

impl std::str::FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(s: &str) -> Result<Self, FaultSpecError> {
        let parts: Vec<&str> = s.split(':').collect();
        let (device, mode, start, end, reported) = match parts[..] {
            [d, m, a, b] => (d, m, a, b, false),
            [d, m, a, b, "reported"] => (d, m, a, b, true),
            _ => return Err(FaultSpecError::Shape(s.to_owned())),
        };
        if !DEVICES.contains(&device) {
            return Err(FaultSpecError::UnknownDevice {
                spec: s.to_owned(),
                device: device.to_owned(),
            });
        }
        let value = |prefix: &str| {
            mode.strip_prefix(prefix)
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| v.is_finite())
        };
        let mode = match (device, mode) {
            ("map", _) => value("offset=").map(FaultMode::Offset),
            // The RTK correction link can only be lost: the receiver falls back to single
            // point (then float, then fixed once it returns).
            ("corrections", m) => (m == "dropout").then_some(FaultMode::Dropout),
            (_, "dropout") => Some(FaultMode::Dropout),
            (_, "stuck") => Some(FaultMode::Stuck),
            (_, m) if m.starts_with("late=") => {
                value("late=").filter(|d| *d >= 0.0).map(FaultMode::Late)
            }
            _ => value("bias=").map(FaultMode::Bias),
        };
        let Some(mode) = mode else {
            return Err(FaultSpecError::UnknownMode {
                spec: s.to_owned(),
                mode: parts[1].to_owned(),
            });
        };
        let time = |t: &str| t.parse::<f64>().ok().filter(|t| t.is_finite() && *t >= 0.0);
        let (Some(start_s), Some(end_s)) = (time(start), time(end)) else {
            return Err(FaultSpecError::Times(s.to_owned()));
        };
        if end_s <= start_s {
            return Err(FaultSpecError::EmptyWindow(s.to_owned()));
        }
        Ok(FaultSpec {
            device: device.to_owned(),
            mode,
            start_s,
            end_s,
            reported,
        })
    }
}

/// The topic a device publishes on (what its own fault reports name).
fn topic_of(device: &str) -> &'static str {
    use railfuse_catalog::topics;
    match device {
        "gnss" => topics::GNSS_FIX,
        "imu" => topics::IMU,
        "radar" => topics::RADAR_SPEED,
        "odometer1" => topics::ODOMETER_1,
        "odometer2" => topics::ODOMETER_2,
        "loop" => topics::LOOP_POSITION,
        "map" => topics::TRACK_MAP,
        "eddy_current" => topics::EDDY_CURRENT,
        // The receiver's correction link: its fixes show the loss.
        "corrections" => topics::GNSS_FIX,
        _ => topics::BALISE,
    }
}

/// Which device a simulated message comes from.
fn device_of(e: &Emit) -> Option<&'static str> {
    Some(match e {
        Emit::Gnss(_) => "gnss",
        Emit::Imu(_) => "imu",
        Emit::Radar(_) => "radar",
        Emit::Odometer(0, _) => "odometer1",
        Emit::Odometer(_, _) => "odometer2",
        Emit::Loop(_) => "loop",
        Emit::Balise(_) => "balise",
        Emit::EddyCurrent(_) => "eddy_current",
        Emit::Truth(_) | Emit::Event(_) | Emit::TimeReference(..) => return None,
    })
}

struct Active {
    spec: FaultSpec,
    start_ns: u64,
    end_ns: u64,
    /// The device's last message before the window (what a stuck device keeps sending).
    frozen: Option<Emit>,
    started: bool,
    cleared: bool,
}

/// Applies the faults to the stream of simulated messages, in log-time order.
pub struct FaultInjector {
    faults: Vec<Active>,
}

impl FaultInjector {
    pub fn new(specs: &[FaultSpec], start_ns: u64) -> Self {
        let faults = specs
            .iter()
            .map(|s| Active {
                spec: s.clone(),
                start_ns: start_ns + seconds(s.start_s),
                end_ns: start_ns + seconds(s.end_s),
                frozen: None,
                started: false,
                cleared: false,
            })
            .collect();
        Self { faults }
    }

    /// Events due at `log_time_ns` (window edges), then the message as the faulty device
    /// sends it (None: dropped).
    pub fn apply(&mut self, log_time_ns: u64, emit: Emit, events: &mut Vec<Event>) -> Option<Emit> {
        for f in &mut self.faults {
            let text =
                |what: &str| format!("{}: {} {}", f.spec.device, describe(f.spec.mode), what);
            if !f.started && log_time_ns >= f.start_ns {
                f.started = true;
                events.push(Event {
                    stamp_ns: f.start_ns,
                    kind: EventKind::FaultInjected,
                    text: text("starts"),
                });
                if f.spec.reported {
                    events.push(Event {
                        stamp_ns: f.start_ns,
                        kind: EventKind::DeviceFault,
                        text: topic_of(&f.spec.device).to_owned(),
                    });
                }
            }
            if f.started && !f.cleared && log_time_ns >= f.end_ns {
                f.cleared = true;
                events.push(Event {
                    stamp_ns: f.end_ns,
                    kind: EventKind::FaultCleared,
                    text: text("ends"),
                });
                if f.spec.reported {
                    events.push(Event {
                        stamp_ns: f.end_ns,
                        kind: EventKind::DeviceRecovered,
                        text: topic_of(&f.spec.device).to_owned(),
                    });
                }
            }
        }
        let Some(device) = device_of(&emit) else {
            return Some(emit);
        };
        let mut emit = Some(emit);
        for f in self.faults.iter_mut().filter(|f| f.spec.device == device) {
            let Some(e) = emit.take() else { break };
            let inside = log_time_ns >= f.start_ns && log_time_ns < f.end_ns;
            emit = match (inside, f.spec.mode) {
                (false, _) => {
                    if log_time_ns < f.start_ns {
                        f.frozen = Some(e.clone());
                    }
                    Some(e)
                }
                (true, FaultMode::Dropout) => None,
                (true, FaultMode::Stuck) => Some(match &f.frozen {
                    Some(frozen) => restamped(frozen.clone(), stamp_of(&e)),
                    None => e,
                }),
                (true, FaultMode::Bias(b)) => Some(biased(e, b)),
                (true, FaultMode::Late(d)) => {
                    let late = stamp_of(&e) + seconds(d);
                    Some(restamped(e, late))
                }
                // The map is published once, offset where the fault says (simulate_line).
                (true, FaultMode::Offset(_)) => Some(e),
            };
        }
        emit
    }
}

fn describe(m: FaultMode) -> String {
    match m {
        FaultMode::Dropout => "dropout".into(),
        FaultMode::Stuck => "stuck".into(),
        FaultMode::Bias(b) => format!("bias {b}"),
        FaultMode::Offset(d) => format!("offset {d} m"),
        FaultMode::Late(d) => format!("stamps {d} s late"),
    }
}

fn stamp_of(e: &Emit) -> u64 {
    match e {
        Emit::Gnss(m) => m.stamp_ns,
        Emit::Imu(m) => m.stamp_ns,
        Emit::Radar(m) => m.stamp_ns,
        Emit::Odometer(_, m) => m.stamp_ns,
        Emit::Loop(m) => m.stamp_ns,
        Emit::Balise(m) => m.stamp_ns,
        Emit::EddyCurrent(m) => m.stamp_ns,
        Emit::Truth(m) => m.stamp_ns,
        Emit::Event(m) => m.stamp_ns,
        Emit::TimeReference(_, m) => m.stamp_ns,
    }
}

fn restamped(mut e: Emit, t: u64) -> Emit {
    match &mut e {
        Emit::Gnss(m) => m.stamp_ns = t,
        Emit::Imu(m) => m.stamp_ns = t,
        Emit::Radar(m) => m.stamp_ns = t,
        Emit::Odometer(_, m) => m.stamp_ns = t,
        Emit::Loop(m) => m.stamp_ns = t,
        Emit::Balise(m) => m.stamp_ns = t,
        Emit::EddyCurrent(m) => m.stamp_ns = t,
        Emit::Truth(m) => m.stamp_ns = t,
        Emit::Event(m) => m.stamp_ns = t,
        Emit::TimeReference(_, m) => m.stamp_ns = t,
    }
    e
}

fn biased(mut e: Emit, b: f64) -> Emit {
    const M_PER_DEG: f64 = 111_320.0;
    match &mut e {
        Emit::Gnss(m) => {
            if let (Some(lat), Some(lon)) = (m.latitude_deg, m.longitude_deg) {
                let course = m.course_rad.unwrap_or(0.0);
                m.latitude_deg = Some(lat + b * course.cos() / M_PER_DEG);
                m.longitude_deg =
                    Some(lon + b * course.sin() / (M_PER_DEG * lat.to_radians().cos()));
            }
        }
        Emit::Imu(m) => m.specific_force_mps2[0] += b,
        Emit::Radar(m) => m.speed_mps += b,
        Emit::Odometer(_, m) => m.speed_mps += b,
        Emit::Loop(m) => m.chainage_m += b,
        Emit::Balise(m) => m.chainage_m += b,
        // Volts on every sample of both sensors (a drifting amplifier).
        Emit::EddyCurrent(m) => {
            for v in m.sensor_a.iter_mut().chain(m.sensor_b.iter_mut()) {
                *v += b as f32;
            }
        }
        Emit::Truth(_) | Emit::Event(_) | Emit::TimeReference(..) => {}
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_catalog::messages::RadarSpeed;

    fn radar(t: u64, v: f64) -> Emit {
        Emit::Radar(RadarSpeed {
            stamp_ns: t,
            speed_mps: v,
            quality: 1.0,
            valid: true,
            speed_variance_m2ps2: None,
        })
    }

    #[test]
    fn specs_parse_and_bad_ones_say_why() {
        let f: FaultSpec = "gnss:bias=30:150:250".parse().unwrap();
        assert_eq!(f.mode, FaultMode::Bias(30.0));
        assert!("radar:melt:1:2"
            .parse::<FaultSpec>()
            .unwrap_err()
            .to_string()
            .contains("unknown mode"));
        assert!("warp:dropout:1:2"
            .parse::<FaultSpec>()
            .unwrap_err()
            .to_string()
            .contains("unknown device"));
        assert!("radar:dropout:5:2"
            .parse::<FaultSpec>()
            .unwrap_err()
            .to_string()
            .contains("ends before"));
        assert!(
            "radar:stuck:1:2:reported"
                .parse::<FaultSpec>()
                .unwrap()
                .reported
        );
        // The correction link can only be lost.
        let f: FaultSpec = "corrections:dropout:20:320".parse().unwrap();
        assert_eq!(f.mode, FaultMode::Dropout);
        for bad in ["corrections:stuck:1:2", "corrections:bias=1:1:2"] {
            let e = bad.parse::<FaultSpec>().unwrap_err().to_string();
            assert!(
                e.contains("unknown mode") && e.contains("corrections: dropout"),
                "{e}"
            );
        }
    }

    #[test]
    fn dropout_stuck_and_bias_change_only_their_window() {
        let sec = 1_000_000_000;
        for (mode, expect) in [
            (FaultMode::Dropout, vec![Some(1.0), None, None, Some(4.0)]),
            (
                FaultMode::Stuck,
                vec![Some(1.0), Some(1.0), Some(1.0), Some(4.0)],
            ),
            (
                FaultMode::Bias(0.5),
                vec![Some(1.0), Some(2.5), Some(3.5), Some(4.0)],
            ),
        ] {
            let mut inj = FaultInjector::new(
                &[FaultSpec {
                    device: "radar".into(),
                    mode,
                    start_s: 2.0,
                    end_s: 4.0,
                    reported: false,
                }],
                0,
            );
            let mut events = Vec::new();
            let got: Vec<Option<f64>> = (1..=4)
                .map(
                    |k| match inj.apply(k * sec, radar(k * sec, k as f64), &mut events) {
                        Some(Emit::Radar(m)) => {
                            assert_eq!(m.stamp_ns, k * sec);
                            Some(m.speed_mps)
                        }
                        _ => None,
                    },
                )
                .collect();
            assert_eq!(got, expect, "{mode:?}");
            assert_eq!(
                events.iter().map(|e| e.kind).collect::<Vec<_>>(),
                vec![EventKind::FaultInjected, EventKind::FaultCleared]
            );
        }
    }
}
