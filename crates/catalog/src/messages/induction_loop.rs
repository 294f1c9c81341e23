use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// Along-track position from a cross-induction loop (the cable crosses every few metres; each
/// crossing detected is a position fix at the crossing's surveyed chainage).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LoopPosition {
    pub stamp_ns: u64,
    pub chainage_m: f64,
    /// Index of the crossing counted from the loop's start, when the loop reports crossings.
    #[serde(default)]
    pub crossing: Option<u32>,
    /// The sensor's own variance estimate, m².
    #[serde(default)]
    pub variance_m2: Option<f64>,
}

protobuf_form!(LoopPosition {
    stamp_ns,
    chainage_m,
    crossing,
    variance_m2
});
