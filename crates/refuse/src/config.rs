//! The pipeline configuration file (TOML). One file declares any number of named pipelines;
//! one replay runs them all.
//!
//! ```toml
//! [[pipeline]]
//! name = "kalman"
//! filter = "kalman"
//! motion = { model = "constant_acceleration", jerk_psd = 0.05 }
//!
//! [[pipeline.sensor]]
//! topic = "/loop/position"
//! variance = "message"      # the variance each message reports, or a number in SI units²
//! gate_nis = 25.0           # optional innovation gate
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::{ConstantAcceleration, ProcessNoise};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelinesConfig {
    pub pipeline: Vec<PipelineConfig>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterKind {
    Kalman,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineConfig {
    /// Names the output channels `/fused/<name>/…`: letters, digits, `_` and `-`.
    pub name: String,
    pub filter: FilterKind,
    pub motion: MotionConfig,
    #[serde(default)]
    pub initial: InitialConfig,
    /// Measurements are released to the filter in sensor-time order once the replay is this
    /// far past them, so sensors with different latencies are fused in the right order.
    #[serde(default = "default_reorder_window_s")]
    pub reorder_window_s: f64,
    pub sensor: Vec<SensorConfig>,
}

fn default_reorder_window_s() -> f64 {
    0.5
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionModelKind {
    ConstantAcceleration,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionConfig {
    pub model: MotionModelKind,
    /// Power spectral density of a continuous white jerk, m²/s⁵.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jerk_psd: Option<f64>,
    /// Variance of a jerk held constant over each step (sources 000/001), m²/s⁶.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jerk_variance: Option<f64>,
}

/// The filter starts at its first position measurement: chainage from it; speed from the
/// latest valid speed measurement before it (else `speed_mps`, `speed_std_mps`); acceleration
/// zero with `acceleration_std_mps2`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialConfig {
    pub speed_mps: f64,
    pub speed_std_mps: f64,
    pub acceleration_std_mps2: f64,
}

impl Default for InitialConfig {
    fn default() -> Self {
        Self { speed_mps: 0.0, speed_std_mps: 5.0, acceleration_std_mps2: 1.0 }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged, expecting = "a variance (a number, SI units squared) or \"message\"")]
pub enum Variance {
    Fixed(f64),
    FromMessage(FromMessage),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FromMessage {
    Message,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    pub topic: String,
    pub variance: Variance,
    /// Reject a measurement whose normalised innovation squared exceeds this (χ², 1 dof:
    /// 6.63 keeps 99 %, 10.83 keeps 99.9 %).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gate_nis: Option<f64>,
}

impl PipelinesConfig {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::ConfigRead { path: path.to_owned(), source })?;
        Self::parse(&text, path)
    }

    /// Parses and validates configuration text; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let config: PipelinesConfig = toml::from_str(text).map_err(|e| Error::ConfigSyntax {
            path: path.to_owned(),
            message: match e.span() {
                Some(span) => {
                    let (line, column) = line_column(text, span.start);
                    format!("line {line}, column {column}: {}", e.message())
                }
                None => e.message().to_owned(),
            },
        })?;
        config.validate(path)?;
        Ok(config)
    }

    fn validate(&self, path: &Path) -> Result<()> {
        let invalid = |p: &PipelineConfig, message: String| Error::ConfigInvalid { path: path.to_owned(), pipeline: p.name.clone(), message };
        if self.pipeline.is_empty() {
            return Err(Error::ConfigSyntax { path: path.to_owned(), message: "no [[pipeline]] declared".into() });
        }
        for (i, p) in self.pipeline.iter().enumerate() {
            if p.name.is_empty() || !p.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
                return Err(invalid(p, "the name may hold only letters, digits, '_' and '-'".into()));
            }
            if self.pipeline[..i].iter().any(|q| q.name == p.name) {
                return Err(invalid(p, "declared twice".into()));
            }
            p.process_noise().map_err(|m| invalid(p, m))?;
            if !(p.reorder_window_s.is_finite() && p.reorder_window_s >= 0.0) {
                return Err(invalid(p, format!("reorder_window_s must be ≥ 0, not {}", p.reorder_window_s)));
            }
            let init = &p.initial;
            if !(init.speed_std_mps > 0.0 && init.acceleration_std_mps2 > 0.0 && init.speed_mps.is_finite()) {
                return Err(invalid(p, "initial standard deviations must be positive".into()));
            }
            if p.sensor.is_empty() {
                return Err(invalid(p, "no [[pipeline.sensor]]: nothing to fuse".into()));
            }
            for s in &p.sensor {
                if let Variance::Fixed(v) = s.variance {
                    if !(v.is_finite() && v > 0.0) {
                        return Err(invalid(p, format!("sensor {}: variance must be positive, not {v}", s.topic)));
                    }
                }
                if let Some(g) = s.gate_nis {
                    if !(g.is_finite() && g > 0.0) {
                        return Err(invalid(p, format!("sensor {}: gate_nis must be positive, not {g}", s.topic)));
                    }
                }
            }
        }
        Ok(())
    }
}

