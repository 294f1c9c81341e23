//! A serial device (a GNSS receiver on RS-232 or USB) opened raw, 8N1, no flow control, at a
//! set baud rate, through the `serialport` crate (any rate the driver takes: Linux sets
//! non-standard ones too).

use std::io;
use std::path::Path;
use std::time::Duration;

use serialport::{DataBits, FlowControl, Parity, StopBits, TTYPort};

/// Reads return at least this often, so the reader can notice a stop.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// Opens `path` at `baud`.
pub fn open(path: &Path, baud: u32) -> io::Result<TTYPort> {
    if baud == 0 {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, "baud rate 0"));
    }
    serialport::new(path.to_string_lossy(), baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .timeout(READ_TIMEOUT)
        .open_native()
        .map_err(io::Error::from)
}
