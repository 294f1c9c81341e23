//! Vector's BLF (binary logging format: CANalyzer, CANoe, python-can's `BLFWriter`), as
//! python-can's `BLFReader` reads it: a 144-byte file header (its start time a SYSTEMTIME,
//! which carries no zone: taken as UTC, as the ASC log's date is), then `LOBJ` objects; the
//! log containers among them (raw or zlib) hold, end to end, the objects that are frames:
//! `CAN_MESSAGE`/`CAN_MESSAGE2` (classic), `CAN_ERROR_EXT`, `CAN_FD_MESSAGE` and
//! `CAN_FD_MESSAGE_64`. Other objects are read past. A frame's bus is `CAN<n>`, the file's
//! channel (from 1).
//!
//! A BLF is untrusted input: every size is checked before it is used, an object is at most
//! [`MAX_OBJECT`] bytes and a container inflates to at most [`MAX_CONTAINER`]; a file that
//! breaks the format ends the reading with the byte offset where it did, the frames before it
//! kept.

use std::io::Read;

use flate2::read::ZlibDecoder;

use crate::frame::Frame;

/// The largest object taken (a log container is 128 KiB as Vector and python-can write them).
pub const MAX_OBJECT: usize = 16 << 20;
/// The most a container may inflate to.
pub const MAX_CONTAINER: u64 = 64 << 20;

const FILE_HEADER: usize = 144;
const BASE: usize = 16;
const LOG_CONTAINER: u32 = 10;
const CAN_MESSAGE: u32 = 1;
const CAN_ERROR_EXT: u32 = 73;
const CAN_MESSAGE2: u32 = 86;
const CAN_FD_MESSAGE: u32 = 100;
const CAN_FD_MESSAGE_64: u32 = 101;
const CAN_MSG_EXT: u32 = 0x8000_0000;
const REMOTE_FLAG: u8 = 0x80;

/// Where and why a BLF stopped reading.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {reason}")]
pub struct BadObject {
    pub offset: u64,
    pub reason: String,
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// A BLF read object by object: each item a frame, or the fault that ended the file.
pub struct Reader<R> {
    input: R,
    offset: u64,
    start_ns: u64,
    /// Inflated container bytes not yet parsed (an object may span two containers).
    data: Vec<u8>,
    pos: usize,
    done: bool,
    objects: u64,
    /// The last container was cut off by the end of the file.
    cut: bool,
}

/// A SYSTEMTIME (year, month, weekday, day, hour, minute, second, ms) as ns, taken as UTC.
fn systemtime_ns(t: &[u8]) -> u64 {
    let f = |i: usize| u32::from(u16_at(t, 2 * i));
    chrono::NaiveDate::from_ymd_opt(f(0) as i32, f(1), f(3))
        .and_then(|d| d.and_hms_milli_opt(f(4), f(5), f(6), f(7)))
        .and_then(|dt| dt.and_utc().timestamp_nanos_opt())
        .map_or(0, |ns| ns.max(0) as u64)
}

impl<R: Read> Reader<R> {
    /// Reads the file header; a file that is not a BLF is refused here.
    pub fn new(mut input: R) -> Result<Self, BadObject> {
        let mut header = [0u8; FILE_HEADER];
        let bad = |reason: &str| BadObject {
            offset: 0,
            reason: reason.into(),
        };
        input
            .read_exact(&mut header)
            .map_err(|_| bad("shorter than a BLF file header"))?;
        if &header[..4] != b"LOGG" {
            return Err(bad("not a BLF file (no LOGG signature)"));
        }
        let size = u32_at(&header, 4) as usize;
        if !(FILE_HEADER..=4096).contains(&size) {
            return Err(bad(&format!("a file header of {size} bytes")));
        }
        let mut rest = vec![0u8; size - FILE_HEADER];
        input
            .read_exact(&mut rest)
            .map_err(|_| bad("the file header runs past the end"))?;
        Ok(Self {
            input,
            offset: size as u64,
            start_ns: systemtime_ns(&header[40..56]),
            data: Vec::new(),
            pos: 0,
            done: false,
            objects: 0,
            cut: false,
        })
    }

