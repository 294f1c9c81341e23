use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// A balise passage: the reader antenna was over the balise at `stamp_ns`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BalisePassage {
    pub stamp_ns: u64,
    pub balise_id: String,
    /// The balise's surveyed chainage, from its telegram or the track database.
    pub chainage_m: f64,
    /// Variance of the passage position (survey plus detection), m².
    #[serde(default)]
    pub variance_m2: Option<f64>,
}

protobuf_form!(BalisePassage {
    stamp_ns,
    balise_id,
    chainage_m,
    variance_m2
});
