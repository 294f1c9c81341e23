//! ASAM MDF 4 (4.00–4.20), the measurement format of vehicle loggers (CSS CANedge, Vector,
//! ETAS, most bus loggers), read streaming, every size bounded.
//!
//! What this crate owns:
//! - [`block`]: a block's header, links and data, each length checked against the file and
//!   a bound before anything is allocated; texts (TX, MD).
//! - [`layout`]: the file's tree (header, data groups, channel groups, channels with their
//!   conversions), read once, link cycles refused.
//! - [`data`]: a data group's data as one byte stream over DT, DL and HL lists and DZ blocks
//!   (deflate and transposed deflate), each DZ inflated to at most [`data::MAX_INFLATED`].
//! - [`records`]: the records of a data group, sorted (one channel group) or unsorted (record
//!   ids), with variable-length signal data (VLSD) from channel groups or SD blocks.
//! - [`bus`]: CAN bus logging (ASAM's `CAN_DataFrame`, `CAN_RemoteFrame`, `CAN_ErrorFrame`
//!   groups) as [`railfuse_can::frame::Frame`]s in time order across data groups.
//!
//! Why by hand: the `mdf4-rs` crate reads a whole file into memory (memory grows with the
//! drive) and has no transposed DZ; `mdfr` reads into Arrow arrays, whole. Here a file is
//! read record by record with a bounded buffer, and an unfinalised or cut-off file (a logger's
//! power cut) gives the records before the cut.

pub mod block;
pub mod bus;
pub mod data;
pub mod layout;
pub mod records;
pub mod signals;

/// Where and why an MDF file could not be read on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MdfError {
    #[error("byte {offset}: {reason}")]
    Format { offset: u64, reason: String },
    #[error("{0}")]
    Io(String),
}

impl MdfError {
    pub(crate) fn at(offset: u64, reason: impl Into<String>) -> Self {
        MdfError::Format {
            offset,
            reason: reason.into(),
        }
    }
}

impl From<std::io::Error> for MdfError {
    fn from(e: std::io::Error) -> Self {
        MdfError::Io(e.to_string())
    }
}

pub type Result<T, E = MdfError> = std::result::Result<T, E>;