    /// Objects read so far (outer ones and those in containers).
    pub fn objects_read(&self) -> u64 {
        self.objects
    }

    /// Bytes of the file read so far.
    pub fn bytes_read(&self) -> u64 {
        self.offset
    }

    fn fail(&mut self, reason: String) -> Option<Result<Frame, BadObject>> {
        self.done = true;
        Some(Err(BadObject {
            offset: self.offset,
            reason,
        }))
    }

    /// The next container's inflated bytes appended; false at the end of the file.
    fn next_container(&mut self) -> Result<bool, String> {
        loop {
            let mut base = [0u8; BASE];
            match self.input.read(&mut base[..1]) {
                Ok(0) => return Ok(false),
                Ok(_) => {}
                Err(e) => return Err(e.to_string()),
            }
            self.input
                .read_exact(&mut base[1..])
                .map_err(|_| "an object header cut off".to_owned())?;
            if &base[..4] != b"LOBJ" {
                return Err("no LOBJ signature where an object begins".into());
            }
            let size = u32_at(&base, 8) as usize;
            let kind = u32_at(&base, 12);
            if !(BASE..=MAX_OBJECT).contains(&size) {
                return Err(format!("an object of {size} bytes"));
            }
            let want = size - BASE + size % 4;
            let mut body = Vec::with_capacity(want);
            (&mut self.input)
                .take(want as u64)
                .read_to_end(&mut body)
                .map_err(|e| e.to_string())?;
            let cut = body.len() < want;
            self.offset += (BASE + body.len()) as u64;
            self.objects += 1;
            if cut && kind != LOG_CONTAINER {
                return Err(format!("an object of {size} bytes runs past the end"));
            }
            if kind != LOG_CONTAINER {
                continue;
            }
            if body.len() < 16 {
                return Err("a log container's header cut off".into());
            }
            let contents = &body[16..(size - BASE).min(body.len())];
            // What is left of the last container, then this one.
            self.data.drain(..self.pos);
            self.pos = 0;
            match u16_at(&body, 0) {
                0 => self.data.extend_from_slice(contents),
                2 => {
                    let mut z = ZlibDecoder::new(contents).take(MAX_CONTAINER + 1);
                    let before = self.data.len();
                    let inflated = z.read_to_end(&mut self.data);
                    // A container cut off by the end of the file gives what it holds.
                    if let (Err(e), false) = (inflated, cut) {
                        return Err(format!("a log container does not inflate: {e}"));
                    }
                    if (self.data.len() - before) as u64 > MAX_CONTAINER {
                        return Err(format!(
                            "a log container inflates past {MAX_CONTAINER} bytes"
                        ));
                    }
                }
                _ => continue, // a compression this reader does not know: read past
            }
            if self.data.len() > MAX_OBJECT + MAX_CONTAINER as usize {
                return Err("an object spans more containers than any frame needs".into());
            }
            self.cut = cut;
            return Ok(true);
        }
    }

