pub mod bench;
pub mod demo;
pub mod eval;
pub mod info;
pub mod refuse;
pub mod simulate;
pub mod viz;

/// The pipeline configuration used when none is given: `samples/kalman.toml`.
pub const DEFAULT_PIPELINES: &str = include_str!("../../samples/kalman.toml");
