//! ROS 2 messages in CDR (MCAP message encoding `cdr`, schema encoding `ros2msg`), read as
//! catalogue messages. A payload is a 4-byte encapsulation header (little- or big-endian CDR)
//! and the message's fields in CDR, decoded by `cdr-encoding` into the structs below, which
//! follow the ROS 2 message definitions field for field.
//!
//! - `sensor_msgs/msg/NavSatFix` → GNSS fix. Status −1 (NO_FIX) is skipped and counted; 0 is
//!   a single fix, 1 (SBAS) differential, 2 (GBAS) RTK fixed, as ROS GNSS drivers report RTK.
//!   The position covariance (ENU, m², as ROS defines it) is used unless its type is UNKNOWN.
//!   The altitude is ellipsoidal (REP 145 / the message's definition).
//! - `sensor_msgs/msg/Imu` → IMU: `linear_acceleration` is specific force (gravity included,
//!   REP 145), `angular_velocity` the angular rate; the frame id is the sensor id.
//! - `geometry_msgs/msg/TwistWithCovarianceStamped`, `TwistStamped` and
//!   `nav_msgs/msg/Odometry` → the speed along body x (`twist.linear.x`) of a radar or an
//!   odometer, as the sensor's role says; its variance from the covariance's first element
//!   where that is positive. With role `gnss` a twist is a receiver's velocity in east/north
//!   (x east, y north: the ublox driver's `fix_velocity`, nmea_navsat_driver's `vel`): a GNSS
//!   fix with speed over ground and course and no position, since ROS sends a receiver's
//!   position (NavSatFix) and velocity on two topics.
//!
//! `header.stamp` is the measurement time; a zero stamp takes the log time (the caller says
//! so once per topic).
//!
//! The other way, a pipeline's fused state is written for ROS tools as a NavSatFix (its
//! position on the globe with covariance) and an Odometry (position in the map frame, speed
//! along body x), with their definitions as MCAP `ros2msg` schemas.

use byteorder::{BigEndian, LittleEndian};
use serde::{Deserialize, Serialize};

use super::{Decode, ForeignError, FrameTransform, PositionFix, Role, Translated};
use crate::messages::{
    AnyMessage, FixType, FusedState, GnssFix, Imu, MessageKind, Odometer, RadarSpeed, TrackMap,
};

/// The MCAP message encoding of ROS 2 channels.
pub const ENCODING: &str = "cdr";

pub const NAV_SAT_FIX: &str = "sensor_msgs/msg/NavSatFix";
pub const IMU: &str = "sensor_msgs/msg/Imu";
pub const TWIST_WITH_COVARIANCE_STAMPED: &str = "geometry_msgs/msg/TwistWithCovarianceStamped";
pub const TWIST_STAMPED: &str = "geometry_msgs/msg/TwistStamped";
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";

/// Every schema read here.
pub const SCHEMAS: &[&str] = &[
    NAV_SAT_FIX,
    IMU,
    TWIST_WITH_COVARIANCE_STAMPED,
    TWIST_STAMPED,
    ODOMETRY,
];

