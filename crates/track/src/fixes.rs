//! A run's GNSS fixes as the fit takes them: read through the run reader (a file, a split
//! recording, a ROS 2 bag; railfuse's `GnssFix`, a ROS 2 `NavSatFix` or a Foxglove
//! `LocationFix`), only those of the stated quality, in a local plane shared by every run.

use std::collections::HashMap;

use railfuse_catalog::foreign::ForeignChannels;
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::{ChannelInfo, LogRecord};
use railfuse_catalog::messages::{
    FixType, FusedState, GnssFix, Imu, MessageKind, Odometer, RadarSpeed, Vehicle,
};
use railfuse_catalog::run::Run;
use railfuse_eval::FixQuality;

use crate::motion::{Lean, MotionRecorder, MotionStep, Tilt, TiltRecorder};

/// A position fix in the local plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    pub stamp_ns: u64,
    pub east_m: f64,
    pub north_m: f64,
    /// Its horizontal 1σ, m (from the receiver's covariance, else its fix type).
    pub sigma_m: f64,
    /// The top of rail's height under it, m up in the plane's frame: the antenna's height
    /// less its lever arm's z on the run's vehicle; `None` for a fix without an altitude.
    pub up_m: Option<f64>,
}

/// The receiver's course over ground, from its Doppler velocity: it holds where RTK is lost
/// (the velocity does not need the corrections) and a steady multipath pull does not bend it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Course {
    pub stamp_ns: u64,
    /// Clockwise from north, rad.
    pub course_rad: f64,
    pub speed_mps: f64,
}

/// Below this speed a course says little, m/s.
pub const MIN_COURSE_SPEED_MPS: f64 = 5.0;

/// One run's fixes of the stated quality, in time order, and its own motion.
#[derive(Debug, Clone, Default)]
pub struct RunFixes {
    pub name: String,
    pub fixes: Vec<Fix>,
    /// Its IMU's turn and its odometer's distance, step by step (empty without both).
    pub motion: Vec<MotionStep>,
    /// The receiver's course, from fixes of every quality, where it moved fast enough.
    pub courses: Vec<Course>,
    /// Its points are a 2-D pipeline's fused states, not GNSS fixes.
    pub fused: bool,
    /// Its IMU's roll, with the vehicle that places it and the antenna, until the lean's
    /// `take_out` takes the antenna's lean and the cant from it.
    pub tilt: Option<Tilt>,
    /// What taking the antenna's lean out of its fixes did.
    pub lean: Option<Lean>,
    /// The antenna's height above the rail where the vehicle puts it up but the run has no
    /// IMU to take its lean out with, m: its fixes lean into each canted curve by
    /// `z sin φ` (0.44 m for 4.1 m and 160 mm of cant), left in.
    pub lean_kept_m: Option<f64>,
    /// Each fix's cant from the run's IMU, rad, the left rail up positive looking the way the
    /// run travels (empty without an IMU and a vehicle).
    pub cant_rad: Vec<Option<f64>>,
}

/// Why a run's fixes could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FixesError {
    #[error(transparent)]
    Log(#[from] railfuse_catalog::Error),
    #[error("{run}: no GNSS fix channel (railfuse GnssFix, ROS 2 NavSatFix or Foxglove LocationFix) to fit a line to")]
    NoGnss { run: String },
    #[error("{run}: several GNSS channels ({topics}): name one with --topic")]
    SeveralGnss { run: String, topics: String },
    #[error("{run}: no GNSS channel {topic}")]
    NoTopic { run: String, topic: String },
    #[error("{run}: {topic} holds no fused state with a position (an along-track pipeline's states are chainage on a map; a 2-D pipeline's, such as gnss_ins, have one)")]
    NoFusedPosition { run: String, topic: String },
    #[error("{run}: none of its {fixes} fixes on {topic} is of the stated quality ({quality})")]
    NoneOfQuality {
        run: String,
        topic: String,
        fixes: usize,
        quality: String,
    },
}

