//! A UDP socket made for bursts: a receive buffer sized for them, and the kernel's count of
//! datagrams it dropped when that buffer was full (`SO_RXQ_OVFL`, read from each datagram's
//! control message), so that a loss is counted instead of silent.

use std::io::IoSliceMut;
use std::net::UdpSocket;
use std::os::fd::AsRawFd;

use nix::sys::socket::{self, sockopt, ControlMessageOwned, MsgFlags};

/// The UDP receive buffer asked for: bursts of datagrams wait here while the thread is busy.
pub const UDP_RECEIVE_BUFFER: usize = 8 << 20;

/// Asks for a receive buffer of `bytes` (beyond `net.core.rmem_max` where the process may,
/// as root may); returns what the kernel granted (it reports twice the usable size).
pub fn size_receive_buffer(sock: &UdpSocket, bytes: usize) -> usize {
    if socket::setsockopt(sock, sockopt::RcvBufForce, &bytes).is_err() {
        let _ = socket::setsockopt(sock, sockopt::RcvBuf, &bytes);
    }
    socket::getsockopt(sock, sockopt::RcvBuf).map_or(0, |granted| granted / 2)
}

/// Receives datagrams with the kernel's drop count. The kernel stamps its running count on
/// each datagram it queues, so drops are known when the next datagram after them arrives.
pub struct Receiver<'a> {
    sock: &'a UdpSocket,
    cmsg: Vec<u8>,
    /// The kernel's drop count as last reported (it reports a running total).
    dropped: u64,
}

impl<'a> Receiver<'a> {
    /// Turns on the kernel's drop count for `sock` (where the kernel has it).
    pub fn new(sock: &'a UdpSocket) -> Self {
        let _ = socket::setsockopt(sock, sockopt::RxqOvfl, &1);
        Self {
            sock,
            cmsg: nix::cmsg_space!(u32),
            dropped: 0,
        }
    }

    /// One datagram into `buf`: its length, and how many datagrams the kernel has dropped
    /// on this socket so far.
    pub fn recv(&mut self, buf: &mut [u8]) -> std::io::Result<(usize, u64)> {
        let mut iov = [IoSliceMut::new(buf)];
        let msg = socket::recvmsg::<()>(
            self.sock.as_raw_fd(),
            &mut iov,
            Some(&mut self.cmsg),
            MsgFlags::empty(),
        )
        .map_err(std::io::Error::from)?;
        let n = msg.bytes;
        if let Ok(cmsgs) = msg.cmsgs() {
            for c in cmsgs {
                if let ControlMessageOwned::RxqOvfl(total) = c {
                    self.dropped = u64::from(total);
                }
            }
        }
        Ok((n, self.dropped))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_datagram_arrives_with_the_drop_count_and_the_buffer_is_sized() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        assert!(size_receive_buffer(&rx, 1 << 20) >= 64 << 10);
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        tx.send_to(b"hello", rx.local_addr().unwrap()).unwrap();
        let mut r = Receiver::new(&rx);
        let mut buf = [0u8; 64];
        assert_eq!(r.recv(&mut buf).unwrap(), (5, 0));
        assert_eq!(&buf[..5], b"hello");
    }

    #[test]
    fn datagrams_the_kernel_drops_on_a_full_buffer_are_counted_to_the_last_one() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        size_receive_buffer(&rx, 4096); // the kernel's smallest: a burst overflows it
        rx.set_read_timeout(Some(std::time::Duration::from_millis(200)))
            .unwrap();
        let mut r = Receiver::new(&rx);
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let sent = 2000;
        for _ in 0..sent {
            tx.send_to(&[7u8; 1000], rx.local_addr().unwrap()).unwrap();
        }
        let (mut received, mut dropped) = (0u64, 0);
        let mut buf = [0u8; 2048];
        while let Ok((_, d)) = r.recv(&mut buf) {
            received += 1;
            dropped = d;
        }
        // The kernel stamps its running count on the datagrams queued after a drop: the next
        // one brings it.
        tx.send_to(b"next", rx.local_addr().unwrap()).unwrap();
        dropped = r.recv(&mut buf).map_or(dropped, |(_, d)| d);
        assert!(
            dropped > 0,
            "nothing dropped: the buffer was not full ({received} received, buffer {})",
            socket::getsockopt(&rx, sockopt::RcvBuf).unwrap()
        );
        assert_eq!(
            received + dropped,
            sent,
            "every datagram received or counted"
        );
    }
}
