//! The vehicle's CAN bus as a recorder source: SocketCAN, an SLCAN serial adapter, a
//! socketcand server or a cannelloni gateway. Each frame is logged whole on
//! `/can/<bus>/frames` and, with the vehicle's DBC, decoded ([`CanDecoder`]).
//!
//! An adapter that goes away mid-run (a dongle unplugged, a gateway's connection lost) ends
//! that source with its reason; the recording and the other sources go on. What an adapter
//! sends that is not a frame is skipped and counted with where it was; drops are counted
//! where they can be seen: the kernel's on a full socket buffer (SocketCAN, cannelloni), the
//! gateway's sequence gaps (cannelloni), the recorder's own full queue (every source).

mod cannelloni;
mod frames;
mod slcan;
mod socketcan;
mod socketcand;

use std::sync::Arc;

use railfuse_can::dbc::Database;

use super::link::Link;
use super::source_spec::CanAdapter;
use crate::decode::can::CanDecoder;
use crate::error::SourceError;
use frames::Frames;

/// Records `adapter` until it ends or the recorder stops.
pub(super) fn run(
    adapter: &CanAdapter,
    dbc: Option<Arc<Database>>,
    link: &Link,
) -> Result<(), SourceError> {
    let dbcs = railfuse_can::dbc::BusDbcs::every_bus(dbc);
    let mut out = Frames::new(CanDecoder::new(dbcs), adapter.bus(), link);
    let fail = |cause: String| SourceError::Can {
        adapter: adapter.to_string(),
        cause,
    };
    match adapter {
        CanAdapter::SocketCan { iface } => socketcan::run(iface, &mut out).map_err(fail),
        CanAdapter::Slcan {
            path,
            bitrate,
            baud,
        } => slcan::run(path, *bitrate, *baud, &mut out).map_err(fail),
        CanAdapter::Socketcand { addr, bus } => socketcand::run(addr, bus, &mut out).map_err(fail),
        CanAdapter::Cannelloni { addr, .. } => cannelloni::run(*addr, &mut out).map_err(fail),
    }
}
