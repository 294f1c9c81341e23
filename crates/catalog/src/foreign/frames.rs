//! A ROS recording's `/tf_static` as the train's installation drawing: each sensor topic's
//! `header.frame_id` placed in the tree of static transforms, and so on the train
//! ([`Vehicle`]), the way robot_localization finds a sensor's place from tf.
//!
//! The body frame is railfuse's: origin at the front end on the top of rail, x forward, y
//! left, z up (ROS's REP 103 axes). A tree names the front end with a frame `front_end`
//! ([`FRONT_END`]); without one, its root frame (`base_link`) is taken as the front end and
//! that is said. A frame `rear_end` gives the train's length; without one the length is the
//! rearmost sensor's distance from the front end, also said.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::FrameTransform;
use crate::log::LogMessage;
use crate::messages::{SensorMount, Vehicle};
use crate::vehicle::VehicleProblem;

/// The topic of static transforms.
pub const TF_STATIC: &str = "/tf_static";
/// The frame at the train's front end on the top of rail (the body frame's origin).
pub const FRONT_END: &str = "front_end";
/// The frame at the train's rear end (its distance from the front end is the length).
pub const REAR_END: &str = "rear_end";
/// Longest frame name read from a header (untrusted input).
const MAX_FRAME_ID: usize = 256;

/// Why a `/tf_static` cannot place the sensors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FramesProblem {
    #[error("/tf_static: frames {} form a cycle", .0.join(" → "))]
    Cycle(Vec<String>),
    #[error("/tf_static: frame '{frame}' has two parents, '{first}' and '{second}'")]
    TwoParents {
        frame: String,
        first: String,
        second: String,
    },
    #[error(
        "/tf_static: topic {topic}'s frame '{frame}' is in no transform (a missing frame): \
         publish where it sits, or place the sensor in [vehicle]"
    )]
    Missing { topic: String, frame: String },
    #[error("/tf_static: frames '{0}' and '{1}' are in trees no transform joins")]
    Apart(String, String),
    #[error("/tf_static: transform of '{0}' has a rotation that is not a quaternion")]
    Rotation(String),
    #[error("/tf_static places the sensors outside the train: {0}")]
    Vehicle(VehicleProblem),
}

/// The static transforms of a recording, as a tree: each frame's pose in its root's frame.
#[derive(Debug, Clone, Default)]
pub struct FrameTree {
    /// Each child frame's transform (to its one parent).
    parent_of: BTreeMap<String, (String, Isometry3<f64>)>,
}

impl FrameTree {
    /// The tree of `transforms`: every frame with one parent, no cycle, every rotation a
    /// quaternion.
    pub fn new(transforms: &[FrameTransform]) -> Result<Self, FramesProblem> {
        let mut parent_of: BTreeMap<String, (String, Isometry3<f64>)> = BTreeMap::new();
        for t in transforms {
            let (child, parent) = (bare(&t.child), bare(&t.parent));
            let [x, y, z, w] = t.rotation_xyzw;
            let q = Quaternion::new(w, x, y, z);
            let norm = q.norm();
            let unit = norm.is_finite() && (norm - 1.0).abs() < 1e-3;
            if !(unit && t.translation_m.iter().all(|v| v.is_finite())) {
                return Err(FramesProblem::Rotation(child.to_owned()));
            }
            let pose = Isometry3::from_parts(
                Translation3::from(Vector3::from(t.translation_m)),
                UnitQuaternion::from_quaternion(q),
            );
            match parent_of.get(child) {
                Some((first, _)) if first != parent => {
                    return Err(FramesProblem::TwoParents {
                        frame: child.to_owned(),
                        first: first.clone(),
                        second: parent.to_owned(),
                    })
                }
                _ => {
                    parent_of.insert(child.to_owned(), (parent.to_owned(), pose));
                }
            }
        }
        let tree = Self { parent_of };
        for frame in tree.parent_of.keys() {
            tree.in_root(frame)?;
        }
        Ok(tree)
    }