    /// The frame of the inner object at `self.pos`, if it is one; `None` when the object
    /// runs on into the next container.
    fn inner(&mut self) -> Option<Result<Option<Frame>, String>> {
        let d = &self.data;
        // Objects are padded to 4 bytes (but CAN_FD_MESSAGE_64): the next one is near.
        let at = (self.pos..(self.pos + 8).min(d.len().saturating_sub(3)))
            .find(|&p| &d[p..p + 4] == b"LOBJ");
        let Some(at) = at else {
            return match d.len() < self.pos + 8 {
                true => None,
                false => Some(Err("no LOBJ signature where an object begins".into())),
            };
        };
        if d.len() < at + BASE {
            return None;
        }
        let (header_size, version) = (u16_at(d, at + 4) as usize, u16_at(d, at + 6));
        let (size, kind) = (u32_at(d, at + 8) as usize, u32_at(d, at + 12));
        if size < BASE + 16 || size > MAX_OBJECT || header_size > size {
            return Some(Err(format!("an object of {size} bytes in a container")));
        }
        if d.len() < at + size {
            return None;
        }
        self.pos = at + size;
        self.objects += 1;
        let o = &d[at..at + size];
        let (flags, stamp, body) = match version {
            1 => (u32_at(o, 16), u64_at(o, 24), 32),
            2 if size >= 40 => (u32_at(o, 16), u64_at(o, 24), 40),
            _ => return Some(Ok(None)),
        };
        let ns = if flags == 1 {
            stamp.saturating_mul(10_000)
        } else {
            stamp
        };
        Some(Ok(frame_of(kind, &o[body..], header_size.max(body), o)
            .map(|mut f| {
                f.stamp_ns = self.start_ns.saturating_add(ns);
                f
            })))
    }
}

/// The frame an object of `kind` holds (its body `b`, the whole object `o`), if it is one.
fn frame_of(kind: u32, b: &[u8], header_size: usize, o: &[u8]) -> Option<Frame> {
    let frame = |channel: u16, raw: u32, data: &[u8]| Frame {
        stamp_ns: 0,
        bus: format!("CAN{channel}"),
        id: raw & 0x1FFF_FFFF,
        extended: raw & CAN_MSG_EXT != 0,
        rtr: false,
        error: false,
        fd: false,
        brs: false,
        esi: false,
        data: data.to_vec(),
    };
    match kind {
        CAN_MESSAGE | CAN_MESSAGE2 if b.len() >= 16 => {
            let dlc = usize::from(b[3]).min(8);
            let mut f = frame(u16_at(b, 0), u32_at(b, 4), &b[8..8 + dlc]);
            f.rtr = b[2] & REMOTE_FLAG != 0;
            if f.rtr {
                f.data.clear();
            }
            Some(f)
        }
        CAN_ERROR_EXT if b.len() >= 32 => {
            let dlc = usize::from(b[10]).min(8);
            let mut f = frame(u16_at(b, 0), u32_at(b, 16), &b[24..24 + dlc]);
            (f.error, f.extended) = (true, false);
            Some(f)
        }
        CAN_FD_MESSAGE if b.len() >= 84 => {
            let (flags, fd_flags, valid) = (b[2], b[13], usize::from(b[14]).min(64));
            let mut f = frame(u16_at(b, 0), u32_at(b, 4), &b[20..20 + valid]);
            (f.fd, f.brs, f.esi) = (fd_flags & 1 != 0, fd_flags & 2 != 0, fd_flags & 4 != 0);
            f.rtr = flags & REMOTE_FLAG != 0;
            Some(f)
        }
        CAN_FD_MESSAGE_64 if b.len() >= 40 => {
            let valid = usize::from(b[2]).min(64);
            let flags = u32_at(b, 12);
            let ext = usize::from(b[35]);
            // Data as far as the object (or its extension) goes, zeros past it, as CANoe does.
            let end = if ext > 0 { ext } else { o.len() }.min(o.len());
            let start = header_size + 40;
            let mut data = o.get(start..end.max(start)).unwrap_or(&[]).to_vec();
            data.truncate(valid);
            data.resize(valid, 0);
            let mut f = frame(u16::from(b[0]), u32_at(b, 4), &data);
            f.fd = flags & 0x1000 != 0;
            (f.brs, f.esi, f.rtr) = (flags & 0x2000 != 0, flags & 0x4000 != 0, flags & 0x10 != 0);
            Some(f)
        }
        _ => None,
    }
}

impl<R: Read> Iterator for Reader<R> {
    type Item = Result<Frame, BadObject>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            match self.inner() {
                Some(Ok(Some(f))) => return Some(Ok(f)),
                Some(Ok(None)) => {}
                Some(Err(reason)) => return self.fail(reason),
                None => match self.next_container() {
                    Ok(true) => {}
                    Ok(false) => {
                        self.done = true;
                        // Bytes left that are not a whole object: the file was cut off.
                        if self.cut || self.data.len() > self.pos + 8 {
                            return self.fail(
                                "the file is cut off: its last object runs past the end".into(),
                            );
                        }
                    }
                    Err(reason) => return self.fail(reason),
                },
            }
        }
        None
    }
}
