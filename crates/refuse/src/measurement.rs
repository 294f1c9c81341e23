//! Sensor models: how a message of each channel kind becomes scalar measurements of the
//! along-track state `[s, v, a]` (or `[s, v]`) of the train's front end.
//!
//! | schema | measures | H |
//! |---|---|---|
//! | `railfuse.LoopPosition` | chainage (the loop antenna's, moved to the front end) | `[1, 0, 0]` |
//! | `railfuse.BalisePassage` | chainage (surveyed, at the passage of the balise antenna) | `[1, 0, 0]` |
//! | `railfuse.RadarSpeed` | speed (invalid samples rejected) | `[0, 1, 0]` |
//! | `railfuse.Odometer` | speed over its window | `[0, 1, 0]` |
//! | `railfuse.GnssFix` | chainage (the antenna's fix projected on the track map, moved to the front end), speed | `[1, 0, 0]`, `[0, 1, 0]` |
//! | `railfuse.Imu` | along-track acceleration (body x, gravity of the gradient removed) | `[0, 0, 1]` |
//!
//! Each sensor is where the vehicle ([`SensorContext::vehicle`]) puts it: a chainage measured
//! at a sensor `x` behind the front end is the front end's `x` further on (and a roof antenna
//! on a gradient leans back by its height times the gradient); wheels and a radar measure the
//! rail, `√(1 + G²)` longer than the chainage on a gradient `G`; an IMU's specific force is
//! turned by its mounting into the body, and the gradient's `g sin θ` at its place taken from
//! the track map (map-aided: the along-track filters have no attitude of their own). A point
//! train on a flat map is left as it was.
//!
//! A GNSS fix without a position (fix type `none`) gives no chainage; its variance along the
//! track is the receiver's east/north covariance projected on the track direction.

use std::path::Path;

use nalgebra::RowSVector;
use railfuse_catalog::log::LogMessage;
use railfuse_catalog::map_matching::nearest_on;
use railfuse_catalog::messages::{
    BalisePassage, FusedState, GnssFix, Imu, LoopPosition, MessageKind, Odometer, RadarSpeed,
    SensorMount, TrackMap, Vehicle,
};
use railfuse_catalog::track_profile::TrackPose;
use railfuse_catalog::vehicle::TrainPlace;
use railfuse_catalog::vehicle::GRAVITY_MPS2;

use crate::error::Result;

pub use railfuse_estimation::quantity::Quantity;

/// How a sensor's measurement of one quantity `q` sees the state: `z = H x + offset`. A bias
/// state adds to the row; a scale-factor state `k` makes it non-linear, `z = (1 + k) h_q x`
/// (`h_q` the quantity's own row: `q`'s unit entry, and `−W/2` at the acceleration for a
/// speed averaged over a window `W`), linearised at the estimate of the moment (an extended
/// Kalman row): `H = h + k̂ h_q` with `h_q x̂` at `k`, offset `−k̂ h_q x̂`.
#[derive(Debug, Clone, Copy)]
pub struct ObservationRow<const N: usize> {
    /// The row of the linear part (the quantity's own row and any bias state's entry).
    pub h: RowSVector<f64, N>,
    /// The quantity's own row, what a scale factor multiplies.
    pub scaled: RowSVector<f64, N>,
    /// The state holding this sensor's scale factor, if the pipeline estimates one.
    pub scale_state: Option<usize>,
}

impl<const N: usize> ObservationRow<N> {
    /// Whether the row depends on the estimate (and so needs a linearisation point).
    pub fn is_linearised(&self) -> bool {
        self.scale_state.is_some()
    }

    /// `H` and the offset at the linearisation point `x` (ignored for a linear row).
    pub fn at(&self, x: Option<&nalgebra::SVector<f64, N>>) -> (RowSVector<f64, N>, f64) {
        match (self.scale_state, x) {
            (Some(j), Some(x)) => {
                let (q, k) = ((self.scaled * x)[0], x[j]);
                let mut h = self.h + self.scaled * k;
                h[j] = q;
                (h, -q * k)
            }
            _ => (self.h, 0.0),
        }
    }
}

/// One scalar measurement taken from a message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub stamp_ns: u64,
    pub quantity: Quantity,
    pub value: f64,
    /// The variance the sensor reported with it, if any.
    pub reported_variance: Option<f64>,
    /// False when the sensor itself flags the sample as unusable.
    pub valid: bool,
}

