//! The pipeline `refuse` runs on a log given no configuration: one Kalman filter on the
//! constant-acceleration model, in chainage, fusing every channel whose messages feed a
//! sensor model, whatever tool wrote the log. What each topic decodes to picks its sensor
//! (through [`Translator`] for other tools' schemas); a speed whose schema cannot say whose
//! it is (a ROS `Twist`) takes its role from the topic's name (`radar`, `odom`, `wheel`,
//! `gps`, …). Every topic is accounted for: used, with what it gives, or left out, with why.
//!
//! The pipeline is written as configuration text and parsed like any file, so what it runs is
//! exactly what `--save-config` writes for the user to edit.
//!
//! The variances are a first look's, not a tuned pipeline's, but the errors that are not white
//! noise are modelled as states, so that the covariance it reports is honest: each speed
//! sensor's scale factor (a radar's mounting, a worn wheel), a loop's survey scale, an IMU's
//! acceleration bias (a mounting's tilt of gravity among it), and a GNSS fix's chainage bias
//! (the antenna's place and the map's survey). A GNSS fix's chainage takes the variance the
//! fix reports where the log's fixes report one (an RTK fix's centimetres; a multipath-pulled
//! single fix's metres), else 4 m²; speeds 0.1 (m/s)² with tight gates, an IMU's
//! acceleration 0.01 (m/s²)², loops and balises as their messages report.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use railfuse_catalog::foreign::{Role, Translator};
use railfuse_catalog::log::{ChannelInfo, LogRecord};
use railfuse_catalog::messages::{GnssFix, MessageKind};
use railfuse_catalog::run::Run;
use railfuse_catalog::{foxglove, topics};

use crate::error::{Error, Result};
use crate::spec::Pipelines;

/// The name of the default pipeline (its fused channels are `/fused/default/…`).
pub const NAME: &str = "default";

/// One topic of the log and what the default pipeline did with it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopicChoice {
    pub topic: String,
    /// What it gives (used) or why it was left out.
    pub why: String,
}

/// The default pipeline of one log.
#[derive(Debug, Clone)]
pub struct DefaultConfig {
    /// The configuration text, as a file would hold it.
    pub text: String,
    pub used: Vec<TopicChoice>,
    pub left_out: Vec<TopicChoice>,
}

impl DefaultConfig {
    /// The pipelines of the text; `path` names them in messages and anchors relative paths.
    pub fn pipelines(&self, path: &Path) -> Result<Pipelines> {
        Pipelines::parse(&self.text, path)
    }
}

/// What one sensor table of the default pipeline says.
struct Sensor {
    role: Option<Role>,
    fields: Option<&'static str>,
    variance: &'static str,
    gate_nis: Option<f64>,
    /// Its error states (`scale_factor = …`), a line.
    states: Option<&'static str>,
}

/// A speed sensor's scale factor: 1 % either way before the run shows it.
const SPEED_SCALE: &str = "scale_factor = { std = 0.01 }";
/// A loop's survey scale (it grows 2 cm a kilometre at 2e-5).
const LOOP_SCALE: &str = "scale_factor = { std = 1e-4, quantity = \"chainage\" }";
/// An IMU's acceleration bias: a mounting's tilt of gravity (3° is 0.5 m/s²) and the
/// accelerometer's own, steady over a run.
const IMU_BIAS: &str = "acceleration_bias = { std_mps2 = 0.5, time_constant_s = 3600.0 }";
/// A GNSS fix's chainage bias: the antenna's place on the train and the map's survey, steady
/// over a run.
const GNSS_BIAS: &str = "chainage_bias = { std_m = 0.1, time_constant_s = 1e6 }";

