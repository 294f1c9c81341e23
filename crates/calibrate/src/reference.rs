//! What the train did, without the IMU: the run replayed through the configuration's first
//! Kalman pipeline with the IMU taken out and the RTS smoother on. The mounting is then fitted
//! against motion the IMU had no part in (an IMU whose mounting is wrong would otherwise bend
//! the reference towards itself).

use std::path::PathBuf;

use railfuse_catalog::messages::MessageKind;
use railfuse_catalog::run::Run;
use railfuse_eval::Reference;
use railfuse_refuse::replay::{refuse, RefuseOptions};
use railfuse_refuse::spec::{EstimatorSpec, Pipelines};

use crate::error::{Error, Result};

/// The reference pipeline's name in the replay's output.
pub const REFERENCE_PIPELINE: &str = "mounting_reference";

/// A run replayed for calibration: its fused log (every input record, the reference's
/// smoothed states) in a temporary directory removed with it.
pub struct ReferenceReplay {
    _dir: tempfile::TempDir,
    pub fused: PathBuf,
    /// The run, as messages name it.
    pub input: String,
    /// The IMU's topic.
    pub imu: String,
}

/// The IMU the calibration is for: `asked`, else the run's one IMU channel.
pub fn imu_topic(run: &Run, asked: Option<&str>) -> Result<String> {
    let channels = railfuse_refuse::default_config::channels(run)?;
    let imus: Vec<&str> = channels
        .iter()
        .filter(|c| c.kind() == Some(MessageKind::Imu))
        .map(|c| c.topic.as_str())
        .collect();
    let fail = |message: String| Error::Run {
        input: run.display(),
        message,
    };
    match (asked, imus.as_slice()) {
        (Some(topic), _) if imus.contains(&topic) => Ok(topic.to_owned()),
        (Some(topic), []) => Err(fail(format!("has no IMU channel (asked for {topic})"))),
        (Some(topic), found) => Err(fail(format!(
            "has no IMU channel {topic} (its IMU channels: {})",
            found.join(", ")
        ))),
        (None, [one]) => Ok((*one).to_owned()),
        (None, []) => Err(fail("has no IMU channel to calibrate".into())),
        (None, several) => Err(fail(format!(
            "has several IMU channels ({}): name one with --imu",
            several.join(", ")
        ))),
    }
}

/// The configuration's first Kalman pipeline without `imu`, smoothed.
fn reference_config(config: &Pipelines, imu: &str) -> Result<Pipelines> {
    let Some(first) = config
        .pipeline
        .iter()
        .find(|p| matches!(p.estimator, EstimatorSpec::Kalman { .. }))
    else {
        return Err(Error::Config(format!(
            "{}: no Kalman pipeline to replay the run through without the IMU",
            config.path.display()
        )));
    };
    let mut reference = first.clone();
    reference.name = REFERENCE_PIPELINE.to_owned();
    reference.sensors.retain(|s| s.topic != imu);
    reference.withhold = None;
    if reference.sensors.is_empty() {
        return Err(Error::Config(format!(
            "{}: pipeline '{}' reads nothing but the IMU: the train's motion must come from \
             other sensors (GNSS, radar, odometers, balises)",
            config.path.display(),
            first.name
        )));
    }
    if let EstimatorSpec::Kalman { smoother, .. } = &mut reference.estimator {
        *smoother = true;
    }
    Ok(Pipelines {
        pipeline: vec![reference],
        ..config.clone()
    })
}

/// Replays `run` through `config`'s reference pipeline without `imu`.
pub fn replay_without_imu(run: &Run, config: &Pipelines, imu: &str) -> Result<ReferenceReplay> {
    let reference_config = reference_config(config, imu)?;
    let dir = tempfile::tempdir().map_err(|source| Error::Io {
        path: std::env::temp_dir(),
        source,
    })?;
    let fused = dir.path().join("reference.mcap");
    let no_scoring = Reference::topic(railfuse_catalog::topics::GROUND_TRUTH);
    refuse(&RefuseOptions {
        run,
        output: &fused,
        config: &reference_config,
        config_source: format!("{} (IMU calibration reference)", config.path.display()),
        reference: &no_scoring,
        withhold: None,
        progress: None,
        observer: None,
    })?;
    Ok(ReferenceReplay {
        _dir: dir,
        fused,
        input: run.display(),
        imu: imu.to_owned(),
    })
}