/// What the sensor models need besides the message: the track map (GNSS fixes' chainage,
/// gradients), the vehicle (where each sensor sits) and where the train was last estimated.
#[derive(Debug, Clone)]
pub struct SensorContext {
    pub track: Option<TrackMap>,
    /// The train: each sensor's lever arm and mounting. A point train (every sensor at the
    /// front end, aligned) where nothing places them.
    pub vehicle: Vehicle,
    /// The front end as last estimated (the first pipeline's state): what the corrections
    /// that depend on where the train is (a gradient) are taken at. They change over tens of
    /// metres, so the estimate carried forward at its speed is close enough.
    pub whereabouts: Option<Whereabouts>,
}

impl Default for SensorContext {
    fn default() -> Self {
        SensorContext {
            track: None,
            vehicle: Vehicle::point(),
            whereabouts: None,
        }
    }
}

/// The front end's chainage and speed at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Whereabouts {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    pub speed_mps: f64,
}

impl SensorContext {
    /// The sensor on the message's topic, where the vehicle puts it.
    fn mount(&self, msg: &LogMessage<'_>) -> SensorMount {
        self.vehicle.mount_or_front(&msg.channel.topic)
    }

    /// The track's frame at `mount`'s place at `stamp_ns`, from the last estimate carried
    /// forward; None before the first estimate or without a map.
    fn pose_of(&self, mount: &SensorMount, stamp_ns: u64) -> Option<TrackPose> {
        let (map, w) = (self.track.as_ref()?, self.whereabouts?);
        let dt = railfuse_catalog::seconds_between(w.stamp_ns, stamp_ns).clamp(-5.0, 5.0);
        map.pose_at(mount.chainage(w.chainage_m + w.speed_mps * dt))
    }

