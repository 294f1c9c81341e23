//! The values tuning may change: a parameter is the path of a number in one pipeline's table
//! of the configuration file, with its bounds. Candidates are written into the file's own text
//! (a [`toml_edit`] document), so the tuned file keeps its layout and comments and only the
//! tuned numbers change, and every candidate is validated exactly as `refuse` validates a file.
//!
//! Paths: keys joined by `.`, and `[TOPIC]` after `sensor` to pick a sensor by its topic:
//! `motion.jerk_psd`, `sensor[/radar/speed].variance`, `sensor[/gnss].variance.chainage`,
//! `sensor[/odometer/1].gate_nis`, `sensor[/gnss].chainage_bias.time_constant_s`,
//! `federated.detector.timeout_s`.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Serialize;
use toml_edit::{DocumentMut, Item, TableLike, Value};

use crate::error::{Error, Result};
use railfuse_refuse::config::{ParamBounds, Scale};
use railfuse_refuse::spec::{PipelineSpec, Pipelines};

#[derive(Debug, Clone, PartialEq, Eq)]
enum Segment {
    Key(String),
    /// `[topic]`: the element of an array of tables whose `topic` is this.
    Select(String),
}

/// The path of a number in a pipeline's table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamPath {
    text: String,
    segments: Vec<Segment>,
}

impl fmt::Display for ParamPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

impl std::str::FromStr for ParamPath {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let bad = |why: &str| format!("parameter '{text}': {why}");
        let mut segments = Vec::new();
        let mut rest = text;
        loop {
            let end = rest.find(['.', '[']).unwrap_or(rest.len());
            let key = &rest[..end];
            if key.is_empty() {
                return Err(bad("an empty key"));
            }
            segments.push(Segment::Key(key.to_owned()));
            rest = &rest[end..];
            if let Some(inner) = rest.strip_prefix('[') {
                let close = inner.find(']').ok_or_else(|| bad("'[' without ']'"))?;
                if close == 0 {
                    return Err(bad("an empty [topic]"));
                }
                segments.push(Segment::Select(inner[..close].to_owned()));
                rest = &inner[close + 1..];
            }
            match rest.strip_prefix('.') {
                Some(r) => rest = r,
                None if rest.is_empty() => break,
                None => return Err(bad("expected '.' after ']'")),
            }
        }
        if matches!(segments.last(), Some(Segment::Select(_))) {
            return Err(bad("ends at a [topic], not at a number"));
        }
        Ok(Self {
            text: text.to_owned(),
            segments,
        })
    }
}

/// One tuned value: where it is, its bounds and the value it starts from (the file's).
#[derive(Debug, Clone, Serialize)]
pub struct Param {
    #[serde(serialize_with = "serialize_display")]
    pub path: ParamPath,
    pub min: f64,
    pub max: f64,
    pub scale: ScaleName,
    pub start: f64,
    /// Grid search: points along it.
    pub steps: usize,
    /// The file writes it as an integer: candidates are rounded.
    pub integer: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleName {
    Linear,
    Log,
}

fn serialize_display<S: serde::Serializer>(
    p: &ParamPath,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.collect_str(p)
}

/// Grid points along a parameter when its bounds do not say.
pub const DEFAULT_GRID_STEPS: usize = 5;

impl Param {
    /// Where `v` sits between the bounds, 0 … 1 (on the log scale for log parameters).
    pub fn to_unit(&self, v: f64) -> f64 {
        match self.scale {
            ScaleName::Linear => (v - self.min) / (self.max - self.min),
            ScaleName::Log => (v / self.min).ln() / (self.max / self.min).ln(),
        }
    }

    /// The value at `u` (clamped to 0 … 1), rounded as the file will hold it.
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = if u.is_nan() { 0.5 } else { u.clamp(0.0, 1.0) };
        let v = match self.scale {
            ScaleName::Linear => self.min + u * (self.max - self.min),
            ScaleName::Log => self.min * (self.max / self.min).powf(u),
        };
        self.round(v.clamp(self.min, self.max))
    }

    /// As written to the file: six significant digits (integers for integer values).
    pub fn round(&self, v: f64) -> f64 {
        if self.integer {
            return v.round();
        }
        format!("{v:.5e}").parse().unwrap_or(v)
    }

    /// The values a grid search takes along this parameter.
    pub fn grid(&self) -> Vec<f64> {
        (0..self.steps)
            .map(|i| self.from_unit(i as f64 / (self.steps - 1) as f64))
            .collect()
    }

