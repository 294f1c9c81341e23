//! Where a CAN source's frames go (decoded into items, counted, queued), and the read loop
//! of the adapters that are byte streams (SLCAN, socketcand).

use std::io::Read;

use railfuse_can::frame::Frame;
use railfuse_catalog::messages::SourceStats;

use crate::decode::can::CanDecoder;
use crate::recorder::link::{lock, nothing_waiting, now_ns, Drain, Link};

/// Where a source's frames go: decoded into items, counted, queued.
pub(super) struct Frames<'a> {
    decoder: CanDecoder,
    bus: String,
    link: &'a Link,
    pub(super) local: SourceStats,
    items: Vec<crate::recorder::message::Item>,
}

impl<'a> Frames<'a> {
    pub(super) fn new(decoder: CanDecoder, bus: String, link: &'a Link) -> Self {
        Self {
            decoder,
            bus,
            link,
            local: SourceStats::default(),
            items: Vec::new(),
        }
    }

    /// Says `text` at once on the recorder's status line.
    pub(super) fn alert(&self, text: String) {
        self.link.alert(text);
    }

    /// One frame at bus time `stamp_ns` (None: the receive time), received now.
    pub(super) fn frame(&mut self, mut frame: Frame, stamp_ns: Option<u64>) {
        let receive_ns = now_ns();
        frame.stamp_ns = stamp_ns.unwrap_or(receive_ns);
        frame.bus.clone_from(&self.bus);
        self.decoder
            .frame(&frame, receive_ns, &mut self.local, &mut self.items);
    }

    /// Queues what was decoded and adds the figures to the source's; false when the recorder
    /// has gone.
    pub(super) fn flush(&mut self) -> bool {
        if self.local != SourceStats::default() {
            lock(&self.link.stats).absorb(&self.local);
            self.local = SourceStats::default();
        }
        self.link.send(&mut self.items, None)
    }

    pub(super) fn stopping(&self) -> bool {
        self.link.stopping()
    }
}

/// Reads `r` until it ends, fails, or the recorder stops (then for up to [`DRAIN`] while
/// bytes keep coming), each read handed to `feed`. A tty's timed-out read returns 0 bytes,
/// as does one whose device is gone: `tty_hung_up` tells them apart (None: a socket, whose
/// 0 bytes are its end).
pub(super) fn pump(
    mut r: impl Read,
    out: &mut Frames<'_>,
    tty_hung_up: Option<&dyn Fn() -> bool>,
    mut feed: impl FnMut(&[u8], &mut Frames<'_>),
) -> Result<(), String> {
    let mut buf = vec![0u8; 64 << 10];
    let mut drain = Drain::default();
    loop {
        if drain.over(out.stopping()) {
            return Ok(());
        }
        match r.read(&mut buf) {
            Ok(0) if drain.draining() => return Ok(()),
            Ok(0) => match tty_hung_up {
                Some(hung_up) if !hung_up() => {}
                Some(_) => return Err("went away (the line hung up)".into()),
                None => return Err("the adapter closed the connection".into()),
            },
            Ok(n) => {
                feed(&buf[..n], out);
                if !out.flush() {
                    return Ok(());
                }
            }
            Err(e) if nothing_waiting(&e) => {
                if drain.draining() {
                    return Ok(());
                }
            }
            Err(e) => return Err(format!("went away: {e}")),
        }
    }
}
