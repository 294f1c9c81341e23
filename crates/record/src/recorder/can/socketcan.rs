//! A Linux SocketCAN interface (`can0`, `vcan0`) read through a raw CAN socket: classic and
//! FD frames and error frames (every error class), each stamped by the kernel when it
//! received it (`SO_TIMESTAMPNS`), and the kernel's count of frames dropped on a full socket
//! buffer (`SO_RXQ_OVFL`), as for UDP.

use std::io::IoSliceMut;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

use nix::sys::socket::{self, sockopt, ControlMessageOwned, MsgFlags};
use nix::sys::time::TimeVal;
use railfuse_can::frame::{Frame, ERROR_FLAG};

use super::frames::Frames;

const EFF_FLAG: u32 = 0x8000_0000;
const RTR_FLAG: u32 = 0x4000_0000;
/// `struct can_frame` and `struct canfd_frame`.
const CAN_MTU: usize = 16;
const CANFD_MTU: usize = 72;
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;

/// A raw CAN socket bound to `iface`, with FD frames, every error class, the kernel's
/// stamps and drop count turned on.
fn open(iface: &str) -> Result<OwnedFd, String> {
    let name = std::ffi::CString::new(iface).map_err(|_| "a name with a NUL".to_owned())?;
    // SAFETY: if_nametoindex reads a NUL-terminated string.
    let index = unsafe { libc::if_nametoindex(name.as_ptr()) };
    if index == 0 {
        return Err(format!(
            "no network interface {iface} (`ip link show` lists them; a USB adapter may need \
             `ip link set {iface} up type can bitrate 500000`)"
        ));
    }
    // SAFETY: socket() takes no pointers; a valid descriptor is owned from here.
    let fd = unsafe {
        libc::socket(
            libc::PF_CAN,
            libc::SOCK_RAW | libc::SOCK_CLOEXEC,
            libc::CAN_RAW,
        )
    };
    if fd < 0 {
        return Err(format!(
            "cannot open a CAN socket: {}",
            std::io::Error::last_os_error()
        ));
    }
    // SAFETY: `fd` was just returned by socket() and is owned by nothing else.
    let sock = unsafe { OwnedFd::from_raw_fd(fd) };
    let set = |level: libc::c_int, name: libc::c_int, value: u32| {
        // SAFETY: the option value is a live u32 of the size given.
        unsafe {
            libc::setsockopt(
                sock.as_raw_fd(),
                level,
                name,
                (&value as *const u32).cast(),
                std::mem::size_of::<u32>() as libc::socklen_t,
            )
        }
    };
    // FD frames where the kernel has them (a classic-only kernel refuses: classic frames).
    set(libc::SOL_CAN_RAW, libc::CAN_RAW_FD_FRAMES, 1);
    set(
        libc::SOL_CAN_RAW,
        libc::CAN_RAW_ERR_FILTER,
        libc::CAN_ERR_MASK,
    );
    // SAFETY: sockaddr_can is plain data; zeroed is a valid value to fill in.
    let mut addr: libc::sockaddr_can = unsafe { std::mem::zeroed() };
    addr.can_family = libc::AF_CAN as libc::sa_family_t;
    addr.can_ifindex = index as libc::c_int;
    // SAFETY: `addr` is a live sockaddr_can of the size given.
    let bound = unsafe {
        libc::bind(
            sock.as_raw_fd(),
            (&addr as *const libc::sockaddr_can).cast(),
            std::mem::size_of::<libc::sockaddr_can>() as libc::socklen_t,
        )
    };
    if bound < 0 {
        return Err(format!(
            "cannot bind to {iface}: {}",
            std::io::Error::last_os_error()
        ));
    }
    let _ = socket::setsockopt(&sock, sockopt::ReceiveTimestampns, &true);
    let _ = socket::setsockopt(&sock, sockopt::RxqOvfl, &1);
    let _ = socket::setsockopt(&sock, sockopt::ReceiveTimeout, &TimeVal::new(0, 100_000));
    Ok(sock)
}