    /// Whether `frame` is in some transform.
    pub fn knows(&self, frame: &str) -> bool {
        let frame = bare(frame);
        self.parent_of.contains_key(frame) || self.parent_of.values().any(|(p, _)| p == frame)
    }

    /// `frame`'s root and its pose in the root's frame.
    fn in_root(&self, frame: &str) -> Result<(String, Isometry3<f64>), FramesProblem> {
        let mut path = vec![bare(frame).to_owned()];
        let mut pose = Isometry3::identity();
        while let Some((parent, to_parent)) = self.parent_of.get(path.last().expect("not empty")) {
            pose = to_parent * pose;
            if let Some(i) = path.iter().position(|f| f == parent) {
                let mut cycle = path[i..].to_vec();
                cycle.push(parent.clone());
                return Err(FramesProblem::Cycle(cycle));
            }
            path.push(parent.clone());
        }
        Ok((path.pop().expect("not empty"), pose))
    }

    /// The train whose sensors are `sensors` (topic, frame) in this tree: each placed in the
    /// body frame (at [`FRONT_END`], else the sensors' root), with the notes a user should
    /// read (what was taken for the front end and the length).
    pub fn vehicle(
        &self,
        name: &str,
        sensors: &[(String, String)],
    ) -> Result<(Vehicle, Vec<String>), FramesProblem> {
        let mut notes = Vec::new();
        let mut placed = Vec::new();
        for (topic, frame) in sensors {
            if !self.knows(frame) {
                return Err(FramesProblem::Missing {
                    topic: topic.clone(),
                    frame: frame.clone(),
                });
            }
            let (root, pose) = self.in_root(frame)?;
            placed.push((topic, frame, root, pose));
        }
        let Some((_, _, root, _)) = placed.first() else {
            return Ok((Vehicle::point(), notes));
        };
        let body = match self.knows(FRONT_END) {
            true => self.in_root(FRONT_END)?,
            false => {
                notes.push(format!(
                    "/tf_static has no frame '{FRONT_END}': its root '{root}' is taken as the \
                     front end on the top of rail"
                ));
                (root.clone(), Isometry3::identity())
            }
        };
        let from_body = body.1.inverse();
        let mut vehicle = Vehicle {
            name: name.to_owned(),
            ..Vehicle::point()
        };
        for (topic, frame, root, pose) in &placed {
            if *root != body.0 {
                return Err(FramesProblem::Apart((*frame).clone(), body.0.clone()));
            }
            let in_body = from_body * pose;
            let (roll, pitch, yaw) = in_body.rotation.euler_angles();
            vehicle.sensors.push(SensorMount {
                topic: (*topic).clone(),
                frame_id: Some((*frame).clone()),
                // + 0.0: no "-0.000" where a frame is not turned.
                lever_arm_m: in_body.translation.vector.map(|v| v + 0.0).into(),
                mounting_deg: [roll, pitch, yaw].map(|a| a.to_degrees() + 0.0),
            });
        }
        let rearmost = vehicle
            .sensors
            .iter()
            .map(|s| -s.lever_arm_m[0])
            .fold(0.0, f64::max);
        vehicle.length_m = match self.knows(REAR_END) {
            true => {
                let (rear_root, rear) = self.in_root(REAR_END)?;
                if rear_root != body.0 {
                    return Err(FramesProblem::Apart(REAR_END.into(), body.0.clone()));
                }
                -(from_body * rear).translation.vector.x
            }
            false => {
                notes.push(format!(
                    "/tf_static has no frame '{REAR_END}': the train's length is taken as the \
                     rearmost sensor's {rearmost:.3} m behind the front end"
                ));
                rearmost
            }
        };
        vehicle.check().map_err(FramesProblem::Vehicle)?;
        Ok((vehicle, notes))
    }
}

/// tf's frame names without the leading slash ROS 1 allowed (`/base_link` is `base_link`).
fn bare(frame: &str) -> &str {
    frame.trim_start_matches('/')
}

