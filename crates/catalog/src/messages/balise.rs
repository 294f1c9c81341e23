use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

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