/// The default pipeline for the log at `input`; `track` is a track file (GeoJSON or CSV)
/// for a log without one, which GNSS fixes need to give chainage.
pub fn default_config(run: &Run, track: Option<&Path>) -> Result<DefaultConfig> {
    let channels = channels(run)?;
    let input = run.name();
    let track_in_log = channels
        .iter()
        .any(|c| c.kind() == Some(MessageKind::TrackMap));
    let has_track = track_in_log || track.is_some();
    let gnss_reports = gnss_reports(run, &channels)?;
    let (mut used, mut left_out) = (Vec::new(), Vec::new());
    let mut sensors = String::new();
    let mut sensor_topics = Vec::new();
    for c in &channels {
        let choice = |why: String| TopicChoice {
            topic: c.topic.clone(),
            why,
        };
        match sensor_of(c, has_track, &gnss_reports) {
            Ok((sensor, gives)) => {
                if let Some(s) = sensor {
                    write_sensor(&mut sensors, &c.topic, &s);
                    sensor_topics.push(c.topic.clone());
                }
                used.push(choice(gives));
            }
            Err(why) => left_out.push(choice(why)),
        }
    }
    if sensors.is_empty() {
        let why: Vec<String> = left_out
            .iter()
            .map(|c| format!("{}: {}", c.topic, c.why))
            .collect();
        return Err(Error::NoDefaultPipeline(format!(
            "{}: no topic feeds a sensor model, so there is no default pipeline to run ({}); \
             write one and pass it with --config",
            input.display(),
            if why.is_empty() {
                "the log has no channels".to_owned()
            } else {
                why.join("; ")
            }
        )));
    }
    let mut text = format!(
        "# The default pipeline railfuse picked for {} from what its topics decode to.\n",
        input.display()
    );
    if let (Some(t), false) = (track, track_in_log) {
        let t = std::path::absolute(t).unwrap_or_else(|_| t.to_owned());
        writeln!(text, "track = {}", toml_string(&t.display().to_string())).unwrap();
    }
    if let Some(v) = log_vehicle(run, &channels)? {
        write_vehicle(&mut text, v, &sensor_topics, "The log's /vehicle");
    } else if let Some((v, _)) = tf_vehicle(run, &channels, &sensor_topics)? {
        write_vehicle(
            &mut text,
            v,
            &sensor_topics,
            "The train the log's /tf_static places",
        );
    }
    write!(
        text,
        "\n[[pipeline]]\nname = \"{NAME}\"\nfilter = \"kalman\"\n\
         motion = {{ model = \"constant_acceleration\", jerk_psd = 0.2 }}\n\
         reorder_window_s = 0.5\n\n\
         [pipeline.initial]\nspeed_mps = 0.0\nspeed_std_mps = 30.0\nacceleration_std_mps2 = 1.0\n\
         {sensors}"
    )
    .unwrap();
    Ok(DefaultConfig {
        text,
        used,
        left_out,
    })
}

/// `v` as the configuration's `[vehicle]` table under a comment saying whence it came: the
/// pipeline reads the log's train as it is; written out, it is there to edit (a calibrated
/// mounting), for the sensors the pipeline reads.
fn write_vehicle(
    text: &mut String,
    mut v: railfuse_catalog::messages::Vehicle,
    sensor_topics: &[String],
    whence: &str,
) {
    v.sensors.retain(|m| sensor_topics.contains(&m.topic));
    let table =
        std::collections::BTreeMap::from([("vehicle", crate::config::VehicleConfig::of(&v))]);
    let table = toml::to_string(&table).expect("a vehicle serialises");
    write!(
        text,
        "\n# {whence}: the train's length, where each sensor sits and how it is turned.\n{table}"
    )
    .unwrap();
}

