//! A cannelloni gateway's datagrams ([`railfuse_can::cannelloni`]), with the kernel's drops
//! and the gateway's sequence gaps counted.

use std::net::UdpSocket;
use std::time::Duration;

use railfuse_can::cannelloni;

use super::frames::Frames;
use crate::recorder::link::{nothing_waiting, Drain};
use crate::recorder::udp::UDP_RECEIVE_BUFFER;

/// How often a blocking read wakes to see whether the recorder is stopping.
const TICK: Duration = Duration::from_millis(100);

/// A cannelloni gateway's datagrams, with the kernel's drops and the gateway's sequence gaps.
pub(super) fn run(addr: std::net::SocketAddr, out: &mut Frames<'_>) -> Result<(), String> {
    let sock = UdpSocket::bind(addr).map_err(|e| format!("cannot bind {addr}: {e}"))?;
    sock.set_read_timeout(Some(TICK))
        .map_err(|e| e.to_string())?;
    let granted = crate::recorder::udp::size_receive_buffer(&sock, UDP_RECEIVE_BUFFER);
    if granted < UDP_RECEIVE_BUFFER {
        out.alert(format!(
            "cannelloni {addr}: the kernel gives a receive buffer of {} KiB \
             (net.core.rmem_max); bursts may be dropped, and are counted",
            granted >> 10
        ));
    }
    let mut receiver = crate::recorder::udp::Receiver::new(&sock);
    let mut buf = vec![0u8; 65_536];
    let (mut last_sequence, mut kernel_dropped, mut datagram) = (None::<u8>, 0u64, 0u64);
    let mut drain = Drain::default();
    loop {
        if drain.over(out.stopping()) {
            return Ok(());
        }
        match receiver.recv(&mut buf) {
            Ok((n, dropped_so_far)) => {
                datagram += 1;
                out.local.kernel_dropped += dropped_so_far.saturating_sub(kernel_dropped);
                kernel_dropped = kernel_dropped.max(dropped_so_far);
                match cannelloni::parse(&buf[..n]) {
                    Ok(d) => {
                        if let Some(last) = last_sequence {
                            let lost = cannelloni::lost_between(last, d.sequence);
                            // A gap of more than half the sequence space is a reordering or a
                            // restarted gateway, not a loss.
                            if lost > 0 && lost < 128 {
                                *out.local
                                    .warnings
                                    .entry("cannelloni datagrams lost (sequence gaps)".into())
                                    .or_insert(0) += lost;
                            }
                        }
                        last_sequence = Some(d.sequence);
                        for f in d.frames {
                            out.frame(f, None);
                        }
                    }
                    Err(e) => out.local.skip(
                        "cannelloni datagram that does not parse",
                        &format!("datagram {datagram}"),
                        &e,
                    ),
                }
                if !out.flush() {
                    return Ok(());
                }
            }
            Err(e) if nothing_waiting(&e) => {
                if drain.draining() {
                    return Ok(());
                }
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}