    /// Where the train stands, for moving a measured position between its points: on `map`
    /// with the front end at `front_chainage_m` (the body leaning at `speed_mps`), else on a
    /// straight at `heading_rad`.
    pub fn place<'m>(
        &self,
        map: Option<&'m TrackMap>,
        front_chainage_m: Option<f64>,
        speed_mps: f64,
        heading_rad: f64,
    ) -> TrainPlace<'m> {
        match (map, front_chainage_m) {
            (Some(map), Some(front)) => TrainPlace::Map {
                map,
                front_chainage_m: front,
                body_roll_rad: self.vehicle.lean_on(map, front, speed_mps),
            },
            _ => TrainPlace::Straight { heading_rad },
        }
    }

    /// The front end's chainage when the sensor on `topic` measured its own place at (east,
    /// north): that point's nearest place on `map`'s main line, moved by the lever arm
    /// (searched over the whole line: for a start, not for every fix).
    pub fn front_chainage_of_measured(
        &self,
        map: &TrackMap,
        topic: &str,
        (east_m, north_m): (f64, f64),
    ) -> Option<f64> {
        let m = nearest_on(&map.vertices, 0..map.vertices.len(), east_m, north_m)?;
        Some(
            self.vehicle
                .mount_or_front(topic)
                .front_chainage(m.chainage_m),
        )
    }

    /// A position the sensor on `topic` measured (east, north) moved to the centre line's
    /// point `to_x_m` along the body (0: the front end), the train standing at `place`; as
    /// it is for a sensor the vehicle does not place at the front end.
    pub fn move_measured(
        &self,
        topic: &str,
        (east_m, north_m): (f64, f64),
        place: TrainPlace<'_>,
        to_x_m: f64,
    ) -> (f64, f64) {
        let mount = self.vehicle.mount_or_front(topic);
        if mount.lever_arm_m == [0.0; 3] && to_x_m == 0.0 {
            return (east_m, north_m);
        }
        let offset = mount.offset_from(place, to_x_m);
        (east_m - offset.x, north_m - offset.y)
    }

    /// A speed measured along the rail at `mount`'s place, as the chainage's rate.
    fn chainage_rate(&self, mount: &SensorMount, stamp_ns: u64, rail_speed: f64) -> f64 {
        self.pose_of(mount, stamp_ns)
            .map_or(rail_speed, |p| rail_speed / p.rail_per_chainage())
    }

    /// The IMU's acceleration along the track: its specific force turned into the body by its
    /// mounting, less the gradient's gravity at its place.
    fn along_track_acceleration(&self, mount: &SensorMount, m: &Imu) -> f64 {
        let body = mount.mounting() * nalgebra::Vector3::from(m.specific_force_mps2);
        let gravity = self
            .pose_of(mount, m.stamp_ns)
            .map_or(0.0, |p| GRAVITY_MPS2 * p.along_track_gravity());
        body.x - gravity
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorModel {
    LoopPosition,
    BalisePosition,
    RadarSpeed,
    OdometerSpeed,
    GnssFix,
    ImuAcceleration,
    /// Raw eddy-current blocks: whole messages for an `eddy_current` pipeline, no scalar.
    EddyCurrent,
    /// Another pipeline's fused states (an earlier `refuse`): its chainage and speed with
    /// their variances, a sensor like any other (an eddy-current pipeline's speed beside a
    /// radar's and the odometers').
    FusedState,
}

impl SensorModel {
    /// The message kinds a sensor model reads.
    pub const SUPPORTED: &'static [MessageKind] = &[
        MessageKind::LoopPosition,
        MessageKind::BalisePassage,
        MessageKind::RadarSpeed,
        MessageKind::Odometer,
        MessageKind::GnssFix,
        MessageKind::Imu,
        MessageKind::EddyCurrentBlock,
        MessageKind::FusedState,
    ];

    pub fn for_kind(kind: MessageKind) -> Option<Self> {
        Some(match kind {
            MessageKind::LoopPosition => SensorModel::LoopPosition,
            MessageKind::BalisePassage => SensorModel::BalisePosition,
            MessageKind::RadarSpeed => SensorModel::RadarSpeed,
            MessageKind::Odometer => SensorModel::OdometerSpeed,
            MessageKind::GnssFix => SensorModel::GnssFix,
            MessageKind::Imu => SensorModel::ImuAcceleration,
            MessageKind::EddyCurrentBlock => SensorModel::EddyCurrent,
            MessageKind::FusedState => SensorModel::FusedState,
            _ => return None,
        })
    }

    pub fn for_schema(schema: &str) -> Option<Self> {
        Self::for_kind(MessageKind::from_schema(schema)?)
    }

    /// Gate rejections in a row of its chainage after which a pipeline resets its position to
    /// it (config `reset_after`): an absolute fix must win over a filter that went wrong. 0
    /// for what is not an absolute fix.
    pub fn default_reset_after(self) -> u32 {
        match self {
            SensorModel::BalisePosition => 1,
            SensorModel::LoopPosition => 3,
            SensorModel::GnssFix => 10,
            _ => 0,
        }
    }

    /// The quantities this model can give.
    pub fn quantities(self) -> &'static [Quantity] {
        match self {
            SensorModel::LoopPosition | SensorModel::BalisePosition => &[Quantity::Chainage],
            SensorModel::RadarSpeed | SensorModel::OdometerSpeed => &[Quantity::Speed],
            SensorModel::GnssFix => &[Quantity::Chainage, Quantity::Speed],
            SensorModel::ImuAcceleration => &[Quantity::Acceleration],
            SensorModel::EddyCurrent => &[],
            SensorModel::FusedState => &[Quantity::Chainage, Quantity::Speed],
        }
    }

    /// Decodes a message into its measurements (at most one per quantity), in `quantities()`
    /// order.
    pub fn decode(
        self,
        msg: &LogMessage<'_>,
        path: &Path,
        ctx: &SensorContext,
        out: &mut Vec<Measurement>,
    ) -> Result<()> {
        out.clear();
        match self {
            SensorModel::LoopPosition => {
                let m: LoopPosition = msg.decode(path)?;
                out.push(one(
                    m.stamp_ns,
                    Quantity::Chainage,
                    ctx.mount(msg).front_chainage(m.chainage_m),
                    m.variance_m2,
                    true,
                ));
            }
            SensorModel::BalisePosition => {
                let m: BalisePassage = msg.decode(path)?;
                out.push(one(
                    m.stamp_ns,
                    Quantity::Chainage,
                    ctx.mount(msg).front_chainage(m.chainage_m),
                    m.variance_m2,
                    true,
                ));
            }
            SensorModel::RadarSpeed => {
                let m: RadarSpeed = msg.decode(path)?;
                let speed = ctx.chainage_rate(&ctx.mount(msg), m.stamp_ns, m.speed_mps);
                out.push(one(
                    m.stamp_ns,
                    Quantity::Speed,
                    speed,
                    m.speed_variance_m2ps2,
                    m.valid,
                ));
            }
            SensorModel::OdometerSpeed => {
                let m: Odometer = msg.decode(path)?;
                let speed = ctx.chainage_rate(&ctx.mount(msg), m.stamp_ns, m.speed_mps);
                out.push(one(m.stamp_ns, Quantity::Speed, speed, None, true));
            }
            SensorModel::ImuAcceleration => {
                let m: Imu = msg.decode(path)?;
                out.push(one(
                    m.stamp_ns,
                    Quantity::Acceleration,
                    ctx.along_track_acceleration(&ctx.mount(msg), &m),
                    None,
                    true,
                ));
            }
            // Read whole by its pipeline; nothing scalar in a block.
            SensorModel::EddyCurrent => {}
            SensorModel::FusedState => fused_state(msg, path, out)?,
            SensorModel::GnssFix => gnss(msg, path, ctx, out)?,
        }
        Ok(())
    }
}