    /// Whether `v` sits on a bound (within 0.1 % of the range): a sign the bound, not the
    /// data, chose it.
    pub fn on_bound(&self, v: f64) -> bool {
        let u = self.to_unit(v);
        u <= 1e-3 || u >= 1.0 - 1e-3
    }
}

/// A configuration file opened for tuning one of its pipelines.
#[derive(Debug, Clone)]
pub struct TunableConfig {
    pub path: PathBuf,
    doc: DocumentMut,
    pub pipeline: String,
}

impl TunableConfig {
    /// Opens configuration text (already validated by [`Pipelines::parse`]) at `pipeline`.
    pub fn new(text: &str, path: &Path, pipeline: &str) -> Result<Self> {
        let doc: DocumentMut = text.parse().map_err(|e: toml_edit::TomlError| {
            railfuse_refuse::Error::ConfigSyntax {
                path: path.to_owned(),
                message: e.message().to_owned(),
            }
        })?;
        let mut c = Self {
            path: path.to_owned(),
            doc,
            pipeline: pipeline.to_owned(),
        };
        c.table_mut()?;
        Ok(c)
    }

    fn fail(&self, message: String) -> Error {
        Error::Request {
            path: self.path.clone(),
            pipeline: self.pipeline.clone(),
            message,
        }
    }

    fn table_mut(&mut self) -> Result<&mut toml_edit::Table> {
        let name = self.pipeline.clone();
        let path = self.path.clone();
        let found = self
            .doc
            .get_mut("pipeline")
            .and_then(Item::as_array_of_tables_mut)
            .and_then(|a| {
                a.iter_mut()
                    .find(|t| t.get("name").and_then(Item::as_str) == Some(name.as_str()))
            });
        found.ok_or_else(|| Error::Request {
            path,
            pipeline: name,
            message: "no [[pipeline]] of that name".into(),
        })
    }

    /// The parameter at `path` with `bounds`, starting from the file's value.
    pub fn param(&mut self, path: &ParamPath, bounds: &ParamBounds) -> Result<Param> {
        let (start, integer) =
            number(self.value_mut(path)?).map_err(|why| self.fail(format!("{path} {why}")))?;
        let ParamBounds {
            min,
            max,
            scale,
            steps,
        } = *bounds;
        let bad = |why: String| self.fail(format!("{path}: {why}"));
        if !(min.is_finite() && max.is_finite() && min < max) {
            return Err(bad(format!("bounds {min} … {max} are not an interval")));
        }
        if !(min..=max).contains(&start) {
            return Err(bad(format!(
                "bounds {min} … {max} do not contain the file's value {start}"
            )));
        }
        let scale = match scale {
            Some(Scale::Linear) => ScaleName::Linear,
            Some(Scale::Log) if min > 0.0 => ScaleName::Log,
            Some(Scale::Log) => return Err(bad("a log scale needs bounds above 0".into())),
            None if min > 0.0 => ScaleName::Log,
            None => ScaleName::Linear,
        };
        let steps = steps.unwrap_or(DEFAULT_GRID_STEPS);
        if steps < 2 {
            return Err(bad("a grid needs at least 2 steps".into()));
        }
        Ok(Param {
            path: path.clone(),
            min,
            max,
            scale,
            start,
            steps,
            integer,
        })
    }

    /// The file's number at `path`, if it holds one there.
    pub fn number_at(&mut self, path: &ParamPath) -> Option<f64> {
        self.value_mut(path)
            .ok()
            .and_then(|v| number(v).ok())
            .map(|(x, _)| x)
    }

    /// What a tune without parameters tunes: the process noise and every sensor variance the
    /// file gives as a number (not "message"), each over two decades either side of its
    /// value, on a log scale. `topics` are the pipeline's sensors.
    pub fn noise_values(&mut self, topics: &[&str]) -> Vec<(String, ParamBounds)> {
        let motion = [
            "motion.jerk_psd",
            "motion.jerk_variance",
            "motion.acceleration_psd",
            "motion.acceleration_std_mps2",
        ]
        .map(str::to_owned);
        let sensors = topics.iter().flat_map(|t| {
            ["", ".chainage", ".speed", ".acceleration"]
                .map(|field| format!("sensor[{t}].variance{field}"))
        });
        let mut out = Vec::new();
        for name in motion.into_iter().chain(sensors) {
            let Ok(path) = name.parse::<ParamPath>() else {
                continue;
            };
            if let Some(v) = self.number_at(&path).filter(|v| v.is_finite() && *v > 0.0) {
                let bounds = ParamBounds {
                    min: v / 100.0,
                    max: v * 100.0,
                    scale: Some(railfuse_refuse::config::Scale::Log),
                    steps: None,
                };
                out.push((name, bounds));
            }
        }
        out
    }

