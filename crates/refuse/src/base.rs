//! What every pipeline is given of its configuration whatever its estimator: its name, its
//! sensors' topics and gates, the reorder window and where it starts. Below the pipelines and
//! the spec that builds them, so that a pipeline depends on this and never on the spec.

/// The part of a pipeline's spec a pipeline that reads whole messages uses.
#[derive(Debug, Clone)]
pub struct PipelineBase {
    pub name: String,
    /// Each sensor's topic, in the configuration's order.
    pub topics: Vec<String>,
    /// Each sensor's NIS gate, if it has one.
    pub gates: Vec<Option<f64>>,
    /// Measurements are released in sensor-time order once the replay is this far past them.
    pub reorder_window_ns: u64,
    pub initial: InitialSpec,
}

/// Where the filter starts (see [`crate::config::InitialConfig`]), as variances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialSpec {
    /// A start chainage, if the pipeline is told one: (chainage, variance).
    pub chainage: Option<(f64, f64)>,
    /// The variance of the start chainage of a pipeline that starts at distance 0.
    pub distance_variance: f64,
    pub speed_mps: f64,
    pub speed_variance: f64,
    pub acceleration_mps2: f64,
    pub acceleration_variance: f64,
}