/// A fix as read, before the quality is decided.
struct Read {
    fix: Fix,
    /// `None`: a fused state, which has no fix type.
    fix_type: Option<FixType>,
    course: Option<Course>,
}

/// The channels a run's line may come from, each with its topic and what was read from it:
/// GNSS fixes, and fused states of 2-D pipelines (GNSS/INS), whose positions hold through the
/// fixes' gaps.
#[derive(Default)]
struct Sources {
    gnss: HashMap<u16, (String, Vec<Read>)>,
    fused: HashMap<u16, (String, Vec<Read>)>,
    /// The motion sensors' channels: kind and topic.
    motion: HashMap<u16, (MessageKind, String)>,
    /// The installation drawing's channel (`/vehicle`).
    vehicle: Option<u16>,
}

impl Sources {
    /// Takes note of a channel: a GNSS or fused one if `wanted`, a motion sensor's, the
    /// vehicle's.
    fn channel(&mut self, c: &ChannelInfo, wanted: bool) {
        let entry = (c.topic.clone(), Vec::new());
        match c.kind() {
            Some(MessageKind::GnssFix) if wanted => {
                self.gnss.entry(c.id).or_insert(entry);
            }
            Some(MessageKind::FusedState) if wanted => {
                self.fused.entry(c.id).or_insert(entry);
            }
            Some(MessageKind::Vehicle) => self.vehicle = Some(c.id),
            Some(k @ (MessageKind::Imu | MessageKind::Odometer | MessageKind::RadarSpeed)) => {
                self.motion.insert(c.id, (k, c.topic.clone()));
            }
            _ => {}
        }
    }
}

/// The σ a fix type stands for where the receiver reports no covariance, m.
fn sigma_of(fix_type: FixType) -> f64 {
    match fix_type {
        FixType::RtkFixed => 0.02,
        FixType::RtkFloat => 0.3,
        FixType::Dgps => 0.7,
        _ => 2.0,
    }
}

/// The fixes of `run` on `topic` (else its one GNSS channel; Foxglove twins of another
/// channel only where there is no other) of `quality`, in the plane of `origin` (set from
/// the first fix read where it is still `None`).
pub fn read_fixes(
    run: &Run,
    topic: Option<&str>,
    quality: &FixQuality,
    origin: &mut Option<GeodeticOrigin>,
) -> Result<RunFixes, FixesError> {
    let (name, path) = (run.display(), run.name().to_owned());
    let mut reader = run.reader()?;
    let mut foreign = ForeignChannels::default();
    let mut sources = Sources::default();
    let mut motion = MotionRecorder::default();
    let mut vehicle = None::<Vehicle>;
    let mut tilt = TiltRecorder::default();
    let mut buf = Vec::new();
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                let c = match c.kind() {
                    None => foreign.channel(c.clone(), None).unwrap_or(c),
                    Some(_) => c,
                };
                sources.channel(&c, topic.is_none_or(|t| t == c.topic));
            }
            LogRecord::Message(m) => {
                if let Some((kind, topic)) = sources.motion.get(&m.channel.id) {
                    // A motion sample that does not decode is a gap in it.
                    match kind {
                        MessageKind::Imu => m.decode::<Imu>(&path).map(|x| {
                            motion.imu(&x);
                            tilt.imu(topic, &x);
                        }),
                        MessageKind::Odometer => {
                            m.decode::<Odometer>(&path).map(|x| motion.odometer(&x))
                        }
                        _ => m.decode::<RadarSpeed>(&path).map(|x| motion.radar(&x)),
                    }
                    .ok();
                    continue;
                }
                let id = m.channel.id;
                if Some(id) == sources.vehicle {
                    // The installation drawing: where the antenna is above the rail.
                    vehicle = m.decode(&path).ok();
                    continue;
                }
                if let Some((_, read)) = sources.fused.get_mut(&id) {
                    let state: FusedState = m.decode(&path)?;
                    read.extend(fused_to_plane(&state, origin));
                    continue;
                }
                if !sources.gnss.contains_key(&id) {
                    continue;
                }
                // A foreign sample that does not read is a gap, as in eval.
                let Ok(Some(m)) = foreign.message(m, &mut buf) else {
                    continue;
                };
                let fix: GnssFix = m.decode(&path)?;
                if let Some(r) = to_plane(&fix, origin) {
                    sources.gnss.get_mut(&id).expect("a GNSS channel").1.push(r);
                }
            }
            _ => {}
        }
    }
    let (topic, read) = choose(&name, topic, sources)?;
    let mut run = keep_quality(name, topic.clone(), read, quality)?;
    run.motion = motion.finish();
    on_the_train(&mut run, vehicle, topic, tilt);
    Ok(run)
}

