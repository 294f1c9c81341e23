//! railfuse-can: the vehicle's CAN bus, the odometry a train puts on it and how railfuse
//! reads it.
//!
//! - [`frame`]: one frame as railfuse keeps it (id, flags, data, bus time), classic and FD.
//! - [`candump`]: the log format of can-utils' `candump -l`, and [`asc`]: Vector's ASC log,
//!   both line by line ([`lines`]: bounded), each line that does not parse reported with its
//!   number; [`blf`]: Vector's binary log, object by object, every size bounded.
//! - [`dbc`]: the vehicle's DBC file as a [`dbc::Database`] of messages and signals (the
//!   grammar is the `can-dbc` crate's), checked for what would decode wrongly, each fault
//!   with its line.
//! - The adapters' wire formats, for live capture: [`slcan`] (the serial line protocol of USB
//!   dongles), [`socketcand`] (CAN over TCP) and [`cannelloni`] (CAN over UDP), each bounded
//!   and each fault said.
//! - [`decode`]: a frame's signals in their units (scale, offset, signed, Intel and Motorola
//!   byte order, IEEE floats, multiplexed signals, value tables), each out of its declared
//!   range flagged; checked against cantools signal for signal. [`encode`]: the inverse, for
//!   what sends on the bus.

pub mod asc;
pub mod blf;
pub mod candump;
pub mod cannelloni;
pub mod dbc;
pub mod decode;
pub mod encode;
pub mod frame;
pub mod lines;
pub mod slcan;
pub mod socketcand;