impl PipelineConfig {
    pub fn process_noise(&self) -> Result<ProcessNoise, String> {
        let positive = |what: &str, v: f64| {
            if v.is_finite() && v > 0.0 { Ok(v) } else { Err(format!("motion.{what} must be positive, not {v}")) }
        };
        match (self.motion.jerk_psd, self.motion.jerk_variance) {
            (Some(q), None) => Ok(ProcessNoise::WhiteJerkPsd(positive("jerk_psd", q)?)),
            (None, Some(v)) => Ok(ProcessNoise::PiecewiseJerkVariance(positive("jerk_variance", v)?)),
            _ => Err("motion needs exactly one of jerk_psd or jerk_variance".into()),
        }
    }

    pub fn motion_model(&self) -> ConstantAcceleration {
        ConstantAcceleration { noise: self.process_noise().expect("validated on load") }
    }

    /// This pipeline alone, as TOML: what is stored beside its fused channels.
    pub fn to_toml(&self) -> String {
        toml::to_string(&PipelinesConfig { pipeline: vec![self.clone()] }).expect("a config serialises")
    }
}

fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// A config file path for messages when the text did not come from a file.
pub fn embedded_path(name: &str) -> PathBuf {
    PathBuf::from(format!("<embedded {name}>"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
motion = { model = "constant_acceleration", jerk_psd = 0.05 }

[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"

[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.01
gate_nis = 16.0
"#;

    fn err(text: &str) -> String {
        PipelinesConfig::parse(text, Path::new("p.toml")).unwrap_err().to_string()
    }

    #[test]
    fn a_good_config_parses_and_round_trips() {
        let c = PipelinesConfig::parse(GOOD, Path::new("p.toml")).unwrap();
        assert_eq!(c.pipeline[0].sensor[0].variance, Variance::FromMessage(FromMessage::Message));
        assert_eq!(c.pipeline[0].sensor[1].variance, Variance::Fixed(0.01));
        let again = PipelinesConfig::parse(&c.pipeline[0].to_toml(), Path::new("x")).unwrap();
        assert_eq!(again.pipeline[0], c.pipeline[0]);
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line_and_column() {
        let e = err(&GOOD.replace("gate_nis = 16.0", "gate_nsi = 16.0"));
        assert!(e.starts_with("p.toml: line 14, column 1: unknown field `gate_nsi`"), "{e}");
    }

    #[test]
    fn a_wrong_type_is_named_with_its_line() {
        let e = err(&GOOD.replace("variance = 0.01", "variance = [1]"));
        assert!(e.contains("line 13, column 12") && e.contains("a variance"), "{e}");
    }

    #[test]
    fn invalid_values_are_refused_with_the_pipeline_name() {
        assert!(err(&GOOD.replace("variance = 0.01", "variance = -1.0")).contains("pipeline 'kf': sensor /radar/speed: variance must be positive"));
        assert!(err(&GOOD.replace("jerk_psd = 0.05", "jerk_psd = 0.05, jerk_variance = 1.0")).contains("exactly one"));
        assert!(err(&GOOD.replace("filter = \"kalman\"", "filter = \"magic\"")).contains("unknown variant `magic`"));
        assert!(err(&GOOD.replace("name = \"kf\"", "name = \"a/b\"")).contains("letters, digits"));
    }
}