fn one(
    stamp_ns: u64,
    quantity: Quantity,
    value: f64,
    reported_variance: Option<f64>,
    valid: bool,
) -> Measurement {
    Measurement {
        stamp_ns,
        quantity,
        value,
        reported_variance,
        valid,
    }
}

/// Another pipeline's state (or smoothed state) as chainage and speed measurements.
fn fused_state(msg: &LogMessage<'_>, path: &Path, out: &mut Vec<Measurement>) -> Result<()> {
    let m: FusedState = msg.decode(path)?;
    let var = |v: f64| (v.is_finite() && v > 0.0).then_some(v);
    out.push(one(
        m.stamp_ns,
        Quantity::Chainage,
        m.chainage_m,
        var(m.covariance[0]),
        m.chainage_m.is_finite(),
    ));
    out.push(one(
        m.stamp_ns,
        Quantity::Speed,
        m.speed_mps,
        var(m.covariance[4]),
        m.speed_mps.is_finite(),
    ));
    Ok(())
}

/// A GNSS fix as chainage on the track and speed signed by its course against the track.
fn gnss(
    msg: &LogMessage<'_>,
    path: &Path,
    ctx: &SensorContext,
    out: &mut Vec<Measurement>,
) -> Result<()> {
    let m: GnssFix = msg.decode(path)?;
    let along = ctx.track.as_ref().and_then(|t| t.chainage_of_fix(&m));
    let (chainage, variance, heading) = along.unwrap_or((f64::NAN, None, None));
    // The antenna's place on the map, moved to the front end.
    let chainage = match &ctx.track {
        Some(map) if along.is_some() => ctx.mount(msg).front_chainage_of_point(map, chainage),
        _ => chainage,
    };
    out.push(one(
        m.stamp_ns,
        Quantity::Chainage,
        chainage,
        variance,
        along.is_some(),
    ));
    // Speed over ground is a magnitude: signed by the course against the track.
    let sign = match (m.course_rad, heading) {
        (Some(c), Some(h)) if (c - h).cos() < 0.0 => -1.0,
        _ => 1.0,
    };
    let speed = m.speed_mps.map(|v| sign * v);
    out.push(one(
        m.stamp_ns,
        Quantity::Speed,
        speed.unwrap_or(f64::NAN),
        None,
        m.fix_type.has_position() && speed.is_some(),
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{RowSVector, SVector};

    /// A scale factor multiplies the quantity's own row, whatever it is: a loop's chainage
    /// scale on `s`, an odometer's on its window-averaged speed `v − a W/2`; a bias entry is
    /// left as it is. The linearised row reproduces `z = (1 + k) h_q x + b` at the estimate.
    #[test]
    fn a_scale_factor_scales_the_quantitys_own_row_chainage_or_windowed_speed() {
        // x = [s, v, a, b, k]: a loop with a chainage bias (3) and a chainage scale (4).
        let x = SVector::<f64, 5>::from([60_000.0, 30.0, 0.5, 0.2, 2e-5]);
        let scaled = RowSVector::<f64, 5>::from([1.0, 0.0, 0.0, 0.0, 0.0]);
        let mut h = scaled;
        h[3] = 1.0;
        let row = ObservationRow {
            h,
            scaled,
            scale_state: Some(4),
        };
        let (hl, offset) = row.at(Some(&x));
        assert_eq!(hl[0], 1.0 + 2e-5);
        assert_eq!(hl[3], 1.0);
        assert_eq!(hl[4], 60_000.0);
        let z = (1.0 + x[4]) * x[0] + x[3];
        assert!(((hl * x)[0] + offset - z).abs() < 1e-9);

        // An odometer averaging over 0.2 s, with its scale factor in state 3.
        let x = SVector::<f64, 4>::from([0.0, 20.0, -1.0, 0.004]);
        let scaled = RowSVector::<f64, 4>::from([0.0, 1.0, -0.1, 0.0]);
        let row = ObservationRow {
            h: scaled,
            scaled,
            scale_state: Some(3),
        };
        let (hl, offset) = row.at(Some(&x));
        let z = (1.0 + x[3]) * (x[1] - 0.1 * x[2]);
        assert!(((hl * x)[0] + offset - z).abs() < 1e-12);
        assert!((hl[2] + 0.1 * 1.004).abs() < 1e-15);
        assert_eq!(hl[3], 20.1);
    }
}