/// The train a ROS recording's `/tf_static` places, for a run without `/vehicle`: each of
/// `topics` at its messages' `header.frame_id`, with what was assumed (the front end, the
/// length); `None` where the run has no `/tf_static`. A cycle, a missing frame or a sensor
/// placed off the train is refused.
pub fn tf_vehicle(
    run: &Run,
    channels: &[Arc<ChannelInfo>],
    topics: &[String],
) -> Result<Option<(railfuse_catalog::messages::Vehicle, Vec<String>)>> {
    use railfuse_catalog::foreign::frames;
    let has = |t: &str| channels.iter().any(|c| c.topic == t);
    if has(topics::VEHICLE) || !has(frames::TF_STATIC) {
        return Ok(None);
    }
    let collected = frames::scan(run, topics)?;
    match collected.vehicle("from /tf_static", Some(topics)) {
        None => Ok(None),
        Some(Ok(v)) => Ok(Some(v)),
        Some(Err(e)) => Err(Error::Map(format!("{}: {e}", run.name().display()))),
    }
}

/// The log's `/vehicle` (its first), where it has that channel.
fn log_vehicle(
    run: &Run,
    channels: &[Arc<ChannelInfo>],
) -> Result<Option<railfuse_catalog::messages::Vehicle>> {
    if !channels
        .iter()
        .any(|c| c.kind() == Some(MessageKind::Vehicle))
    {
        return Ok(None);
    }
    let mut reader = run.reader()?;
    while let Some(record) = reader.next() {
        if let LogRecord::Message(m) = record? {
            if m.is::<railfuse_catalog::messages::Vehicle>() {
                return Ok(Some(m.decode(&run.name())?));
            }
        }
    }
    Ok(None)
}

/// Every channel of the log, by topic: from the summary, or from the data section where the
/// summary does not list them.
pub fn channels(run: &Run) -> Result<Vec<Arc<ChannelInfo>>> {
    let mut reader = run.reader()?;
    let mut channels = match reader.summary().and_then(|s| s.channels.clone()) {
        Some(c) => c,
        None => {
            let mut found = Vec::new();
            while let Some(record) = reader.next() {
                if let LogRecord::Channel(c) = record? {
                    found.push(c);
                }
            }
            found
        }
    };
    channels.sort_by(|a, b| a.topic.cmp(&b.topic).then(a.id.cmp(&b.id)));
    channels.dedup_by(|a, b| a.topic == b.topic);
    Ok(channels)
}

/// What a channel's topic alone says of it, whatever its schema: railfuse's own outputs are
/// left out, `/tf_static` places the sensors.
fn by_topic(topic: &str) -> Option<std::result::Result<(Option<Sensor>, String), String>> {
    if topic.starts_with(topics::FUSED_PREFIX) {
        return Some(Err("a fused output of an earlier re-fusion".into()));
    }
    if topic.starts_with(foxglove::TOPIC_PREFIX) {
        return Some(Err(
            "railfuse's Foxglove twin of a channel of its own, for Foxglove's panels".into(),
        ));
    }
    (topic == railfuse_catalog::foreign::frames::TF_STATIC).then(|| {
        Ok((
            None,
            "the sensors' frames: where each sits on the train".into(),
        ))
    })
}

