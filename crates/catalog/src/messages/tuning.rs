use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// One evaluation of a `railfuse tune` search, on `/tune/<pipeline>/trace`: the candidate, its
/// objective, and the best objective so far (the convergence trace).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TuneEvaluation {
    /// When the evaluation was entered in the trace, ns since the Unix epoch.
    pub stamp_ns: u64,
    /// 0 is the configuration file's own values.
    pub evaluation: u64,
    /// The objective (absent when it was infinite: a candidate that could not be scored).
    #[serde(default)]
    pub objective: Option<f64>,
    /// The lowest objective up to and including this evaluation.
    #[serde(default)]
    pub best: Option<f64>,
    /// The candidate's values, by parameter path.
    pub values: Vec<TunedValue>,
}

/// One tuned value of a candidate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TunedValue {
    /// Its path in the pipeline's table (`sensor[/radar/speed].variance`).
    pub name: String,
    pub value: f64,
}

protobuf_form!(TuneEvaluation {
    stamp_ns,
    evaluation,
    objective,
    best,
    values
});
protobuf_form!(TunedValue { name, value });
