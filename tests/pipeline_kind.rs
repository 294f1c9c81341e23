//! A pipeline kind added the way railfuse's own are: a kind (its name, its settings table, its
//! checks of the pipeline table) and its pipeline, registered with one line
//! (`Registry::standard().with(DeadReckoning)`). Nothing in the spec, the pipeline table or
//! the replay changes: the configuration names it, the replay runs it, the output carries it.

mod common;

use std::path::Path;
use std::sync::Arc;

use common::*;
use railfuse_catalog::log::{LogMessage, LogReader, LogRecord};
use railfuse_catalog::messages::{FusedState, GroundTruth, Odometer};
use railfuse_refuse::base::PipelineBase;
use railfuse_refuse::config::PipelineConfig;
use railfuse_refuse::fused::{Fused, PipelineCounts};
use railfuse_refuse::kinds::{
    sensor_of, settings_of, settings_value, KindSpec, MessagePipeline, PipelineKind,
};
use railfuse_refuse::measurement::SensorContext;
use railfuse_refuse::noise::VarianceValue;
use railfuse_refuse::registry::Registry;
use railfuse_refuse::replay::{refuse, RefuseOptions};
use railfuse_refuse::spec::Pipelines;
use serde::{Deserialize, Serialize};

/// `filter = "dead_reckoning"`: chainage by integrating one odometer's speed.
struct DeadReckoning;

/// `[pipeline.dead_reckoning]`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct Settings {
    odometer: String,
    /// Variance of each speed sample, (m/s)²: the chainage variance grows by it × dt².
    speed_variance: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            odometer: "/odometer/1".into(),
            speed_variance: 0.01,
        }
    }
}

#[derive(Debug)]
struct Spec(Settings);

impl PipelineKind for DeadReckoning {
    fn name(&self) -> &'static str {
        "dead_reckoning"
    }
    fn section(&self) -> &'static str {
        "dead_reckoning"
    }
    fn spec(
        &self,
        c: &PipelineConfig,
        settings: Option<toml::Value>,
    ) -> Result<Arc<dyn KindSpec>, String> {
        let s: Settings = settings_of(self.section(), settings)?;
        if !(s.speed_variance > 0.0) {
            return Err("dead_reckoning.speed_variance must be positive".into());
        }
        sensor_of(c, "dead_reckoning.odometer", &s.odometer)?;
        Ok(Arc::new(Spec(s)))
    }
}

impl KindSpec for Spec {
    fn name(&self) -> &'static str {
        "dead_reckoning"
    }
    fn settings(&self) -> toml::Value {
        settings_value(&self.0)
    }
    fn build(&self, base: PipelineBase) -> railfuse_refuse::Result<Box<dyn MessagePipeline>> {
        let (chainage, variance) = base.initial.chainage.unwrap_or((0.0, 0.0));
        Ok(Box::new(Integrator {
            topic: base.topics[0].clone(),
            speed_variance: self.0.speed_variance,
            chainage,
            variance,
            last: None,
            counts: PipelineCounts::default(),
        }))
    }
}

struct Integrator {
    topic: String,
    speed_variance: f64,
    chainage: f64,
    variance: f64,
    /// The previous sample: stamp and speed.
    last: Option<(u64, f64)>,
    counts: PipelineCounts,
}

impl MessagePipeline for Integrator {
    fn counts(&self) -> &PipelineCounts {
        &self.counts
    }
    fn bind(&mut self, _sensor: usize, _variance: Option<VarianceValue>) {}
    fn push(
        &mut self,
        _sensor: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        _context: &SensorContext,
        out: &mut Vec<Fused>,
    ) -> railfuse_refuse::Result<()> {
        let o: Odometer = msg.decode(input)?;
        if let Some((t, v)) = self.last.filter(|(t, _)| o.stamp_ns > *t) {
            let dt = (o.stamp_ns - t) as f64 * 1e-9;
            self.chainage += 0.5 * (v + o.speed_mps) * dt;
            self.variance += self.speed_variance * dt * dt;
        }
        self.last = Some((o.stamp_ns, o.speed_mps));
        self.counts.accepted += 1;
        out.push(Fused {
            log_time_ns: msg.log_time_ns,
            state: Some(FusedState {
                stamp_ns: o.stamp_ns,
                chainage_m: self.chainage,
                speed_mps: o.speed_mps,
                covariance: [
                    self.variance,
                    0.0,
                    0.0,
                    0.0,
                    self.speed_variance,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                ],
                source: self.topic.clone(),
                acceleration_mps2: 0.0,
                sensor_states: Vec::new(),
                plane: None,
            }),
            ..Fused::default()
        });
        Ok(())
    }
    fn finish(&mut self, _log_time_ns: u64, _context: &SensorContext, _out: &mut Vec<Fused>) {}
}