#[derive(Debug, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct NavSatStatus {
    pub status: i8,
    pub service: u16,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct NavSatFix<H = Header> {
    pub header: H,
    pub status: NavSatStatus,
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    pub position_covariance: [f64; 9],
    pub position_covariance_type: u8,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct ImuMsg<H = Header> {
    pub header: H,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

/// A 6×6 covariance, row-major (serde reads arrays of up to 32 elements: six rows of six).
type Covariance6 = [[f64; 6]; 6];

#[derive(Debug, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Covariance6,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct TwistWithCovarianceStamped<H = Header> {
    pub header: H,
    pub twist: TwistWithCovariance,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct TwistStamped<H = Header> {
    pub header: H,
    pub twist: Twist,
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`: where `child_frame_id` sits in `header.frame_id`.
#[derive(Debug, Serialize, Deserialize)]
pub struct TransformStamped<H = Header> {
    pub header: H,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`: the transforms on `/tf` and `/tf_static`.
#[derive(Debug, Serialize, Deserialize)]
pub struct TfMessage<H = Header> {
    pub transforms: Vec<TransformStamped<H>>,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance6,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Odometry<H = Header> {
    pub header: H,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// The definitions of `std_msgs/Header` and `builtin_interfaces/Time`, which every stamped
/// message includes.
macro_rules! header_definitions {
    () => {
        "\
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"
    };
}

/// `sensor_msgs/msg/NavSatFix` with what it includes, as ROS 2 writes a definition into an
/// MCAP schema (`ros2msg`): the message, then each type it uses after a separator line.
pub const NAV_SAT_FIX_DEFINITION: &str = concat!(
    "\
std_msgs/Header header
NavSatStatus status
float64 latitude
float64 longitude
float64 altitude
float64[9] position_covariance
uint8 COVARIANCE_TYPE_UNKNOWN=0
uint8 COVARIANCE_TYPE_APPROXIMATED=1
uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2
uint8 COVARIANCE_TYPE_KNOWN=3
uint8 position_covariance_type
",
    header_definitions!(),
    "\
================================================================================
MSG: sensor_msgs/NavSatStatus
int8 STATUS_NO_FIX=-1
int8 STATUS_FIX=0
int8 STATUS_SBAS_FIX=1
int8 STATUS_GBAS_FIX=2
int8 status
uint16 SERVICE_GPS=1
uint16 SERVICE_GLONASS=2
uint16 SERVICE_COMPASS=4
uint16 SERVICE_GALILEO=8
uint16 service
"
);

/// `nav_msgs/msg/Odometry` with what it includes (see [`NAV_SAT_FIX_DEFINITION`]).
pub const ODOMETRY_DEFINITION: &str = concat!(
    "\
std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
",
    header_definitions!(),
    "\
================================================================================
MSG: geometry_msgs/PoseWithCovariance
Pose pose
float64[36] covariance
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
================================================================================
MSG: geometry_msgs/TwistWithCovariance
Twist twist
float64[36] covariance
================================================================================
MSG: geometry_msgs/Twist
Vector3 linear
Vector3 angular
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"
);

/// The definition railfuse carries for a ROS 2 type, where it has one.
pub fn definition(ros_type: &str) -> Option<&'static str> {
    match ros_type {
        NAV_SAT_FIX => Some(NAV_SAT_FIX_DEFINITION),
        ODOMETRY => Some(ODOMETRY_DEFINITION),
        _ => None,
    }
}

/// A message as a ROS 2 CDR payload: the little-endian encapsulation header, then its fields.
pub fn to_cdr<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut out = vec![0x00, 0x01, 0x00, 0x00];
    out.extend(cdr_encoding::to_vec::<T, LittleEndian>(msg).expect("a ROS message serialises"));
    out
}

fn header_at(stamp_ns: u64, frame_id: &str) -> Header {
    Header {
        stamp: Time {
            sec: (stamp_ns / 1_000_000_000) as i32,
            nanosec: (stamp_ns % 1_000_000_000) as u32,
        },
        frame_id: frame_id.to_owned(),
    }
}

/// A pipeline's fused state as `sensor_msgs/msg/NavSatFix` (CDR): its position on the globe
/// and that position's covariance; `None` where it has no place on the globe (no map).
pub fn fused_nav_sat_fix(
    pipeline: &str,
    f: &FusedState,
    map: Option<&TrackMap>,
) -> Option<Vec<u8>> {
    let g = f.geodetic(map)?;
    Some(to_cdr(&NavSatFix {
        header: header_at(f.stamp_ns, pipeline),
        status: NavSatStatus {
            status: 0,
            service: 0,
        },
        latitude: g.latitude_deg,
        longitude: g.longitude_deg,
        altitude: g.altitude_m,
        position_covariance: g.covariance_enu_m2,
        position_covariance_type: g.covariance_type,
    }))
}

/// A pipeline's fused state as `nav_msgs/msg/Odometry` (CDR): the position in the map's
/// east/north/up frame (`map`), the heading as the yaw, and the speed along the body's x axis
/// (`base_link`) with its variance.
pub fn fused_odometry(f: &FusedState, map: Option<&TrackMap>) -> Vec<u8> {
    let zero = Vector3 {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };
    let mut pose_covariance = [[0.0; 6]; 6];
    let mut twist_covariance = [[0.0; 6]; 6];
    twist_covariance[0][0] = f.covariance[4];
    let (position, orientation) = match f.local(map) {
        Some((east, north, heading, [ee, en, _, nn])) => {
            (pose_covariance[0][0], pose_covariance[0][1]) = (ee, en);
            (pose_covariance[1][0], pose_covariance[1][1]) = (en, nn);
            // ROS yaw is counter-clockwise from east; the heading is clockwise from north.
            let yaw = std::f64::consts::FRAC_PI_2 - heading.unwrap_or(std::f64::consts::FRAC_PI_2);
            let (s, c) = (yaw / 2.0).sin_cos();
            (
                Vector3 {
                    x: east,
                    y: north,
                    z: 0.0,
                },
                Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: s,
                    w: c,
                },
            )
        }
        None => (
            Vector3 {
                x: f.chainage_m,
                y: 0.0,
                z: 0.0,
            },
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        ),
    };
    to_cdr(&Odometry {
        header: header_at(f.stamp_ns, "map"),
        child_frame_id: "base_link".to_owned(),
        pose: PoseWithCovariance {
            pose: Pose {
                position,
                orientation,
            },
            covariance: pose_covariance,
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3 {
                    x: f.speed_mps,
                    y: 0.0,
                    z: 0.0,
                },
                angular: zero,
            },
            covariance: twist_covariance,
        },
    })
}

/// Decodes a CDR payload (encapsulation header first) as `T`.
pub fn from_cdr<T: for<'de> Deserialize<'de>>(
    data: &[u8],
    schema: &str,
) -> Result<T, ForeignError> {
    let fail = |cause: String| ForeignError::Cdr {
        schema: schema.to_owned(),
        cause,
    };
    if data.len() < 4 {
        return Err(fail(format!(
            "{} bytes, shorter than the encapsulation header",
            data.len()
        )));
    }
    // Alignment counts from the end of the encapsulation header.
    let body = &data[4..];
    let decoded = match data[1] {
        0x01 | 0x03 => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        0x00 | 0x02 => cdr_encoding::from_bytes::<T, BigEndian>(body),
        other => {
            return Err(fail(format!(
                "encapsulation kind {other:#04x} is not plain CDR"
            )))
        }
    };
    decoded.map(|(v, _)| v).map_err(|e| fail(e.to_string()))
}

/// A ROS wire format: how a payload decodes, and the header its stamped messages carry
/// (ROS 2's in CDR; ROS 1's, with a sequence number and unsigned seconds, in its own
/// serialisation: see [`super::ros1`]).
pub(super) trait Wire {
    type Header: RosHeader + for<'de> Deserialize<'de>;
    fn decode<T: for<'de> Deserialize<'de>>(data: &[u8], schema: &str) -> Result<T, ForeignError>;
}

/// A stamped message's header: its time and frame.
pub(super) trait RosHeader {
    /// `header.stamp` as seconds and nanoseconds.
    fn stamp(&self) -> (i64, u32);
    fn into_frame_id(self) -> String;
}

impl RosHeader for Header {
    fn stamp(&self) -> (i64, u32) {
        (i64::from(self.stamp.sec), self.stamp.nanosec)
    }
    fn into_frame_id(self) -> String {
        self.frame_id
    }
}

/// ROS 2's CDR.
pub(super) struct Cdr;

impl Wire for Cdr {
    type Header = Header;
    fn decode<T: for<'de> Deserialize<'de>>(data: &[u8], schema: &str) -> Result<T, ForeignError> {
        from_cdr(data, schema)
    }
}

/// The message's time, or the log time where its stamp is zero.
fn stamp(h: &impl RosHeader, log_time_ns: u64) -> Result<(u64, bool), ForeignError> {
    let (sec, nanosec) = h.stamp();
    if sec == 0 && nanosec == 0 {
        return Ok((log_time_ns, true));
    }
    if sec < 0 || nanosec >= 1_000_000_000 {
        return Err(ForeignError::Invalid(format!(
            "header.stamp {sec}.{nanosec:09} is not a time"
        )));
    }
    Ok((sec as u64 * 1_000_000_000 + u64::from(nanosec), false))
}

fn nav_sat_fix<W: Wire>(
    data: &[u8],
    _: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: NavSatFix<W::Header> = W::decode(data, NAV_SAT_FIX)?;
    let fix_type = match m.status.status {
        -1 => return Ok(Translated::Skipped("NavSatFix with status NO_FIX")),
        0 => FixType::Single,
        1 => FixType::Dgps,
        2 => FixType::RtkFixed,
        s => {
            return Err(ForeignError::Invalid(format!(
                "NavSatFix status {s} (−1 to 2)"
            )))
        }
    };
    let (stamp_ns, took_log_time) = stamp(&m.header, log_time_ns)?;
    let fix = PositionFix {
        stamp_ns,
        fix_type,
        latitude_deg: m.latitude,
        longitude_deg: m.longitude,
        altitude_m: m.altitude,
        covariance_enu_m2: m.position_covariance,
        covariance_type: m.position_covariance_type,
        course_rad: None,
    };
    Ok(Translated::Message {
        message: AnyMessage::GnssFix(fix.into_gnss_fix(NAV_SAT_FIX)?),
        took_log_time,
    })
}

fn imu<W: Wire>(
    data: &[u8],
    _: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: ImuMsg<W::Header> = W::decode(data, IMU)?;
    let (a, w) = (&m.linear_acceleration, &m.angular_velocity);
    let (stamp_ns, took_log_time) = stamp(&m.header, log_time_ns)?;
    Ok(Translated::Message {
        message: AnyMessage::Imu(Imu {
            stamp_ns,
            sensor_id: m.header.into_frame_id(),
            specific_force_mps2: [a.x, a.y, a.z],
            angular_rate_radps: [w.x, w.y, w.z],
            accel_lsb_mps2: None,
            gyro_lsb_radps: None,
        }),
        took_log_time,
    })
}

/// A twist's linear velocity (body x for a radar or an odometer, east/north for a GNSS
/// receiver), with the variance of x where given, as the sensor `role` says.
fn speed(
    header: impl RosHeader,
    linear: &Vector3,
    variance: Option<f64>,
    role: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let (stamp_ns, took_log_time) = stamp(&header, log_time_ns)?;
    let variance = variance.filter(|v| v.is_finite() && *v > 0.0);
    let speed_mps = linear.x;
    let message = match role {
        // An odometer's sample is its speed: without one there is nothing to read.
        Some(Role::Odometer) if !speed_mps.is_finite() => {
            return Ok(Translated::Skipped("odometer twist without a finite speed"))
        }
        Some(Role::Gnss) => {
            let (east, north) = (linear.x, linear.y);
            let moving = east.hypot(north) > 0.5;
            AnyMessage::GnssFix(GnssFix {
                stamp_ns,
                fix_type: FixType::Single,
                satellites: 0,
                hdop: None,
                latitude_deg: None,
                longitude_deg: None,
                altitude_m: None,
                altitude_msl_m: None,
                position_covariance_enu_m2: None,
                speed_mps: Some(east.hypot(north)).filter(|v| v.is_finite()),
                // Clockwise from north; undefined when (nearly) standing.
                course_rad: moving.then(|| east.atan2(north).rem_euclid(std::f64::consts::TAU)),
            })
        }
        Some(Role::Odometer) => AnyMessage::Odometer(Odometer {
            stamp_ns,
            sensor_id: header.into_frame_id(),
            pulse_count: None,
            pulses_per_revolution: None,
            wheel_diameter_m: None,
            distance_increment_m: None,
            speed_mps,
        }),
        // A radar measures the speed's magnitude; a NaN one (how a driver says "no echo") is
        // an invalid sample, counted by the sensor model, not a message that fails to read.
        _ => AnyMessage::RadarSpeed(RadarSpeed {
            stamp_ns,
            speed_mps: if speed_mps.is_finite() {
                speed_mps.abs()
            } else {
                0.0
            },
            quality: 1.0,
            valid: speed_mps.is_finite(),
            speed_variance_m2ps2: variance,
        }),
    };
    Ok(Translated::Message {
        message,
        took_log_time,
    })
}

fn twist_with_covariance<W: Wire>(
    data: &[u8],
    role: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: TwistWithCovarianceStamped<W::Header> = W::decode(data, TWIST_WITH_COVARIANCE_STAMPED)?;
    let var = m.twist.covariance[0][0];
    speed(
        m.header,
        &m.twist.twist.linear,
        Some(var),
        role,
        log_time_ns,
    )
}

fn twist<W: Wire>(
    data: &[u8],
    role: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: TwistStamped<W::Header> = W::decode(data, TWIST_STAMPED)?;
    speed(m.header, &m.twist.linear, None, role, log_time_ns)
}

fn odometry<W: Wire>(
    data: &[u8],
    role: Option<Role>,
    log_time_ns: u64,
) -> Result<Translated, ForeignError> {
    let m: Odometry<W::Header> = W::decode(data, ODOMETRY)?;
    let var = m.twist.covariance[0][0];
    let role = role.or(Some(Role::Odometer));
    speed(
        m.header,
        &m.twist.twist.linear,
        Some(var),
        role,
        log_time_ns,
    )
}

/// The transforms of a `tf2_msgs/TFMessage` in the wire format `W`: each sensor frame
/// (child) where it sits in its parent frame.
pub(super) fn transforms<W: Wire>(data: &[u8]) -> Result<Vec<FrameTransform>, ForeignError> {
    let m: TfMessage<W::Header> = W::decode(data, "tf2_msgs/TFMessage")?;
    Ok(m.transforms
        .into_iter()
        .map(|t| {
            let (v, q) = (&t.transform.translation, &t.transform.rotation);
            FrameTransform {
                parent: t.header.into_frame_id(),
                child: t.child_frame_id,
                translation_m: [v.x, v.y, v.z],
                rotation_xyzw: [q.x, q.y, q.z, q.w],
            }
        })
        .collect())
}

/// The transforms of a ROS 2 `tf2_msgs/msg/TFMessage` (CDR).
pub fn transforms_cdr(data: &[u8]) -> Result<Vec<FrameTransform>, ForeignError> {
    transforms::<Cdr>(data)
}

/// The catalogue kind and reader of `schema` (ROS 2's name: `sensor_msgs/msg/NavSatFix`) in
/// the wire format `W` for a sensor of `role`; `Ok(None)` for a schema not read here.
pub(super) fn reader<W: Wire>(
    schema: &str,
    role: Option<Role>,
) -> Result<Option<(MessageKind, Decode)>, String> {
    let speed_kind = |role: Option<Role>, default: Option<Role>| match role.or(default) {
        Some(Role::Radar) => Ok(MessageKind::RadarSpeed),
        Some(Role::Odometer) => Ok(MessageKind::Odometer),
        Some(Role::Gnss) => Ok(MessageKind::GnssFix),
        Some(other) => Err(format!(
            "{schema} is a velocity: it can be a radar's, an odometer's or a GNSS receiver's, \
             not {other:?}"
        )),
        None => Err(format!(
            "{schema} can be a radar's, an odometer's or a GNSS receiver's velocity: say which \
             with role = \"radar\", \"odometer\" or \"gnss\""
        )),
    };
    let wrong_role = |kind: &str| Err(format!("{schema} is {kind}: its role cannot be {role:?}"));
    Ok(Some(match schema {
        NAV_SAT_FIX => match role {
            None | Some(Role::Gnss) => (MessageKind::GnssFix, nav_sat_fix::<W> as Decode),
            _ => return wrong_role("a GNSS fix"),
        },
        IMU => match role {
            None | Some(Role::Imu) => (MessageKind::Imu, imu::<W> as Decode),
            _ => return wrong_role("an IMU sample"),
        },
        TWIST_WITH_COVARIANCE_STAMPED => (
            speed_kind(role, None)?,
            twist_with_covariance::<W> as Decode,
        ),
        TWIST_STAMPED => (speed_kind(role, None)?, twist::<W> as Decode),
        ODOMETRY => (
            speed_kind(role, Some(Role::Odometer))?,
            odometry::<W> as Decode,
        ),
        _ => return Ok(None),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::foreign::Translator;

    #[test]
    fn a_header_stamp_moves_with_the_clock_and_other_messages_do_not() {
        let msg = NavSatFix {
            header: header_at(1_780_300_800_250_000_000, "gps"),
            status: NavSatStatus {
                status: 0,
                service: 0,
            },
            latitude: 44.6,
            longitude: 10.9,
            altitude: 40.0,
            position_covariance: [0.0; 9],
            position_covariance_type: 0,
        };
        let data = to_cdr(&msg);
        let mut out = Vec::new();
        let back = |t: u64| t - 1_200_000_000;
        assert!(restamp_header(
            NAV_SAT_FIX_DEFINITION.as_bytes(),
            &data,
            back,
            &mut out
        ));
        let moved: NavSatFix = from_cdr(&out, "NavSatFix").unwrap();
        assert_eq!(
            (moved.header.stamp.sec, moved.header.stamp.nanosec),
            (1_780_300_799, 50_000_000)
        );
        assert_eq!(
            (moved.latitude, moved.header.frame_id.as_str()),
            (44.6, "gps")
        );
        // A definition without a header first, and a zero stamp, are left alone.
        assert!(!restamp_header(b"float64 x\n", &data, back, &mut out));
        let zero = to_cdr(&NavSatFix {
            header: header_at(0, "gps"),
            ..msg
        });
        assert!(!restamp_header(
            NAV_SAT_FIX_DEFINITION.as_bytes(),
            &zero,
            back,
            &mut out
        ));
    }

    /// A CDR little-endian payload of a NavSatFix, written field by field as ROS 2 writes it.
    fn nav_sat_fix_payload(status: i8, lat: f64) -> Vec<u8> {
        let mut b = vec![0x00, 0x01, 0x00, 0x00];
        let mut body = Vec::new();
        body.extend_from_slice(&1_700_000_000i32.to_le_bytes());
        body.extend_from_slice(&5u32.to_le_bytes());
        body.extend_from_slice(&4u32.to_le_bytes()); // "gps" + NUL
        body.extend_from_slice(b"gps\0");
        body.push(status as u8);
        body.push(0); // align u16
        body.extend_from_slice(&1u16.to_le_bytes());
        while body.len() % 8 != 0 {
            body.push(0);
        }
        for x in [lat, 10.9, 80.0] {
            body.extend_from_slice(&x.to_le_bytes());
        }
        for k in 0..9 {
            body.extend_from_slice(&(if k % 4 == 0 { 0.25f64 } else { 0.0 }).to_le_bytes());
        }
        body.push(2);
        b.extend(body);
        b
    }

    #[test]
    fn a_nav_sat_fix_reads_as_a_gnss_fix_and_no_fix_or_nan_are_said() {
        let t = Translator::for_schema("cdr", NAV_SAT_FIX, b"", None)
            .unwrap()
            .unwrap();
        let Translated::Message {
            message: AnyMessage::GnssFix(f),
            took_log_time,
        } = t.translate(&nav_sat_fix_payload(0, 44.6), 7).unwrap()
        else {
            panic!("not a fix")
        };
        assert!(!took_log_time);
        assert_eq!(f.stamp_ns, 1_700_000_000_000_000_005);
        assert_eq!(
            (f.fix_type, f.latitude_deg, f.altitude_m),
            (FixType::Single, Some(44.6), Some(80.0))
        );
        assert_eq!(f.position_covariance_enu_m2.map(|c| c[8]), Some(0.25));
        assert_eq!(
            t.translate(&nav_sat_fix_payload(-1, 44.6), 7).unwrap(),
            Translated::Skipped("NavSatFix with status NO_FIX")
        );
        assert!(t.translate(&nav_sat_fix_payload(0, f64::NAN), 7).is_err());
        assert!(matches!(
            t.translate(&[0, 1, 0, 0, 1, 2], 7),
            Err(ForeignError::Cdr { .. })
        ));
        // A twist needs a role; an IMU cannot be a radar.
        assert!(Translator::for_schema("cdr", TWIST_STAMPED, b"", None)
            .unwrap_err()
            .contains("role"));
        assert!(Translator::for_schema("cdr", IMU, b"", Some(Role::Radar)).is_err());
        assert!(Translator::for_schema("json", NAV_SAT_FIX, b"", None)
            .unwrap()
            .is_none());
    }
}

/// Whether a message definition's first field is a `std_msgs/Header` (ROS 1's and ROS 2's;
/// constants, `uint8 KNOWN=3`, are not fields and may come first).
pub(super) fn begins_with_header(definition: &[u8]) -> bool {
    let first_field = std::str::from_utf8(definition)
        .ok()
        .and_then(|d| {
            d.lines()
                .map(str::trim)
                .find(|l| !l.is_empty() && !l.starts_with('#') && !l.contains('='))
        })
        .unwrap_or("");
    matches!(
        first_field.split_whitespace().collect::<Vec<_>>()[..],
        ["std_msgs/Header" | "std_msgs/msg/Header" | "Header", _]
    )
}

/// A CDR message whose definition begins with a `std_msgs/Header` (every stamped sensor
/// message) with its `header.stamp` moved by `correct`, into `out`; false (nothing written)
/// for any other message or a zero stamp (no time of its own).
pub fn restamp_header(
    definition: &[u8],
    data: &[u8],
    correct: impl Fn(u64) -> u64,
    out: &mut Vec<u8>,
) -> bool {
    if !begins_with_header(definition) || data.len() < 12 {
        return false;
    }
    let little = match data[1] {
        0x01 | 0x03 => true,
        0x00 | 0x02 => false,
        _ => return false,
    };
    // ROS 2's seconds are signed 32 bits.
    restamp_words(data, little, i32::MAX as u32, correct, out)
}

/// The header stamp at bytes 4 to 12 of `data` (seconds, nanoseconds: after CDR's
/// encapsulation header, or ROS 1's sequence number) moved by `correct` into `out`; false for
/// a zero stamp, one that is not a time, or one moved past `max_sec`.
pub(super) fn restamp_words(
    data: &[u8],
    little: bool,
    max_sec: u32,
    correct: impl Fn(u64) -> u64,
    out: &mut Vec<u8>,
) -> bool {
    let word = |at: usize| {
        let b = [data[at], data[at + 1], data[at + 2], data[at + 3]];
        if little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    };
    let (sec, nanosec) = (word(4), word(8));
    if sec == 0 && nanosec == 0 || sec > max_sec || nanosec >= 1_000_000_000 {
        return false;
    }
    let t = correct(u64::from(sec) * 1_000_000_000 + u64::from(nanosec));
    let sec = t / 1_000_000_000;
    if sec > u64::from(max_sec) {
        return false;
    }
    let bytes = |v: u32| {
        if little {
            v.to_le_bytes()
        } else {
            v.to_be_bytes()
        }
    };
    out.clear();
    out.extend_from_slice(data);
    out[4..8].copy_from_slice(&bytes(sec as u32));
    out[8..12].copy_from_slice(&bytes((t % 1_000_000_000) as u32));
    true
}
