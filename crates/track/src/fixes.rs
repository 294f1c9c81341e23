//! A run's GNSS fixes as the fit takes them: read through the run reader (a file, a split
//! recording, a ROS 2 bag; railfuse's `GnssFix`, a ROS 2 `NavSatFix` or a Foxglove
//! `LocationFix`), only those of the stated quality, in a local plane shared by every run.

use std::collections::HashMap;

use railfuse_catalog::foreign::ForeignChannels;
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::{FixType, GnssFix, Imu, MessageKind, Odometer, RadarSpeed};
use railfuse_catalog::run::Run;
use railfuse_eval::FixQuality;

use crate::motion::{MotionRecorder, MotionStep};

/// A position fix in the local plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    pub stamp_ns: u64,
    pub east_m: f64,
    pub north_m: f64,
    /// Its horizontal 1σ, m (from the receiver's covariance, else its fix type).
    pub sigma_m: f64,
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
    fix_type: FixType,
    course: Option<Course>,
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
    // Per GNSS channel: its topic and the fixes read from it.
    let mut gnss: HashMap<u16, (String, Vec<Read>)> = HashMap::new();
    // The motion sensors' channels, by kind.
    let mut motion_channels: HashMap<u16, MessageKind> = HashMap::new();
    let mut motion = MotionRecorder::default();
    let mut buf = Vec::new();
    while let Some(record) = reader.next() {
        match record? {
            LogRecord::Channel(c) => {
                let c = match c.kind() {
                    None => foreign.channel(c.clone(), None).unwrap_or(c),
                    Some(_) => c,
                };
                let wanted = topic.is_none_or(|t| t == c.topic);
                match c.kind() {
                    Some(MessageKind::GnssFix) if wanted => {
                        gnss.entry(c.id).or_insert((c.topic.clone(), Vec::new()));
                    }
                    Some(
                        k @ (MessageKind::Imu | MessageKind::Odometer | MessageKind::RadarSpeed),
                    ) => {
                        motion_channels.insert(c.id, k);
                    }
                    _ => {}
                }
            }
            LogRecord::Message(m) => {
                if let Some(kind) = motion_channels.get(&m.channel.id) {
                    // A motion sample that does not decode is a gap in it.
                    match kind {
                        MessageKind::Imu => m.decode::<Imu>(&path).map(|x| motion.imu(&x)),
                        MessageKind::Odometer => {
                            m.decode::<Odometer>(&path).map(|x| motion.odometer(&x))
                        }
                        _ => m.decode::<RadarSpeed>(&path).map(|x| motion.radar(&x)),
                    }
                    .ok();
                    continue;
                }
                if !gnss.contains_key(&m.channel.id) {
                    continue;
                }
                let id = m.channel.id;
                // A foreign sample that does not read is a gap, as in eval.
                let Ok(Some(m)) = foreign.message(m, &mut buf) else {
                    continue;
                };
                let fix: GnssFix = m.decode(&path)?;
                if let Some(r) = to_plane(&fix, origin) {
                    gnss.get_mut(&id).expect("a GNSS channel").1.push(r);
                }
            }
            _ => {}
        }
    }
    let (topic, read) = choose(&name, topic, gnss)?;
    let mut run = keep_quality(name, topic, read, quality)?;
    run.motion = motion.finish();
    Ok(run)
}

/// The channel to fit: the one named, else the one GNSS channel that is not a Foxglove twin.
fn choose(
    run: &str,
    named: Option<&str>,
    gnss: HashMap<u16, (String, Vec<Read>)>,
) -> Result<(String, Vec<Read>), FixesError> {
    let mut channels: Vec<(String, Vec<Read>)> = gnss.into_values().collect();
    let twin = |t: &str| t.starts_with(railfuse_catalog::foxglove::TOPIC_PREFIX);
    if channels.iter().any(|(t, _)| !twin(t)) {
        channels.retain(|(t, _)| !twin(t));
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

/// A fix with a position, in the plane of `origin`.
fn to_plane(fix: &GnssFix, origin: &mut Option<GeodeticOrigin>) -> Option<Read> {
    let (Some(lat), Some(lon)) = (fix.latitude_deg, fix.longitude_deg) else {
        return None;
    };
    if !(fix.fix_type.has_position() && lat.is_finite() && lon.is_finite()) {
        return None;
    }
    let alt = fix.altitude_m.filter(|a| a.is_finite()).unwrap_or(0.0);
    let o = *origin.get_or_insert(GeodeticOrigin {
        latitude_deg: lat,
        longitude_deg: lon,
        altitude_m: alt,
    });
    let (east_m, north_m, _) = o.to_enu(lat, lon, alt);
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
        },
        fix_type: fix.fix_type,
        course,
    })
}

fn keep_quality(
    run: String,
    topic: String,
    read: Vec<Read>,
    quality: &FixQuality,
) -> Result<RunFixes, FixesError> {
    let any_fixed = read.iter().any(|r| r.fix_type == FixType::RtkFixed);
    let keep = |t: FixType| match quality {
        FixQuality::Auto if any_fixed => t == FixType::RtkFixed,
        FixQuality::Auto | FixQuality::All => true,
        FixQuality::Only(types) => types.contains(&t),
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
    })
}