fn config(start_chainage: f64, section: &str) -> String {
    format!(
        r#"
[[pipeline]]
name = "dr"
filter = "dead_reckoning"
motion = {{ model = "constant_velocity", acceleration_psd = 0.1 }}
initial = {{ chainage_m = {start_chainage} }}
{section}
[[pipeline.sensor]]
topic = "/odometer/1"
variance = 0.01
"#
    )
}

/// The truth's first chainage and the truth samples.
fn truth(path: &Path) -> Vec<GroundTruth> {
    let mut reader = LogReader::open(path).unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        if let LogRecord::Message(m) = r.unwrap() {
            if m.channel.topic == "/truth" {
                out.push(m.decode::<GroundTruth>(path).unwrap());
            }
        }
    }
    out
}

#[test]
fn a_kind_registered_with_one_line_is_configured_replayed_written_and_evaluated() {
    let d = tempfile::tempdir().unwrap();
    let (raw, fused) = (d.path().join("run.mcap"), d.path().join("run.fused.mcap"));
    simulate(&["--seed", "3", "--duration", "60"], &raw);
    let truth = truth(&raw);
    let start = truth[0].chainage_m;
    let text = config(
        start,
        "[pipeline.dead_reckoning]\nodometer = \"/odometer/1\"\n",
    );
    let path = d.path().join("dr.toml");

    // railfuse's own registry does not know the kind, and says so where it is named.
    let e = Pipelines::parse(&text, &path).unwrap_err().to_string();
    assert!(
        e.contains("line 4") && e.contains("unknown kind `dead_reckoning`"),
        "{e}"
    );

    // Registered, it is a pipeline like any other.
    let registry = Registry::standard().with(DeadReckoning);
    let pipelines = Pipelines::parse_with(&text, &path, &registry).unwrap();
    let (report, eval) = refuse(&RefuseOptions {
        run: &railfuse_catalog::run::Run::file(&raw),
        output: &fused,
        config: &pipelines,
        config_source: "dr.toml".into(),
        reference: &railfuse_eval::Reference::topic("/truth"),
        withhold: None,
        progress: None,
        observer: None,
    })
    .unwrap();
    let odometer_samples = report.pipelines[0].counts.accepted;
    assert!(odometer_samples > 1000, "{report:?}");
    assert_eq!(report.pipelines[0].fused_states, odometer_samples);

    // The evaluation in the same pass scores it against the truth: 60 s of integrated
    // odometer speed stays within metres of the truth, and no further.
    let dr = eval.pipelines.iter().find(|p| p.name == "dr").unwrap();
    let pos = dr.position_error_m.as_ref().unwrap();
    assert!(pos.samples > 1000, "{pos:?}");
    assert!(pos.max_abs < 10.0, "dead reckoning drifted {pos:?}");
    let travelled = truth.last().unwrap().chainage_m - start;
    assert!(travelled > 100.0, "the run moves: {travelled} m");

    // The output carries its states and its settings with the defaults written out.
    let (states, stored) = states_and_stored_config(&fused, "dr");
    assert_eq!(states, odometer_samples);
    assert!(
        stored.contains("[pipeline.dead_reckoning]") && stored.contains("speed_variance = 0.01"),
        "{stored}"
    );
}

#[test]
fn the_kind_checks_its_settings_table_with_the_line_of_the_pipeline() {
    let path = Path::new("dr.toml");
    let registry = Registry::standard().with(DeadReckoning);
    let bad = config(
        0.0,
        "[pipeline.dead_reckoning]\nodometr = \"/odometer/1\"\n",
    );
    let e = Pipelines::parse_with(&bad, path, &registry)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 2") && e.contains("unknown field `odometr`"),
        "{e}"
    );
    // A table of another kind is refused.
    let other = config(0.0, "[pipeline.safety]\ngnss = \"/gnss/fix\"\n");
    let e = Pipelines::parse_with(&other, path, &registry)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("a [safety] section, but filter = \"dead_reckoning\""),
        "{e}"
    );
}

/// The number of valid states on `/fused/<pipeline>/state` and the pipeline's configuration
/// as stored in the file's metadata.
fn states_and_stored_config(fused: &Path, pipeline: &str) -> (u64, String) {
    let topic = format!("/fused/{pipeline}/state");
    let mut reader = LogReader::open(fused).unwrap();
    let (mut states, mut stored) = (0, None);
    while let Some(r) = reader.next() {
        match r.unwrap() {
            LogRecord::Message(m) if m.channel.topic == topic => {
                let st: FusedState = m.decode(fused).unwrap();
                assert!(st.chainage_m.is_finite() && st.covariance[0] >= 0.0);
                states += 1;
            }
            LogRecord::Metadata { metadata, .. } if metadata.contains_key("config_toml") => {
                stored = metadata.get("config_toml").cloned();
            }
            _ => {}
        }
    }
    (states, stored.expect("the pipeline's config is stored"))
}