    fn value_mut(&mut self, path: &ParamPath) -> Result<&mut Value> {
        let (file, pipeline) = (self.path.clone(), self.pipeline.clone());
        leaf(self.table_mut()?, &path.segments).map_err(|why| Error::Request {
            path: file,
            pipeline,
            message: format!("{path}: {why}"),
        })
    }

    /// Writes `values` (one per parameter) into the document, keeping each number's comments.
    pub fn set(&mut self, params: &[Param], values: &[f64]) -> Result<()> {
        for (p, &v) in params.iter().zip(values) {
            let slot = self.value_mut(&p.path)?;
            let decor = slot.decor().clone();
            *slot = match p.integer {
                true => Value::from(v.round() as i64),
                false => Value::from(v),
            };
            *slot.decor_mut() = decor;
        }
        Ok(())
    }

    /// The file's text as it stands.
    pub fn text(&self) -> String {
        self.doc.to_string()
    }

    /// The pipeline with `values` written in, validated as `refuse` validates a file.
    pub fn spec_with(&self, params: &[Param], values: &[f64]) -> Result<PipelineSpec> {
        let mut c = self.clone();
        c.set(params, values)?;
        let pipelines = Pipelines::parse(&c.text(), &self.path)?;
        let spec = pipelines
            .pipeline
            .into_iter()
            .find(|p| p.name == self.pipeline)
            .ok_or_else(|| self.fail("no [[pipeline]] of that name".into()))?;
        Ok(spec)
    }
}

/// The number a value holds, and whether it is written as an integer.
fn number(v: &Value) -> std::result::Result<(f64, bool), String> {
    match v {
        Value::Float(f) => Ok((*f.value(), false)),
        Value::Integer(i) => Ok((*i.value() as f64, true)),
        Value::String(s) if s.value() == "message" => Err(
            "is \"message\" (each message's own variance), not a number: write a number to \
             tune it"
                .into(),
        ),
        other => Err(format!("is a {}, not a number", other.type_name())),
    }
}

/// Numbers a table may leave out, and the value their absence means.
const OPTIONAL_NUMBERS: &[(&str, f64)] = &[("time_offset_s", 0.0)];