/// What the run's `vehicle` says of its fixes from the antenna `topic`: their heights are
/// the antenna's less its height above the rail, and with the IMU's `tilt` its lean can be
/// taken out.
fn on_the_train(run: &mut RunFixes, vehicle: Option<Vehicle>, topic: String, tilt: TiltRecorder) {
    let antenna_z = vehicle
        .as_ref()
        .and_then(|v| v.mount(&topic))
        .map_or(0.0, |m| m.lever_arm_m[2]);
    for f in &mut run.fixes {
        f.up_m = f.up_m.map(|u| u - antenna_z);
    }
    let (imu, steps) = tilt.finish();
    run.lean_kept_m = (imu.is_none() && antenna_z > 0.0 && !run.fused).then_some(antenna_z);
    run.tilt = vehicle.zip(imu).map(|(vehicle, imu)| Tilt {
        steps,
        vehicle,
        imu,
        antenna: topic,
    });
}

/// The channel to fit: the one named (GNSS or fused), else the one GNSS channel that is not
/// a Foxglove twin, else (a log without GNSS) the one fused channel with positions.
fn choose(
    run: &str,
    named: Option<&str>,
    sources: Sources,
) -> Result<(String, Vec<Read>), FixesError> {
    let twin = |t: &str| t.starts_with(railfuse_catalog::foxglove::TOPIC_PREFIX);
    let mut channels: Vec<(String, Vec<Read>)> = sources.gnss.into_values().collect();
    if channels.iter().any(|(t, _)| !twin(t)) {
        channels.retain(|(t, _)| !twin(t));
    }
    let fused: Vec<(String, Vec<Read>)> = sources.fused.into_values().collect();
    if let (Some(t), Some((_, read))) = (named, fused.first()) {
        if read.is_empty() {
            return Err(FixesError::NoFusedPosition {
                run: run.to_owned(),
                topic: t.to_owned(),
            });
        }
    }
    if channels.is_empty() {
        channels = fused.into_iter().filter(|(_, r)| !r.is_empty()).collect();
    }
    match (channels.len(), named) {
        (1, _) => Ok(channels.pop().expect("one")),
        (0, Some(t)) => Err(FixesError::NoTopic {
            run: run.to_owned(),
            topic: t.to_owned(),
        }),
        (0, None) => Err(FixesError::NoGnss {
            run: run.to_owned(),
        }),
        _ => {
            let mut topics: Vec<String> = channels.into_iter().map(|(t, _)| t).collect();
            topics.sort();
            Err(FixesError::SeveralGnss {
                run: run.to_owned(),
                topics: topics.join(", "),
            })
        }
    }
}