/// What a recording says about its frames: the transforms of its `/tf_static` and each
/// stamped topic's `header.frame_id` (its first message's), gathered message by message.
#[derive(Debug, Clone, Default)]
pub struct FrameCollector {
    transforms: Vec<FrameTransform>,
    /// A topic's frame (the first message's).
    pub topic_frames: BTreeMap<String, String>,
    /// `/tf_static` messages that do not read.
    pub unreadable: u64,
}

impl FrameCollector {
    /// Takes what `m` says about frames: its transforms (on `/tf_static`), else its topic's
    /// frame (a ROS message that begins with a header; the first one's).
    pub fn add(&mut self, m: &LogMessage<'_>) {
        let c = m.channel;
        if c.topic == TF_STATIC {
            let read = match c.message_encoding.as_str() {
                super::ros1::ENCODING => Some(super::ros1::transforms(m.data)),
                super::ros2::ENCODING => Some(super::ros2::transforms_cdr(m.data)),
                _ => None,
            };
            match read {
                Some(Ok(t)) => crate::formats::add_frames(&mut self.transforms, t),
                Some(Err(_)) => self.unreadable += 1,
                None => {}
            }
            return;
        }
        if self.topic_frames.contains_key(&c.topic) {
            return;
        }
        let definition = c.schema.as_ref().map_or(&[][..], |s| &s.data[..]);
        let frame = sensor_frame_id(&c.message_encoding, c.schema_name(), definition, m.data);
        if let Some(frame) = frame {
            self.topic_frames.insert(c.topic.clone(), frame);
        }
    }

    /// Whether a `/tf_static` was read.
    pub fn has_transforms(&self) -> bool {
        !self.transforms.is_empty()
    }

    /// The train of the transforms read, with each of `topics` (every topic with a frame in
    /// the tree where `None`) placed; `None` where no `/tf_static` was read.
    pub fn vehicle(
        &self,
        name: &str,
        topics: Option<&[String]>,
    ) -> Option<Result<(Vehicle, Vec<String>), FramesProblem>> {
        if !self.has_transforms() {
            return None;
        }
        let tree = match FrameTree::new(&self.transforms) {
            Ok(t) => t,
            Err(e) => return Some(Err(e)),
        };
        let sensors: Vec<(String, String)> = match topics {
            Some(topics) => topics
                .iter()
                .filter_map(|t| Some((t.clone(), self.topic_frames.get(t)?.clone())))
                .collect(),
            None => self
                .topic_frames
                .iter()
                .filter(|(_, f)| tree.knows(f))
                .map(|(t, f)| (t.clone(), f.clone()))
                .collect(),
        };
        Some(tree.vehicle(name, &sensors))
    }
}

/// How far into a run [`scan`] looks for `/tf_static` and the topics' frames: a latched
/// `/tf_static` is recorded within seconds of the start.
pub const SCAN_SPAN_NS: u64 = 120_000_000_000;

/// The frames of a run's first [`SCAN_SPAN_NS`]: its `/tf_static`, and the frame of each of
/// `topics`, read until every one is known (a bounded pass, not the whole run).
pub fn scan(run: &crate::run::Run, topics: &[String]) -> crate::error::Result<FrameCollector> {
    let mut frames = FrameCollector::default();
    let mut reader = run.reader()?;
    let mut first = None;
    while let Some(record) = reader.next() {
        let crate::log::LogRecord::Message(m) = record? else {
            continue;
        };
        let start = *first.get_or_insert(m.log_time_ns);
        frames.add(&m);
        let known = topics.iter().all(|t| frames.topic_frames.contains_key(t));
        if frames.has_transforms() && known || m.log_time_ns.saturating_sub(start) > SCAN_SPAN_NS {
            break;
        }
    }
    Ok(frames)
}

