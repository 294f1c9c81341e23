//! railfuse's calibration: the train's geometry found from runs over a mapped line. Today the
//! IMU's mounting angles, from what the IMU read against what the train did:
//!
//! - [`reference`]: each run replayed without the IMU through the configuration's first Kalman
//!   pipeline, RTS-smoothed;
//! - [`bins`]: one-second means of the IMU beside the specific force and rate that motion
//!   gives at the IMU's place on the track map;
//! - [`mounting`]: the filter that finds the angles and the IMU's biases, with σ, and which
//!   angles the runs could not see.

pub mod bins;
pub mod error;
pub mod mounting;
pub mod reference;

use railfuse_catalog::messages::{SensorMount, Vehicle};
use railfuse_catalog::run::Run;
use railfuse_refuse::spec::Pipelines;

pub use error::{Error, Result};
use mounting::{fit_mounting, MountingEstimate, MountingPriors, UNOBSERVABLE_SHARE};

/// What one run gave.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunUse {
    pub input: String,
    pub imu_messages: u64,
    pub bins: usize,
    pub left_out: usize,
}

/// The IMU's mounting found from runs.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub imu: String,
    /// The train as the configuration or the log's drawing gives it.
    pub drawing: Vehicle,
    pub estimate: MountingEstimate,
    pub runs: Vec<RunUse>,
}

impl Calibration {
    /// The drawing's IMU mount.
    pub fn drawn_mount(&self) -> SensorMount {
        self.drawing.mount_or_front(&self.imu)
    }

    /// Whether the runs saw each of roll, pitch and yaw.
    pub fn observable(&self) -> [bool; 3] {
        self.estimate.sigma_share.map(|s| s < UNOBSERVABLE_SHARE)
    }

    /// The drawing with the IMU's mounting replaced by the calibrated angles it could see (an
    /// angle the runs could not see keeps the drawing's value).
    pub fn vehicle(&self) -> Vehicle {
        let mut v = self.drawing.clone();
        let drawn = self.drawn_mount();
        let fitted = self.estimate.mounting_deg();
        let seen = self.observable();
        let mounting_deg = std::array::from_fn(|i| match seen[i] {
            true => fitted[i],
            false => drawn.mounting_deg[i],
        });
        let mount = SensorMount {
            mounting_deg,
            ..drawn
        };
        match v.sensors.iter_mut().find(|s| s.topic == self.imu) {
            Some(s) => *s = mount,
            None => v.sensors.push(mount),
        }
        v
    }
}

/// Finds the IMU's mounting from `runs`, each with the configuration it is replayed with
/// (`imu`: its topic, else the runs' one IMU channel).
pub fn calibrate(
    runs: &[(Run, Pipelines)],
    imu: Option<&str>,
    priors: &MountingPriors,
) -> Result<Calibration> {
    let mut all = Vec::new();
    let mut used = Vec::new();
    let mut drawing: Option<(Vehicle, SensorMount)> = None;
    let mut topic = None;
    for (k, (run, config)) in runs.iter().enumerate() {
        let imu = reference::imu_topic(run, imu.or(topic.as_deref()))?;
        let replay = reference::replay_without_imu(run, config, &imu)?;
        let got = bins::run_bins(&replay, config, k)?;
        if let Some((_, mount)) = &drawing {
            if *mount != got.mount {
                return Err(Error::Run {
                    input: replay.input,
                    message: format!(
                        "its drawing of {imu} ({:?} m, {:?}°) differs from the first run's \
                         ({:?} m, {:?}°): calibrate one installation at a time",
                        got.mount.lever_arm_m,
                        got.mount.mounting_deg,
                        mount.lever_arm_m,
                        mount.mounting_deg
                    ),
                });
            }
        }
        used.push(RunUse {
            input: replay.input.clone(),
            imu_messages: got.imu_messages,
            bins: got.bins.len(),
            left_out: got.left_out,
        });
        all.extend(got.bins);
        drawing.get_or_insert((got.vehicle, got.mount));
        topic = Some(imu);
    }
    let (vehicle, mount) = drawing.ok_or_else(|| Error::Config("no run to calibrate".into()))?;
    let imu = topic.unwrap_or_default();
    let estimate = fit_mounting(&all, mount.mounting(), priors).ok_or_else(|| Error::Run {
        input: used
            .iter()
            .map(|u| u.input.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        message: format!(
            "{} one-second bins of {imu} with a reference state: too few to calibrate from",
            all.len()
        ),
    })?;
    Ok(Calibration {
        imu,
        drawing: vehicle,
        estimate,
        runs: used,
    })
}
