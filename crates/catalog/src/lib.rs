//! The railfuse channel catalogue: every message a railfuse log can carry, the topics they
//! travel on, the JSON schemas generated from the types, and the streaming MCAP log reader and
//! writer that all other railfuse crates share.
//!
//! Why a crate of its own: the recorder (`railfuse-record`), the re-fusion engine
//! (`railfuse-refuse`) and the viewer bridge (`railfuse-viz`) must agree byte for byte on what
//! a channel holds. Keeping the types here lets all three depend downward on one definition
//! without the recorder knowing anything of filters or Rerun.
//!
//! Conventions, everywhere:
//! - SI units (m, m/s, m/s², rad, rad/s, s); degrees only where the name says so
//!   (`latitude_deg`).
//! - Every message carries its sensor's own timestamp `stamp_ns` (ns since the Unix epoch,
//!   sensor clock); the MCAP `publish_time` repeats it and the MCAP `log_time` is the
//!   recorder's receive time.
//! - MCAP message encoding `json`, schema encoding `jsonschema`; the schema is generated from
//!   the Rust type with `schemars`, so the type is the one source of truth.

pub mod error;
pub mod export;
pub mod foreign;
pub mod formats;
pub mod foxglove;
pub mod geodesy;
pub mod inspect;
pub mod log;
pub mod map_matching;
pub mod messages;
pub mod protobuf;
pub mod reference_track;
pub mod rejections;
pub mod run;
pub mod topics;
pub mod track_geojson;
pub mod track_profile;
pub mod train_motion;
pub mod units;
pub mod vehicle;

pub use error::{Error, Result};
pub use messages::ChannelMessage;

/// Nanoseconds in one second, for stamp conversions.
pub const NS_PER_S: f64 = 1e9;

/// Seconds between two nanosecond stamps (`b - a`), signed.
pub fn seconds_between(a_ns: u64, b_ns: u64) -> f64 {
    (b_ns as i128 - a_ns as i128) as f64 / NS_PER_S
}
