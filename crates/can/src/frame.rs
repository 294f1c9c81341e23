//! One CAN frame as railfuse keeps it: nothing of the bus is lost, with or without a DBC.

/// The CAN error flag in a SocketCAN id (`CAN_ERR_FLAG`): an error frame, whose id bits say
/// what went wrong.
pub const ERROR_FLAG: u32 = 0x2000_0000;

/// The largest payload: 8 bytes classic, 64 FD.
pub const MAX_CLASSIC_LEN: usize = 8;
pub const MAX_FD_LEN: usize = 64;

/// A CAN frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Bus time, ns since the Unix epoch (the adapter's or the log's stamp).
    pub stamp_ns: u64,
    /// The interface or bus it came from (`can0`, `vcan0`, a file's channel).
    pub bus: String,
    /// The identifier: 11 bits, or 29 with `extended`.
    pub id: u32,
    pub extended: bool,
    /// A remote transmission request (no data).
    pub rtr: bool,
    /// An error frame: `id` holds the error class bits.
    pub error: bool,
    /// CAN FD, with its bit-rate switch and error-state indicator.
    pub fd: bool,
    pub brs: bool,
    pub esi: bool,
    pub data: Vec<u8>,
}

/// The FD payload lengths a DLC can give.
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];