/// The value at `segments` below `table`.
fn leaf<'a>(
    table: &'a mut dyn TableLike,
    segments: &[Segment],
) -> std::result::Result<&'a mut Value, String> {
    let Some((Segment::Key(key), rest)) = segments.split_first() else {
        return Err("is not a path of keys".into());
    };
    let keys: Vec<String> = table.iter().map(|(k, _)| k.to_owned()).collect();
    // A number whose absence means a known value is written in at that value first (a
    // sensor's latency: none given, none assumed).
    if rest.is_empty() && table.get(key).is_none() {
        if let Some(&(_, value)) = OPTIONAL_NUMBERS.iter().find(|(k, _)| k == key) {
            table.insert(key, toml_edit::value(value));
        }
    }
    let Some(item) = table.get_mut(key) else {
        return Err(format!(
            "not found: there is no '{key}' here (there is {})",
            match keys.is_empty() {
                true => "nothing".to_owned(),
                false => keys.join(", "),
            }
        ));
    };
    match rest.split_first() {
        None => item
            .as_value_mut()
            .ok_or_else(|| format!("'{key}' is a table, not a number")),
        Some((Segment::Select(topic), rest)) => {
            let element: Option<&mut dyn TableLike> = match item {
                Item::ArrayOfTables(a) => a
                    .iter_mut()
                    .find(|t| t.get("topic").and_then(Item::as_str) == Some(topic))
                    .map(|t| t as &mut dyn TableLike),
                Item::Value(Value::Array(a)) => a
                    .iter_mut()
                    .filter_map(Value::as_inline_table_mut)
                    .find(|t| t.get("topic").and_then(Value::as_str) == Some(topic))
                    .map(|t| t as &mut dyn TableLike),
                _ => return Err(format!("'{key}' is not a list of tables with topics")),
            };
            let element = element.ok_or_else(|| format!("no {key} has topic {topic}"))?;
            leaf(element, rest)
        }
        Some((Segment::Key(_), _)) => {
            let inner = item
                .as_table_like_mut()
                .ok_or_else(|| format!("'{key}' is a value, not a table"))?;
            leaf(inner, rest)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"
[[pipeline]]
name = "kf"
filter = "kalman"
# the motion
motion = { model = "constant_acceleration", jerk_psd = 0.2 } # white jerk

[[pipeline.sensor]]
topic = "/loop/position"
variance = "message"

[[pipeline.sensor]]
topic = "/radar/speed"
variance = 0.1   # radar
gate_nis = 16
"#;

    fn open() -> TunableConfig {
        TunableConfig::new(TEXT, Path::new("p.toml"), "kf").unwrap()
    }

    fn bounds(min: f64, max: f64) -> ParamBounds {
        ParamBounds {
            min,
            max,
            scale: None,
            steps: None,
        }
    }

    #[test]
    fn paths_parse_with_topics_and_reject_nonsense() {
        let p: ParamPath = "sensor[/radar/speed].variance".parse().unwrap();
        assert_eq!(
            p.segments,
            vec![
                Segment::Key("sensor".into()),
                Segment::Select("/radar/speed".into()),
                Segment::Key("variance".into())
            ]
        );
        for bad in [
            "",
            "motion.",
            "sensor[/x",
            "sensor[]",
            "sensor[/x]",
            "a[b]c",
        ] {
            assert!(bad.parse::<ParamPath>().is_err(), "{bad}");
        }
    }

    #[test]
    fn values_are_set_in_place_keeping_comments_and_the_rest_of_the_file() {
        let mut c = open();
        let psd = c
            .param(&"motion.jerk_psd".parse().unwrap(), &bounds(0.01, 10.0))
            .unwrap();
        let r = c
            .param(
                &"sensor[/radar/speed].variance".parse().unwrap(),
                &bounds(1e-3, 1.0),
            )
            .unwrap();
        let gate = c
            .param(
                &"sensor[/radar/speed].gate_nis".parse().unwrap(),
                &bounds(4.0, 100.0),
            )
            .unwrap();
        assert_eq!((psd.start, r.start, gate.start), (0.2, 0.1, 16.0));
        assert!(gate.integer && !r.integer && psd.scale == ScaleName::Log);
        c.set(&[psd, r, gate], &[0.05, 0.0123456789, 9.4]).unwrap();
        let text = c.text();
        assert!(text.contains("jerk_psd = 0.05 } # white jerk"), "{text}");
        assert!(text.contains("variance = 0.0123456789   # radar"), "{text}");
        assert!(text.contains("gate_nis = 9\n"), "{text}");
        assert!(text.contains("# the motion") && text.contains("variance = \"message\""));
    }

    #[test]
    fn bad_parameters_are_one_clear_line_each() {
        let mut c = open();
        let err = |c: &mut TunableConfig, p: &str, b: ParamBounds| {
            c.param(&p.parse().unwrap(), &b).unwrap_err().to_string()
        };
        let e = err(&mut c, "motion.jerk_pds", bounds(0.01, 1.0));
        assert!(
            e.contains("motion.jerk_pds") && e.contains("jerk_psd"),
            "{e}"
        );
        let e = err(&mut c, "sensor[/odometer/1].variance", bounds(0.01, 1.0));
        assert!(e.contains("no sensor has topic /odometer/1"), "{e}");
        let e = err(&mut c, "sensor[/loop/position].variance", bounds(0.01, 1.0));
        assert!(e.contains("\"message\""), "{e}");
        let e = err(&mut c, "motion.jerk_psd", bounds(1.0, 10.0));
        assert!(e.contains("do not contain the file's value 0.2"), "{e}");
        assert!(!e.contains('\n'));
        let log_through_zero = ParamBounds {
            scale: Some(Scale::Log),
            ..bounds(0.0, 1.0)
        };
        let e = err(&mut c, "sensor[/radar/speed].variance", log_through_zero);
        assert!(e.contains("log scale needs bounds above 0"), "{e}");
    }

    #[test]
    fn unit_coordinates_round_trip_on_both_scales() {
        let mut c = open();
        let p = c
            .param(&"motion.jerk_psd".parse().unwrap(), &bounds(0.001, 10.0))
            .unwrap();
        assert!((p.from_unit(p.to_unit(0.2)) - 0.2).abs() < 1e-9);
        assert!(
            (p.from_unit(0.5) - 0.1).abs() < 1e-9,
            "{}",
            p.from_unit(0.5)
        );
        assert_eq!(p.from_unit(-3.0), 0.001);
        assert!(p.on_bound(10.0) && !p.on_bound(0.2));
    }
}