/// The frame a ROS message's measurement is in: its `header.frame_id`, or for a
/// `nav_msgs/Odometry` its `child_frame_id` (the twist's frame; the header's is the world's),
/// of a message in ROS 1's serialisation or ROS 2's CDR whose definition begins with a
/// `std_msgs/Header`; `None` for any other message or a header that does not read.
pub fn sensor_frame_id(
    encoding: &str,
    schema: &str,
    definition: &[u8],
    data: &[u8],
) -> Option<String> {
    if !super::ros2::begins_with_header(definition) {
        return None;
    }
    // ROS 1: seq, stamp, then the string; CDR: the encapsulation header, stamp, string (its
    // length counting a NUL, the next field aligned to 4 from the end of the encapsulation).
    let (little, cdr) = match encoding {
        super::ros1::ENCODING => (true, false),
        super::ros2::ENCODING => match data.get(1)? {
            0x01 | 0x03 => (true, true),
            0x00 | 0x02 => (false, true),
            _ => return None,
        },
        _ => return None,
    };
    let string_at = |at: usize| -> Option<(&str, usize)> {
        let word: [u8; 4] = data.get(at..at + 4)?.try_into().ok()?;
        let len = match little {
            true => u32::from_le_bytes(word),
            false => u32::from_be_bytes(word),
        } as usize;
        if len > MAX_FRAME_ID {
            return None;
        }
        let bytes = data.get(at + 4..at + 4 + len)?;
        let end = match cdr {
            true => (at + 4 + len - 4).next_multiple_of(4) + 4,
            false => at + 4 + len,
        };
        let text = if cdr {
            bytes.strip_suffix(&[0])?
        } else {
            bytes
        };
        Some((std::str::from_utf8(text).ok()?, end))
    };
    let (mut frame, next) = string_at(12)?;
    if matches!(schema, "nav_msgs/Odometry" | "nav_msgs/msg/Odometry") {
        frame = string_at(next)?.0;
    }
    (!frame.is_empty()).then(|| bare(frame).to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(parent: &str, child: &str, t: [f64; 3], yaw_deg: f64) -> FrameTransform {
        let h = yaw_deg.to_radians() / 2.0;
        FrameTransform {
            parent: parent.into(),
            child: child.into(),
            translation_m: t,
            rotation_xyzw: [0.0, 0.0, h.sin(), h.cos()],
        }
    }

    fn sensors(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(t, f)| ((*t).to_owned(), (*f).to_owned()))
            .collect()
    }

    #[test]
    fn sensors_are_placed_from_the_front_end_frame_through_the_tree() {
        // base_link mid-train; the front end 50 m ahead of it; the antenna 12 m behind the
        // front end and 4 m up through a roof frame; the IMU turned 2° in yaw.
        let tree = FrameTree::new(&[
            tf("base_link", "front_end", [50.0, 0.0, -1.0], 0.0),
            tf("base_link", "rear_end", [-50.0, 0.0, -1.0], 0.0),
            tf("base_link", "roof", [38.0, 0.0, 1.0], 0.0),
            tf("/roof", "gps", [0.0, 0.0, 2.0], 0.0),
            tf("base_link", "imu_link", [30.0, 0.5, 0.0], 2.0),
        ])
        .unwrap();
        let (v, notes) = tree
            .vehicle(
                "t",
                &sensors(&[("/gnss/fix", "gps"), ("/imu/data", "imu_link")]),
            )
            .unwrap();
        assert!(notes.is_empty(), "{notes:?}");
        assert!((v.length_m - 100.0).abs() < 1e-9);
        let gps = &v.sensors[0];
        for (got, want) in gps.lever_arm_m.iter().zip([-12.0, 0.0, 4.0]) {
            assert!((got - want).abs() < 1e-9, "{:?}", gps.lever_arm_m);
        }
        let imu = &v.sensors[1];
        assert!((imu.lever_arm_m[0] + 20.0).abs() < 1e-9);
        assert!(
            (imu.mounting_deg[2] - 2.0).abs() < 1e-9,
            "{:?}",
            imu.mounting_deg
        );
        assert_eq!(imu.frame_id.as_deref(), Some("imu_link"));
    }

    #[test]
    fn without_a_front_end_frame_the_root_is_the_front_end_and_that_is_said() {
        let tree = FrameTree::new(&[tf("base_link", "gps", [-12.0, 0.0, 4.0], 0.0)]).unwrap();
        let (v, notes) = tree
            .vehicle("t", &sensors(&[("/gnss/fix", "gps")]))
            .unwrap();
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(notes[0].contains("'base_link' is taken as the front end"));
        assert!((v.length_m - 12.0).abs() < 1e-9);
    }

    #[test]
    fn a_cycle_a_missing_frame_two_trees_and_a_sensor_ahead_of_the_train_are_refused() {
        let cycle = FrameTree::new(&[
            tf("a", "b", [1.0, 0.0, 0.0], 0.0),
            tf("b", "c", [1.0, 0.0, 0.0], 0.0),
            tf("c", "a", [1.0, 0.0, 0.0], 0.0),
        ]);
        let e = cycle.unwrap_err().to_string();
        assert_eq!(e, "/tf_static: frames a → c → b → a form a cycle");
        let tree = FrameTree::new(&[
            tf("base_link", "gps", [-12.0, 0.0, 4.0], 0.0),
            tf("odom", "imu", [0.0, 0.0, 0.0], 0.0),
        ])
        .unwrap();
        let missing = tree.vehicle("t", &sensors(&[("/imu/data", "imu_link")]));
        assert!(matches!(missing, Err(FramesProblem::Missing { .. })));
        assert!(missing
            .unwrap_err()
            .to_string()
            .contains("topic /imu/data's frame 'imu_link' is in no transform"));
        let apart = tree.vehicle("t", &sensors(&[("/gnss/fix", "gps"), ("/imu/data", "imu")]));
        assert!(matches!(apart, Err(FramesProblem::Apart(..))), "{apart:?}");
        let ahead = FrameTree::new(&[tf("base_link", "gps", [3.0, 0.0, 4.0], 0.0)]).unwrap();
        let e = ahead.vehicle("t", &sensors(&[("/gnss/fix", "gps")]));
        assert!(matches!(e, Err(FramesProblem::Vehicle(_))), "{e:?}");
        let turned = FrameTree::new(&[tf("base_link", "imu", [-3.0, 0.0, 1.0], 90.0)]).unwrap();
        let e = turned.vehicle("t", &sensors(&[("/imu/data", "imu")]));
        assert!(e.unwrap_err().to_string().contains("over 45°"));
    }

    #[test]
    fn a_sensor_frame_reads_from_ros1_and_cdr_payloads() {
        let def = b"std_msgs/Header header\nfloat64 x\n";
        let read = |enc, schema, data: &[u8]| sensor_frame_id(enc, schema, def, data);
        let mut ros1 = vec![0u8; 12];
        ros1.extend(8u32.to_le_bytes());
        ros1.extend(b"/imu_top");
        ros1.extend(0f64.to_le_bytes());
        assert_eq!(
            read("ros1", "sensor_msgs/Imu", &ros1).as_deref(),
            Some("imu_top")
        );
        // An odometry's twist is in its child frame: "odom" (5 bytes with the NUL, padded to
        // 8), then "wheel1".
        let mut cdr = vec![0u8, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0];
        cdr.extend(5u32.to_le_bytes());
        cdr.extend(b"odom\0\0\0\0");
        cdr.extend(7u32.to_le_bytes());
        cdr.extend(b"wheel1\0");
        assert_eq!(
            read("cdr", "sensor_msgs/msg/Imu", &cdr).as_deref(),
            Some("odom")
        );
        let odometry = read("cdr", "nav_msgs/msg/Odometry", &cdr);
        assert_eq!(odometry.as_deref(), Some("wheel1"));
        assert_eq!(sensor_frame_id("cdr", "x", b"float64 x\n", &cdr), None);
        let mut long = vec![0u8; 12];
        long.extend(u32::MAX.to_le_bytes());
        assert_eq!(read("ros1", "sensor_msgs/Imu", &long), None);
    }
}