/// The sensor a channel feeds and what it gives (`None` sensor: used as context), or why it
/// is left out.
fn sensor_of(
    c: &ChannelInfo,
    has_track: bool,
    reports: &GnssReports,
) -> std::result::Result<(Option<Sensor>, String), String> {
    if let Some(said) = by_topic(&c.topic) {
        return said;
    }
    let schema = c.schema_name();
    let (kind, role, named) = match c.kind() {
        Some(kind) => (kind, None, false),
        None => foreign_kind(c)?,
    };
    let sensor = |role, fields, variance, gate_nis, states| Sensor {
        role,
        fields,
        variance,
        gate_nis,
        states,
    };
    let from_name = if named {
        ", its role from the topic's name"
    } else {
        ""
    };
    Ok(match kind {
        MessageKind::GnssFix => return gnss(c, role, has_track, from_name, reports),
        MessageKind::Imu => (
            Some(sensor(
                role,
                Some("[\"acceleration\"]"),
                "0.01",
                Some(25.0),
                Some(IMU_BIAS),
            )),
            format!("{schema}: the IMU's acceleration along the track, and its bias"),
        ),
        MessageKind::RadarSpeed => (
            Some(sensor(role, None, "0.1", Some(16.0), Some(SPEED_SCALE))),
            format!("{schema}: a Doppler radar's speed{from_name}, and its scale factor"),
        ),
        MessageKind::Odometer => (
            Some(sensor(role, None, "0.1", Some(9.0), Some(SPEED_SCALE))),
            format!("{schema}: an odometer's speed{from_name}, and its scale factor"),
        ),
        MessageKind::LoopPosition => (
            Some(sensor(None, None, "\"message\"", None, Some(LOOP_SCALE))),
            format!("{schema}: the cross-induction loop's chainage, and its survey's scale"),
        ),
        MessageKind::BalisePassage => (
            Some(sensor(None, None, "\"message\"", Some(100.0), None)),
            format!("{schema}: balise passages' chainage"),
        ),
        MessageKind::TrackMap => (None, "the track map: GNSS fixes' chainage".into()),
        MessageKind::Vehicle => (
            None,
            "the vehicle: each sensor's lever arm and mounting".into(),
        ),
        MessageKind::Event => (None, "events: device faults and recoveries".into()),
        MessageKind::GroundTruth => {
            return Err("ground truth: the accuracy table's reference, not a sensor".into())
        }
        MessageKind::EddyCurrentBlock => {
            return Err(
                "eddy-current blocks need the eddy-current pipeline (see samples/seed004.toml)"
                    .into(),
            )
        }
        other => return Err(format!("{}: not a measurement", other.schema_name())),
    })
}

/// The GNSS topics whose fixes report their position's covariance (railfuse's own fixes, read
/// up to the first of each topic that has a position).
type GnssReports = std::collections::BTreeSet<String>;

fn gnss_reports(run: &Run, channels: &[Arc<ChannelInfo>]) -> Result<GnssReports> {
    let mut pending: std::collections::BTreeSet<&str> = channels
        .iter()
        .filter(|c| c.kind() == Some(MessageKind::GnssFix))
        .map(|c| c.topic.as_str())
        .collect();
    let mut reports = GnssReports::new();
    if pending.is_empty() {
        return Ok(reports);
    }
    let mut reader = run.reader()?;
    while let Some(record) = reader.next() {
        let LogRecord::Message(m) = record? else {
            continue;
        };
        let topic = m.channel.topic.as_str();
        if !pending.contains(topic) || !m.is::<GnssFix>() {
            continue;
        }
        let Ok(fix) = m.decode::<GnssFix>(&run.name()) else {
            continue;
        };
        if fix.latitude_deg.is_none() {
            continue;
        }
        if fix.position_covariance_enu_m2.is_some() {
            reports.insert(topic.to_owned());
        }
        pending.remove(topic);
        if pending.is_empty() {
            break;
        }
    }
    Ok(reports)
}

