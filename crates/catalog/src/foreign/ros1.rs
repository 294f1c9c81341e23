//! ROS 1 messages in ROS 1's serialisation (MCAP message encoding `ros1`, schema encoding
//! `ros1msg`, as `mcap convert` writes a bag and as railfuse's own bag reader does): the same
//! messages as ROS 2's ([`super::ros2`]: NavSatFix, Imu, TwistWithCovarianceStamped,
//! TwistStamped, Odometry, and tf's TFMessage), read into the same structs and translated by
//! the same code. Two things differ on the wire: the payload is little-endian with no
//! alignment and no encapsulation header (decoded by `roslibrust_serde_rosmsg`, which checks
//! every length against the payload before it allocates), and `std_msgs/Header` carries a
//! sequence number and an unsigned `time` (`uint32 secs, nsecs`).

use serde::Deserialize;

use super::ros2::{self, RosHeader, Wire};
use super::{Decode, ForeignError, Role};
use crate::messages::MessageKind;

/// The MCAP message encoding of ROS 1 channels.
pub const ENCODING: &str = "ros1";
/// The MCAP schema encoding of ROS 1 message definitions.
pub const SCHEMA_ENCODING: &str = "ros1msg";

/// Every schema read here, by its ROS 1 name.
pub const SCHEMAS: [&str; 5] = [
    "sensor_msgs/NavSatFix",
    "sensor_msgs/Imu",
    "geometry_msgs/TwistWithCovarianceStamped",
    "geometry_msgs/TwistStamped",
    "nav_msgs/Odometry",
];

/// tf's message of transforms (`/tf`, `/tf_static`).
pub const TF_MESSAGE: &str = "tf2_msgs/TFMessage";

#[derive(Debug, Deserialize)]
pub struct Time {
    pub secs: u32,
    pub nsecs: u32,
}

/// ROS 1's `std_msgs/Header`.
#[derive(Debug, Deserialize)]
pub struct Header {
    pub seq: u32,
    pub stamp: Time,
    pub frame_id: String,
}

impl RosHeader for Header {
    fn stamp(&self) -> (i64, u32) {
        (i64::from(self.stamp.secs), self.stamp.nsecs)
    }
    fn into_frame_id(self) -> String {
        self.frame_id
    }
}

/// ROS 1's serialisation.
pub(super) struct Ros1;

impl Wire for Ros1 {
    type Header = Header;
    fn decode<T: for<'de> Deserialize<'de>>(data: &[u8], schema: &str) -> Result<T, ForeignError> {
        from_ros1(data, schema)
    }
}

/// Decodes a ROS 1 payload as `T`: every byte of it, no more and no less.
pub fn from_ros1<T: for<'de> Deserialize<'de>>(
    data: &[u8],
    schema: &str,
) -> Result<T, ForeignError> {
    let fail = |cause: String| ForeignError::Ros1 {
        schema: schema.to_owned(),
        cause,
    };
    let length = u32::try_from(data.len()).map_err(|_| fail("over 4 GiB".into()))?;
    roslibrust_serde_rosmsg::de::from_reader_known_length(data, length)
        .map_err(|e| fail(e.to_string()))
}

/// A ROS 1 type's ROS 2 name (`sensor_msgs/NavSatFix` → `sensor_msgs/msg/NavSatFix`).
pub fn ros2_name(ros1: &str) -> String {
    match ros1.split_once('/') {
        Some((package, name)) if !name.contains('/') => format!("{package}/msg/{name}"),
        _ => ros1.to_owned(),
    }
}

/// Whether railfuse reads messages of this ROS 1 type (as a sensor, or tf's transforms).
pub fn reads(ros1_type: &str) -> bool {
    SCHEMAS.contains(&ros1_type) || ros1_type == TF_MESSAGE
}

/// The catalogue kind and reader of a ROS 1 `schema` for a sensor of `role`.
pub(super) fn reader(
    schema: &str,
    role: Option<Role>,
) -> Result<Option<(MessageKind, Decode)>, String> {
    if !SCHEMAS.contains(&schema) {
        return Ok(None);
    }
    ros2::reader::<Ros1>(&ros2_name(schema), role)
}

/// The transforms of a ROS 1 `tf2_msgs/TFMessage`.
pub fn transforms(data: &[u8]) -> Result<Vec<super::FrameTransform>, ForeignError> {
    ros2::transforms::<Ros1>(data)
}

/// A ROS 1 message whose definition begins with a `std_msgs/Header` with its `header.stamp`
/// (after the sequence number: bytes 4 to 12, little-endian) moved by `correct`, into `out`;
/// false (nothing written) for any other message or a zero stamp (no time of its own).
pub fn restamp_header(
    definition: &[u8],
    data: &[u8],
    correct: impl Fn(u64) -> u64,
    out: &mut Vec<u8>,
) -> bool {
    if !ros2::begins_with_header(definition) || data.len() < 12 {
        return false;
    }
    // ROS 1's `time`: unsigned seconds, little-endian.
    ros2::restamp_words(data, true, u32::MAX, correct, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ros1_header_stamp_moves_with_the_clock_and_other_messages_do_not() {
        let definition = b"# a fix\nuint8 KNOWN=3\nHeader header\nfloat64 latitude\n";
        let mut data = 9u32.to_le_bytes().to_vec();
        data.extend(1_780_300_800u32.to_le_bytes());
        data.extend(250_000_000u32.to_le_bytes());
        data.extend(0u32.to_le_bytes());
        let mut out = Vec::new();
        assert!(restamp_header(
            definition,
            &data,
            |t| t - 1_500_000_000,
            &mut out
        ));
        let h: Header = from_ros1(&out, "std_msgs/Header").unwrap();
        assert_eq!(
            (h.seq, h.stamp.secs, h.stamp.nsecs),
            (9, 1_780_300_798, 750_000_000)
        );
        assert!(!restamp_header(b"string data\n", &data, |t| t, &mut out));
        let zero = [9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        assert!(!restamp_header(definition, &zero, |t| t, &mut out));
    }
}