/// A fused state's position in the plane of `origin`, its σ from its covariance; `None`
/// for an along-track pipeline's state (chainage on a map) or a position that is not finite.
fn fused_to_plane(state: &FusedState, origin: &mut Option<GeodeticOrigin>) -> Option<Read> {
    let p = state.plane.as_ref()?;
    let (lat, lon) = (p.latitude_deg, p.longitude_deg);
    if !(lat.is_finite() && lon.is_finite()) {
        return None;
    }
    let c = p.covariance_en_m2;
    let sigma = ((c[0] + c[3]) / 2.0).sqrt();
    let sigma_m = if sigma.is_finite() && sigma > 0.0 {
        sigma
    } else {
        sigma_of(FixType::RtkFloat)
    };
    let (east_m, north_m, _) = plane_of(origin, lat, lon, 0.0);
    Some(Read {
        fix: Fix {
            stamp_ns: state.stamp_ns,
            east_m,
            north_m,
            sigma_m,
            up_m: None,
        },
        fix_type: None,
        course: None,
    })
}

/// (east, north, up) of a place in the plane of `origin`, which the first place read sets.
fn plane_of(origin: &mut Option<GeodeticOrigin>, lat: f64, lon: f64, alt: f64) -> (f64, f64, f64) {
    let o = *origin.get_or_insert(GeodeticOrigin {
        latitude_deg: lat,
        longitude_deg: lon,
        altitude_m: alt,
    });
    o.to_enu(lat, lon, alt)
}

/// A fix with a position, in the plane of `origin`.
fn to_plane(fix: &GnssFix, origin: &mut Option<GeodeticOrigin>) -> Option<Read> {
    let (Some(lat), Some(lon)) = (fix.latitude_deg, fix.longitude_deg) else {
        return None;
    };
    if !(fix.fix_type.has_position() && lat.is_finite() && lon.is_finite()) {
        return None;
    }
    let altitude = fix.altitude_m.filter(|a| a.is_finite());
    let alt = altitude.unwrap_or(0.0);
    let (east_m, north_m, up_m) = plane_of(origin, lat, lon, alt);
    let sigma_m = fix
        .position_covariance_enu_m2
        .map(|c| ((c[0] + c[4]) / 2.0).sqrt())
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or_else(|| sigma_of(fix.fix_type));
    let course = match (fix.course_rad, fix.speed_mps) {
        (Some(c), Some(v)) if c.is_finite() && v.is_finite() && v >= MIN_COURSE_SPEED_MPS => {
            Some(Course {
                stamp_ns: fix.stamp_ns,
                course_rad: c,
                speed_mps: v,
            })
        }
        _ => None,
    };
    Some(Read {
        fix: Fix {
            stamp_ns: fix.stamp_ns,
            east_m,
            north_m,
            sigma_m,
            up_m: altitude.map(|_| up_m),
        },
        fix_type: Some(fix.fix_type),
        course,
    })
}

fn keep_quality(
    run: String,
    topic: String,
    read: Vec<Read>,
    quality: &FixQuality,
) -> Result<RunFixes, FixesError> {
    let any_fixed = read.iter().any(|r| r.fix_type == Some(FixType::RtkFixed));
    // A fused state has no fix type: a fused channel's states are all kept.
    let fused = read.iter().all(|r| r.fix_type.is_none());
    let keep = |t: Option<FixType>| match (t, quality) {
        (None, _) => true,
        (Some(t), FixQuality::Auto) if any_fixed => t == FixType::RtkFixed,
        (Some(_), FixQuality::Auto | FixQuality::All) => true,
        (Some(t), FixQuality::Only(types)) => types.contains(&t),
    };
    let total = read.len();
    let courses = read.iter().filter_map(|r| r.course).collect();
    let fixes: Vec<Fix> = read
        .into_iter()
        .filter(|r| keep(r.fix_type))
        .map(|r| r.fix)
        .collect();
    if fixes.is_empty() {
        return Err(FixesError::NoneOfQuality {
            run,
            topic,
            fixes: total,
            quality: quality.label(),
        });
    }
    Ok(RunFixes {
        name: run,
        fixes,
        motion: Vec::new(),
        courses,
        fused,
        tilt: None,
        lean: None,
        lean_kept_m: None,
        cant_rad: Vec::new(),
    })
}