/// A GNSS channel's sensor: its speed (a receiver's velocity), its chainage on the track
/// (other tools' fixes carry a position only), or both; refused without a track to put a
/// position-only fix on.
fn gnss(
    c: &ChannelInfo,
    role: Option<Role>,
    has_track: bool,
    from_name: &str,
    reports: &GnssReports,
) -> std::result::Result<(Option<Sensor>, String), String> {
    let schema = c.schema_name();
    let sensor = |fields, variance, states| Sensor {
        role,
        fields,
        variance,
        gate_nis: Some(16.0),
        states,
    };
    Ok(match () {
        _ if role == Some(Role::Gnss) => (
            Some(sensor(Some("[\"speed\"]"), "0.04", None)),
            format!("{schema}: a GNSS receiver's velocity, its speed{from_name}"),
        ),
        // Other tools' fixes (NavSatFix, LocationFix) carry a position only.
        _ if has_track && c.kind().is_none() => (
            Some(sensor(Some("[\"chainage\"]"), "4.0", None)),
            format!("{schema}: GNSS fixes, their chainage on the track"),
        ),
        _ if has_track && reports.contains(&c.topic) => (
            Some(sensor(
                None,
                "{ chainage = \"message\", speed = 0.04 }",
                Some(GNSS_BIAS),
            )),
            format!(
                "{schema}: GNSS fixes, their chainage on the track (with the variance each \
                 reports, and a bias) and their speed"
            ),
        ),
        _ if has_track => (
            Some(sensor(None, "{ chainage = 4.0, speed = 0.04 }", None)),
            format!("{schema}: GNSS fixes, their chainage on the track and their speed"),
        ),
        _ if c.kind().is_some() => (
            Some(sensor(Some("[\"speed\"]"), "0.04", None)),
            format!(
                "{schema}: GNSS speed only; its positions give chainage only on a track map, \
             and the log has none (name one with --track line.geojson)"
            ),
        ),
        _ => {
            return Err(format!(
                "{schema}: GNSS positions give chainage only on a track map, and the log has \
             none: name one with --track line.geojson"
            ))
        }
    })
}

/// What a channel of another tool's schema decodes to, with the role it needs (taken from
/// the topic's name where the schema cannot tell) and whether the name gave it.
fn foreign_kind(c: &ChannelInfo) -> std::result::Result<(MessageKind, Option<Role>, bool), String> {
    let (schema, encoding) = (c.schema_name(), &c.message_encoding);
    let unread = || {
        format!(
            "{schema} ({encoding}): no sensor model reads it (railfuse reads {})",
            Translator::schemas().join(", ")
        )
    };
    match Translator::for_channel(c, None) {
        Ok(Some(t)) => Ok((t.kind, None, false)),
        Ok(None) => Err(unread()),
        Err(needs_role) => {
            let role = role_from_name(&c.topic).ok_or(needs_role)?;
            let t = Translator::for_channel(c, Some(role))?.ok_or_else(unread)?;
            Ok((t.kind, Some(role), true))
        }
    }
}

/// The role a topic's name says (`/radar`, `/wheel_odom`, `/gps/fix_velocity`), if it says
/// one.
fn role_from_name(topic: &str) -> Option<Role> {
    let t = topic.to_ascii_lowercase();
    let says = |words: &[&str]| words.iter().any(|w| t.contains(w));
    if says(&["radar", "doppler"]) {
        Some(Role::Radar)
    } else if says(&["odom", "wheel", "axle", "tacho"]) {
        Some(Role::Odometer)
    } else if says(&["gps", "gnss", "navsat", "fix"]) {
        Some(Role::Gnss)
    } else {
        None
    }
}

fn write_sensor(out: &mut String, topic: &str, s: &Sensor) {
    write!(
        out,
        "\n[[pipeline.sensor]]\ntopic = {}\n",
        toml_string(topic)
    )
    .unwrap();
    if let Some(role) = s.role {
        let name = serde_json::to_string(&role).expect("a role is a name");
        writeln!(out, "role = {name}").unwrap();
    }
    if let Some(fields) = s.fields {
        writeln!(out, "fields = {fields}").unwrap();
    }
    writeln!(out, "variance = {}", s.variance).unwrap();
    if let Some(g) = s.gate_nis {
        writeln!(out, "gate_nis = {g:?}").unwrap();
    }
    if let Some(states) = s.states {
        writeln!(out, "{states}").unwrap();
    }
}

/// A TOML basic string of `s`.
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_topics_name_gives_a_twist_its_role() {
        assert_eq!(role_from_name("/radar"), Some(Role::Radar));
        assert_eq!(role_from_name("/wheel_odom/twist"), Some(Role::Odometer));
        assert_eq!(role_from_name("/gps/fix_velocity"), Some(Role::Gnss));
        assert_eq!(role_from_name("/cmd_vel"), None);
    }
}
