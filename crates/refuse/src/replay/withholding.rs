//! The withholding protocol in the replay: which pipeline does not see which sensor, and
//! when. The command line's `--withhold TOPIC --outages SPEC` applies to every pipeline that
//! fuses TOPIC; a pipeline's own `[pipeline.eval]` applies otherwise. The outages are placed
//! in the run's span (log time) before anything is read, so that a request the run cannot
//! meet fails at once, and they are recorded in the output for `eval`.

use std::path::Path;
use std::sync::Arc;

use railfuse_catalog::log::{ChannelInfo, LogWriter};
use railfuse_catalog::topics;
use railfuse_eval::outages::{Withheld, Withhold};
use railfuse_eval::Evaluator;

use crate::error::{Error, Result};
use crate::spec::PipelineSpec;

/// Each pipeline's withheld sensor and windows, and how many messages it was not shown.
#[derive(Debug, Default)]
pub struct Withholding {
    per_pipeline: Vec<Option<Withheld>>,
    pub hidden: Vec<u64>,
}

impl Withholding {
    /// `requested`: the command line's, over the pipelines' own. `span`: the run's first and
    /// last log time; `channels`: the run's channels, where its summaries list them.
    pub fn resolve(
        input: &Path,
        pipelines: &[PipelineSpec],
        requested: Option<&Withhold>,
        span: Option<(u64, u64)>,
        channels: Option<&[Arc<ChannelInfo>]>,
    ) -> Result<Self> {
        let fail = |topic: &str, problem: String| Error::Withhold {
            input: input.to_owned(),
            problem: format!("withhold {topic}: {problem}"),
        };
        if let Some(w) = requested {
            if !pipelines.iter().any(|p| p.sensor_for(&w.topic).is_some()) {
                let fused: Vec<&str> = pipelines
                    .iter()
                    .flat_map(|p| p.sensors.iter().map(|s| s.topic.as_str()))
                    .collect();
                return Err(fail(
                    &w.topic,
                    format!("no pipeline fuses it (they fuse {})", fused.join(", ")),
                ));
            }
        }
        let mut per_pipeline = Vec::with_capacity(pipelines.len());
        for p in pipelines {
            let w = match requested {
                Some(w) if p.sensor_for(&w.topic).is_some() => Some(w),
                _ => p.withhold.as_ref(),
            };
            let Some(w) = w else {
                per_pipeline.push(None);
                continue;
            };
            if let Some(channels) = channels {
                if !channels.iter().any(|c| c.topic == w.topic) {
                    return Err(fail(&w.topic, "the log has no such channel".into()));
                }
            }
            let placed = w.place(span).map_err(|problem| Error::Withhold {
                input: input.to_owned(),
                problem,
            })?;
            per_pipeline.push(Some(placed));
        }
        Ok(Self {
            hidden: vec![0; per_pipeline.len()],
            per_pipeline,
        })
    }

    /// Writes what each pipeline is not shown into the output (before its fused channels, so
    /// that a reader scores as it goes) and tells the evaluation.
    pub fn record(
        &self,
        pipelines: &[PipelineSpec],
        writer: &mut LogWriter,
        eval: &mut Evaluator,
    ) -> Result<()> {
        for (pi, p) in pipelines.iter().enumerate() {
            if let Some(w) = self.of(pi) {
                let mut record = w.to_metadata();
                record.insert("pipeline".into(), p.name.clone());
                writer.write_metadata(topics::metadata::WITHHELD, record)?;
                eval.withheld(&p.name, w);
            }
        }
        Ok(())
    }

    /// Pipeline `pi`'s withheld sensor, if it has one.
    pub fn of(&self, pi: usize) -> Option<&Withheld> {
        self.per_pipeline.get(pi).and_then(Option::as_ref)
    }

    /// Whether pipeline `pi` is not shown a message of `topic` logged at `log_time_ns`
    /// (counted when it is not).
    pub fn hides(&mut self, pi: usize, topic: &str, log_time_ns: u64) -> bool {
        let hide = self
            .of(pi)
            .is_some_and(|w| w.topic == topic && w.hides(log_time_ns));
        if hide {
            self.hidden[pi] += 1;
        }
        hide
    }
}