/// The frame in a `can_frame` or `canfd_frame` the kernel handed over.
fn frame_of(buf: &[u8]) -> Option<Frame> {
    let fd = match buf.len() {
        CAN_MTU => false,
        CANFD_MTU => true,
        _ => return None,
    };
    let raw = u32::from_ne_bytes(buf[..4].try_into().ok()?);
    let len = usize::from(buf[4]).min(if fd { 64 } else { 8 });
    let flags = if fd { buf[5] } else { 0 };
    let error = raw & ERROR_FLAG != 0;
    let rtr = raw & RTR_FLAG != 0;
    let extended = raw & EFF_FLAG != 0;
    Some(Frame {
        stamp_ns: 0,
        bus: String::new(),
        id: raw
            & if extended || error {
                0x1FFF_FFFF
            } else {
                0x7FF
            },
        extended: extended && !error,
        rtr,
        error,
        fd,
        brs: flags & CANFD_BRS != 0,
        esi: flags & CANFD_ESI != 0,
        data: if rtr {
            Vec::new()
        } else {
            buf[8..8 + len].to_vec()
        },
    })
}

/// Reads `iface` until the recorder stops or the interface goes away.
pub(super) fn run(iface: &str, out: &mut Frames<'_>) -> Result<(), String> {
    let sock = open(iface)?;
    let mut buf = [0u8; CANFD_MTU];
    let mut cmsg = nix::cmsg_space!(libc::timespec, u32);
    let mut kernel_dropped = 0u64;
    while !out.stopping() {
        let mut iov = [IoSliceMut::new(&mut buf)];
        let received = socket::recvmsg::<()>(
            sock.as_raw_fd(),
            &mut iov,
            Some(&mut cmsg),
            MsgFlags::empty(),
        );
        let msg = match received {
            Ok(m) => m,
            Err(nix::errno::Errno::EAGAIN | nix::errno::Errno::EINTR) => continue,
            Err(e) => return Err(format!("went away: {e}")),
        };
        let (mut stamp, mut dropped) = (None, None);
        if let Ok(cmsgs) = msg.cmsgs() {
            for c in cmsgs {
                match c {
                    ControlMessageOwned::ScmTimestampns(t) => {
                        stamp = Some(t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64)
                    }
                    ControlMessageOwned::RxqOvfl(total) => dropped = Some(u64::from(total)),
                    _ => {}
                }
            }
        }
        let n = msg.bytes;
        if let Some(total) = dropped {
            out.local.kernel_dropped += total.saturating_sub(kernel_dropped);
            kernel_dropped = kernel_dropped.max(total);
        }
        match frame_of(&buf[..n]) {
            Some(f) => out.frame(f, stamp),
            None => out.local.count("SocketCAN read of neither frame size"),
        }
        if !out.flush() {
            return Ok(());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_frames_read_as_frames() {
        let mut classic = [0u8; CAN_MTU];
        classic[..4].copy_from_slice(&(0x1234_5678 | EFF_FLAG).to_ne_bytes());
        classic[4] = 2;
        classic[8..10].copy_from_slice(&[0xAB, 0xCD]);
        let f = frame_of(&classic).unwrap();
        assert!(f.extended && f.id == 0x1234_5678 && f.data == [0xAB, 0xCD] && !f.fd);
        let mut fd = [0u8; CANFD_MTU];
        fd[..4].copy_from_slice(&0x123u32.to_ne_bytes());
        fd[4] = 12;
        fd[5] = CANFD_BRS;
        let f = frame_of(&fd).unwrap();
        assert!(f.fd && f.brs && f.data.len() == 12 && f.id == 0x123 && !f.extended);
        let mut err = [0u8; CAN_MTU];
        err[..4].copy_from_slice(&(ERROR_FLAG | 0x04).to_ne_bytes());
        err[4] = 8;
        let f = frame_of(&err).unwrap();
        assert!(f.error && f.id == 4 && !f.extended);
        assert!(frame_of(&[0u8; 20]).is_none());
    }
}
