//! cannelloni's datagrams (CAN over UDP, github.com/mguentner/cannelloni): a gateway on the
//! train sends the bus's frames to the recorder in batches.
//!
//! A datagram is a 5-byte header, version 2, op code 0 (data), a sequence number (one byte,
//! counting up, so a lost datagram shows as a gap) and the count of frames (u16, big
//! endian); then each frame: its SocketCAN id (u32 big endian, with the extended, remote and
//! error flags in its top bits), its length (with `0x80` set for an FD frame, which then has
//! a flags byte: 1 BRS, 2 ESI) and its data. Frames carry no time: the datagram's receive time
//! is the bus time.

use crate::frame::{Frame, ERROR_FLAG, MAX_CLASSIC_LEN, MAX_FD_LEN};

const VERSION: u8 = 2;
const OP_DATA: u8 = 0;
const EFF_FLAG: u32 = 0x8000_0000;
const RTR_FLAG: u32 = 0x4000_0000;
const FD_LEN_FLAG: u8 = 0x80;

/// A datagram's sequence number and frames (their `stamp_ns` and `bus` the caller's to set).
#[derive(Debug, Clone, PartialEq)]
pub struct Datagram {
    pub sequence: u8,
    pub frames: Vec<Frame>,
}

/// Reads one datagram; what does not fit the format is an error naming the byte.
pub fn parse(d: &[u8]) -> Result<Datagram, String> {
    if d.len() < 5 {
        return Err(format!("{} bytes: shorter than the 5-byte header", d.len()));
    }
    if d[0] != VERSION || d[1] != OP_DATA {
        return Err(format!(
            "version {} op code {}: not a cannelloni data datagram (version 2, op code 0)",
            d[0], d[1]
        ));
    }
    let count = u16::from_be_bytes([d[3], d[4]]) as usize;
    let mut frames = Vec::with_capacity(count.min(d.len() / 5));
    let mut at = 5;
    for i in 0..count {
        let need = |at: usize, n: usize| {
            (at + n <= d.len())
                .then_some(())
                .ok_or_else(|| format!("frame {i} runs past the datagram's {} bytes", d.len()))
        };
        need(at, 5)?;
        let raw = u32::from_be_bytes([d[at], d[at + 1], d[at + 2], d[at + 3]]);
        let len_byte = d[at + 4];
        at += 5;
        let fd = len_byte & FD_LEN_FLAG != 0;
        let len = (len_byte & !FD_LEN_FLAG) as usize;
        let flags = if fd {
            need(at, 1)?;
            at += 1;
            d[at - 1]
        } else {
            0
        };
        let rtr = raw & RTR_FLAG != 0;
        if len > if fd { MAX_FD_LEN } else { MAX_CLASSIC_LEN } {
            return Err(format!("frame {i} claims {len} bytes"));
        }
        let carried = if rtr { 0 } else { len };
        need(at, carried)?;
        frames.push(Frame {
            stamp_ns: 0,
            bus: String::new(),
            id: raw & 0x1FFF_FFFF,
            extended: raw & EFF_FLAG != 0,
            rtr,
            error: raw & ERROR_FLAG != 0,
            fd,
            brs: flags & 1 != 0,
            esi: flags & 2 != 0,
            data: d[at..at + carried].to_vec(),
        });
        at += carried;
    }
    Ok(Datagram {
        sequence: d[2],
        frames,
    })
}

/// The datagram of `frames` (for tests and simulated gateways).
pub fn format(sequence: u8, frames: &[Frame]) -> Vec<u8> {
    let mut d = vec![VERSION, OP_DATA, sequence];
    d.extend((frames.len() as u16).to_be_bytes());
    for f in frames {
        let mut id = f.id;
        if f.extended {
            id |= EFF_FLAG;
        }
        if f.rtr {
            id |= RTR_FLAG;
        }
        if f.error {
            id |= ERROR_FLAG;
        }
        d.extend(id.to_be_bytes());
        match f.fd {
            true => d.extend([
                f.data.len() as u8 | FD_LEN_FLAG,
                u8::from(f.brs) | u8::from(f.esi) << 1,
            ]),
            false => d.push(f.data.len() as u8),
        }
        d.extend(&f.data);
    }
    d
}

/// Datagrams lost between sequence numbers `last` and `next` (they count modulo 256).
pub fn lost_between(last: u8, next: u8) -> u64 {
    u64::from(next.wrapping_sub(last).wrapping_sub(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u32, extended: bool, fd: bool, data: &[u8]) -> Frame {
        Frame {
            stamp_ns: 0,
            bus: String::new(),
            id,
            extended,
            rtr: false,
            error: false,
            fd,
            brs: fd,
            esi: false,
            data: data.to_vec(),
        }
    }

    #[test]
    fn a_datagram_reads_back_and_a_broken_one_says_where() {
        let frames = vec![
            frame(0x123, false, false, &[1, 2, 3]),
            frame(0x1ABC_DEF0, true, false, &[]),
            frame(0x321, false, true, &[9; 12]),
        ];
        let d = format(7, &frames);
        assert_eq!(
            parse(&d).unwrap(),
            Datagram {
                sequence: 7,
                frames
            }
        );
        assert!(parse(&d[..d.len() - 1])
            .unwrap_err()
            .contains("frame 2 runs past"));
        assert!(parse(&[1, 0, 0, 0, 0]).unwrap_err().contains("version 1"));
        assert!(parse(&[2, 0]).unwrap_err().contains("shorter"));
        assert_eq!(lost_between(255, 1), 1);
        assert_eq!(lost_between(4, 5), 0);
    }
}
