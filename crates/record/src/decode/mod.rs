//! Decoders of the byte formats sensors speak: u-blox UBX and NMEA 0183. Each checks its
//! checksum and bounds every length before trusting it; what does not decode is reported as a
//! typed error for the caller to count, never a panic.

pub mod can;
pub mod nmea;
pub mod time;
pub mod ubx;
