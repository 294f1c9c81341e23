//! The top-level records of an MCAP file's data section, in file order, with every chunk
//! checked (CRC) and decompressed. Two ways to meet damage:
//!
//! - strict ([`Scanner::open`]): the first damaged record is an error naming its byte offset
//!   and the cause, and saying that `railfuse recover` salvages the rest;
//! - salvage ([`Scanner::salvage`]): damage becomes an [`Item::Damage`] and reading resumes at
//!   the next intact record after it, found by trying every later byte as a record start and
//!   keeping the first that checks out (a chunk must decompress to its CRC). So one corrupt
//!   chunk in the middle costs that chunk only.
//!
//! Reads are positional (`pread`), through a small read-ahead buffer for the many small
//! records and straight into the record's buffer for chunks.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use mcap::records::{op, ChunkHeader};

use super::format::{self, Records, FRAME, MAGIC};
use crate::error::{Error, Result};

/// One top-level item of the data section.
#[derive(Debug)]
pub enum Item {
    /// A record other than a chunk: schema, channel, message (unchunked files), metadata,
    /// attachment, message index, or an application's private record.
    Record {
        opcode: u8,
        offset: u64,
        body: Vec<u8>,
    },
    /// A chunk, intact.
    Chunk(Chunk),
    /// Bytes that hold no intact record (salvage mode only).
    Damage(Damage),
}

/// A chunk as it stands in the file and decompressed.
#[derive(Debug)]
pub struct Chunk {
    /// File offset of the chunk record.
    pub offset: u64,
    pub header: ChunkHeader,
    /// The whole record as in the file (opcode and length included), for a verbatim copy.
    pub raw: Vec<u8>,
    /// The records it holds, decompressed and CRC-checked.
    pub records: Vec<u8>,
}

/// A stretch of the file that holds no intact record.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Damage {
    pub offset: u64,
    pub length: u64,
    pub cause: String,
}

/// Top-level records that can open a data section record. Candidates when looking for where
/// intact data resumes after damage.
const RESUME_AT: [u8; 7] = [
    op::CHUNK,
    op::SCHEMA,
    op::CHANNEL,
    op::METADATA,
    op::ATTACHMENT,
    op::MESSAGE_INDEX,
    op::DATA_END,
];

pub struct Scanner {
    path: PathBuf,
    file: File,
    size: u64,
    pos: u64,
    salvage: bool,
    done: bool,
    ahead: Vec<u8>,
    ahead_at: u64,
    decompressor: format::Decompressor,
    /// Buffers handed back by the caller, for the next chunks' records.
    spares: Vec<Vec<u8>>,
}

const READ_AHEAD: usize = 64 << 10;

/// Spare buffers kept for reuse.
const SPARES: usize = 8;

impl Scanner {
    /// Reads strictly: damage is an error.
    pub fn open(path: &Path) -> Result<Self> {
        Self::new(path, false)
    }

    /// Reads past damage: it is reported as [`Item::Damage`].
    pub fn salvage(path: &Path) -> Result<Self> {
        Self::new(path, true)
    }

    fn new(path: &Path, salvage: bool) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let size = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if size == 0 {
            return Err(Error::Empty {
                path: path.to_owned(),
            });
        }
        let mut magic = [0u8; 8];
        let n = (size as usize).min(8);
        file.read_exact_at(&mut magic[..n], 0)
            .map_err(|e| Error::io(path, e))?;
        if n < 8 || &magic != MAGIC {
            return Err(Error::mcap(
                path,
                "it does not start with the MCAP magic bytes: not an MCAP file",
            ));
        }
        let mut s = Self {
            path: path.to_owned(),
            file,
            size,
            pos: 8,
            salvage,
            done: false,
            ahead: Vec::new(),
            decompressor: format::Decompressor::new(),
            spares: Vec::new(),
            ahead_at: 0,
        };
        // The header record comes first; it carries nothing railfuse needs.
        match s.frame(8) {
            Ok((op::HEADER, len)) => s.pos = 8 + FRAME as u64 + len,
            Ok((other, _)) => {
                return Err(Error::mcap(
                    path,
                    format!("opens with record 0x{other:02x}, not a header"),
                ))
            }
            Err(cause) => return Err(Error::mcap(path, cause)),
        }
        Ok(s)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// File size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// Where reading has got to.
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// The next item, `None` at the end of the data section.
    #[allow(clippy::should_implement_trait)] // fallible, and ends at the data section's end
    pub fn next(&mut self) -> Option<Result<Item>> {
        if self.done {
            return None;
        }
        let at = self.pos;
        match self.record_at(at) {
            Ok(Some(item)) => Some(Ok(item)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(cause) if !self.salvage => {
                self.done = true;
                Some(Err(Error::Damaged {
                    path: self.path.clone(),
                    offset: at,
                    cause,
                }))
            }
            Err(cause) => {
                let resume = self.resume_after(at);
                self.pos = resume.unwrap_or(self.size);
                self.done = resume.is_none();
                Some(Ok(Item::Damage(Damage {
                    offset: at,
                    length: self.pos - at,
                    cause,
                })))
            }
        }
    }

    /// The record at `at`, moving past it; `None` at the data section's end.
    fn record_at(&mut self, at: u64) -> Result<Option<Item>, String> {
        if at == self.size {
            return Err(format!(
                "the file ends at byte {at} without its summary (truncated: was the recording cut off?)"
            ));
        }
        let (opcode, len) = self.frame(at)?;
        let start = at + FRAME as u64;
        match opcode {
            op::DATA_END | op::FOOTER => return Ok(None),
            op::HEADER
            | op::CHUNK_INDEX
            | op::ATTACHMENT_INDEX
            | op::STATISTICS
            | op::METADATA_INDEX
            | op::SUMMARY_OFFSET => {
                return Err(format!(
                    "record 0x{opcode:02x} does not belong in the data section"
                ))
            }
            0x10..=0x7f => return Err(format!("unknown record opcode 0x{opcode:02x}")),
            _ => {}
        }
        let item = if opcode == op::CHUNK {
            let mut raw = vec![0u8; FRAME + len as usize];
            self.read_at(&mut raw, at)?;
            let (header, records) = self.check_chunk(&raw[FRAME..])?;
            Item::Chunk(Chunk {
                offset: at,
                header,
                raw,
                records,
            })
        } else {
            let mut body = vec![0u8; len as usize];
            self.read_at(&mut body, start)?;
            Item::Record {
                opcode,
                offset: at,
                body,
            }
        };
        self.pos = start + len;
        Ok(Some(item))
    }

    /// A buffer of the caller's to reuse for a later chunk's records.
    pub fn recycle(&mut self, buffer: Vec<u8>) {
        if self.spares.len() < SPARES {
            self.spares.push(buffer);
        }
    }

    /// A chunk record body's header and decompressed, CRC-checked records; also every record
    /// in it must be whole.
    fn check_chunk(&mut self, body: &[u8]) -> Result<(ChunkHeader, Vec<u8>), String> {
        let (header, start) = format::parse_chunk_header(body)?;
        let mut records = self.spares.pop().unwrap_or_default();
        let checked = self
            .decompressor
            .decompress(
                &header,
                &body[start..],
                super::RECORD_LENGTH_LIMIT,
                &mut records,
            )
            .and_then(|()| match Records::new(&records).find(|r| r.is_err()) {
                Some(Err(e)) => Err(format!("chunk content is torn: {e}")),
                _ => Ok(()),
            });
        match checked {
            Ok(()) => Ok((header, records)),
            Err(e) => {
                self.recycle(records);
                Err(e)
            }
        }
    }

    /// Opcode and body length of the record at `at`, checked against the file's size.
    fn frame(&mut self, at: u64) -> Result<(u8, u64), String> {
        if self.size - at < FRAME as u64 {
            return Err(format!(
                "the file ends in the middle of a record at byte {at} (truncated: was the recording cut off?)"
            ));
        }
        let mut frame = [0u8; FRAME];
        self.read_at(&mut frame, at)?;
        let len = u64::from_le_bytes(frame[1..].try_into().expect("8 bytes"));
        if len > self.size - at - FRAME as u64 {
            return Err(format!(
                "the record at byte {at} runs past the end of the file (truncated: was the recording cut off?)"
            ));
        }
        if len > super::RECORD_LENGTH_LIMIT as u64 {
            return Err(format!(
                "the record at byte {at} claims {len} bytes, over the limit"
            ));
        }
        Ok((frame[0], len))
    }

    /// The first offset after `at` where an intact record starts, if any.
    fn resume_after(&mut self, at: u64) -> Option<u64> {
        let mut q = at + 1;
        while q + FRAME as u64 <= self.size {
            let mut byte = [0u8; 1];
            self.read_at(&mut byte, q).ok()?;
            if RESUME_AT.contains(&byte[0]) && self.intact_at(q) {
                return Some(q);
            }
            q += 1;
        }
        None
    }

    /// Whether a record that checks out starts at `q`.
    fn intact_at(&mut self, q: u64) -> bool {
        let Ok((opcode, len)) = self.frame(q) else {
            return false;
        };
        if opcode == op::CHUNK {
            // The header alone rules out almost every false start before reading a body.
            let mut head = vec![0u8; (len as usize).min(4096)];
            if self.read_at(&mut head, q + FRAME as u64).is_err() {
                return false;
            }
            let mut cursor = std::io::Cursor::new(&head[..]);
            let parsed: Result<ChunkHeader, _> = binrw::BinRead::read_le(&mut cursor);
            match parsed {
                Ok(h) if h.compressed_size == len - cursor.position() => {}
                _ => return false,
            }
        }
        let mut body = vec![0u8; len as usize];
        if self.read_at(&mut body, q + FRAME as u64).is_err() {
            return false;
        }
        match opcode {
            op::CHUNK => self.check_chunk(&body).is_ok(),
            op::MESSAGE_INDEX => {
                body.len() >= 6 && {
                    let n = u32::from_le_bytes(body[2..6].try_into().expect("4 bytes")) as usize;
                    n == body.len() - 6 && n.is_multiple_of(16)
                }
            }
            op::DATA_END => len == 4 && self.ends_with_magic(),
            op::SCHEMA | op::CHANNEL | op::METADATA | op::ATTACHMENT => {
                parses_exactly(opcode, &body)
            }
            _ => false,
        }
    }

    fn ends_with_magic(&mut self) -> bool {
        let mut tail = [0u8; 8];
        self.size >= 16 && self.read_at(&mut tail, self.size - 8).is_ok() && &tail == MAGIC
    }

    fn read_at(&mut self, buf: &mut [u8], at: u64) -> Result<(), String> {
        let end = at + buf.len() as u64;
        if at >= self.ahead_at && end <= self.ahead_at + self.ahead.len() as u64 {
            let i = (at - self.ahead_at) as usize;
            buf.copy_from_slice(&self.ahead[i..i + buf.len()]);
            return Ok(());
        }
        if buf.len() >= READ_AHEAD {
            return self.file.read_exact_at(buf, at).map_err(|e| e.to_string());
        }
        let n = READ_AHEAD.min((self.size - at) as usize);
        self.ahead.resize(n, 0);
        self.file
            .read_exact_at(&mut self.ahead, at)
            .map_err(|e| e.to_string())?;
        self.ahead_at = at;
        buf.copy_from_slice(&self.ahead[..buf.len()]);
        Ok(())
    }
}

/// Whether `body` parses as an `opcode` record and the parse uses every byte.
fn parses_exactly(opcode: u8, body: &[u8]) -> bool {
    use mcap::records::Record;
    match mcap::parse_record(opcode, body) {
        Ok(Record::Schema { header, data }) => {
            body.len() == 2 + 4 + header.name.len() + 4 + header.encoding.len() + 4 + data.len()
        }
        Ok(Record::Channel(c)) => {
            let meta: usize = c.metadata.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
            body.len() == 2 + 2 + 4 + c.topic.len() + 4 + c.message_encoding.len() + 4 + meta
        }
        Ok(Record::Metadata(m)) => {
            let meta: usize = m.metadata.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
            body.len() == 4 + m.name.len() + 4 + meta
        }
        Ok(Record::Attachment { header, data, crc }) => {
            let fields = 8 + 8 + 4 + header.name.len() + 4 + header.media_type.len() + 8;
            body.len() == fields + data.len() + 4
                && (crc == 0 || crc == crc32fast::hash(&body[..fields + data.len()]))
        }
        _ => false,
    }
}

/// A [`Scanner`] running on its own thread, ahead of the caller: reading and decompressing
/// overlap the caller's work. Memory is bounded by a budget of bytes in flight (raw and
/// decompressed), not by a count of items, so that many small chunks keep the reader far
/// enough ahead to absorb the caller's bursts while a few big ones cannot exhaust memory.
pub struct ReadAhead {
    items: std::sync::mpsc::Receiver<Sent>,
    budget: std::sync::Arc<Budget>,
    /// Buffers going back to the reader for reuse.
    spares: std::sync::mpsc::Sender<Vec<u8>>,
    position: u64,
    size: u64,
    /// The file of the item last returned, as an index into those read.
    file: usize,
}

/// An item as the reader thread sends it: with the position reached (over all files read so
/// far), its weight in the budget and the index of its file.
struct Sent {
    item: Result<Item>,
    position: u64,
    weight: usize,
    file: usize,
}

/// Bytes read ahead and not yet handed to the caller.
struct Budget {
    /// Bytes in flight, and whether the caller has gone.
    state: std::sync::Mutex<(usize, bool)>,
    freed: std::sync::Condvar,
    limit: usize,
}

impl Budget {
    /// Waits until `bytes` more fit (one item always fits when nothing is in flight); false
    /// when the caller has gone.
    fn take(&self, bytes: usize) -> bool {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        while !state.1 && state.0 > 0 && state.0 + bytes > self.limit {
            state = self.freed.wait(state).unwrap_or_else(|e| e.into_inner());
        }
        state.0 += bytes;
        !state.1
    }

    fn give_back(&self, bytes: usize) {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.0 = state.0.saturating_sub(bytes);
        self.freed.notify_one();
    }

    fn close(&self) {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).1 = true;
        self.freed.notify_one();
    }
}

impl Drop for ReadAhead {
    fn drop(&mut self) {
        self.budget.close();
    }
}

impl Item {
    /// Bytes it holds.
    fn weight(&self) -> usize {
        match self {
            Item::Record { body, .. } => body.len(),
            Item::Chunk(c) => c.raw.len() + c.records.len(),
            Item::Damage(_) => 0,
        }
    }
}

/// The default read-ahead budget: a few dozen typical chunks.
pub const READ_AHEAD_BYTES: usize = 2 << 20;

impl ReadAhead {
    /// Reads `scanner` ahead by up to `budget` bytes.
    pub fn new(scanner: Scanner, budget: usize) -> Self {
        let size = scanner.size();
        Self::spawn(scanner, Vec::new(), size, budget)
    }

    /// Reads `files` strictly, one after the other as if they were one, ahead by up to
    /// `budget` bytes: the next file is read while the caller finishes the last, on the
    /// same thread and in the same budget, so that a run split in many parts costs what one
    /// file does. A file that cannot be opened is an error item where it would begin.
    pub fn files(files: &[&Path], budget: usize) -> Result<Self> {
        let Some((first, rest)) = files.split_first() else {
            return Err(Error::Run {
                path: PathBuf::new(),
                cause: "no file to read".into(),
            });
        };
        let scanner = Scanner::open(first)?;
        let mut size = scanner.size();
        for path in rest {
            size += std::fs::metadata(path)
                .map_err(|e| Error::io(path, e))?
                .len();
        }
        let rest = rest.iter().map(|p| p.to_path_buf()).collect();
        Ok(Self::spawn(scanner, rest, size, budget))
    }

    fn spawn(mut scanner: Scanner, rest: Vec<PathBuf>, size: u64, budget: usize) -> Self {
        // The count bound only backs up the byte budget (many tiny records).
        let (tx, items) = std::sync::mpsc::sync_channel(4096);
        let budget = std::sync::Arc::new(Budget {
            state: std::sync::Mutex::new((0, false)),
            freed: std::sync::Condvar::new(),
            limit: budget,
        });
        let reader_budget = budget.clone();
        let (spares, returned) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("log-reader".into())
            .spawn(move || {
                let mut rest = rest.into_iter();
                let (mut file, mut before) = (0, 0);
                loop {
                    for buffer in returned.try_iter() {
                        scanner.recycle(buffer);
                    }
                    let item = match scanner.next() {
                        Some(item) => item,
                        None => {
                            let Some(path) = rest.next() else { break };
                            before += scanner.size();
                            file += 1;
                            match Scanner::open(&path) {
                                Ok(mut next) => {
                                    next.spares = std::mem::take(&mut scanner.spares);
                                    scanner = next;
                                    continue;
                                }
                                Err(e) => Err(e),
                            }
                        }
                    };
                    let failed = item.is_err();
                    let weight = item.as_ref().map_or(0, Item::weight);
                    let position = before + scanner.position();
                    let sent = reader_budget.take(weight)
                        && tx
                            .send(Sent {
                                item,
                                position,
                                weight,
                                file,
                            })
                            .is_ok();
                    if !sent || (failed && !scanner.salvage) {
                        break; // the reader was dropped, or the read cannot go on
                    }
                }
            })
            .expect("a thread to read ahead");
        Self {
            items,
            budget,
            spares,
            position: 0,
            size,
            file: 0,
        }
    }

    /// Gives a chunk's records buffer back, for a later chunk (saves allocating and
    /// faulting in fresh memory for every chunk).
    pub fn recycle(&self, buffer: Vec<u8>) {
        let _ = self.spares.send(buffer); // the reader may have finished
    }

    /// Bytes read up to the item last returned, over all files.
    pub fn position(&self) -> u64 {
        self.position
    }

    /// Bytes of all files.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The file of the item last returned (0 for the first).
    pub fn file(&self) -> usize {
        self.file
    }
}

impl Iterator for ReadAhead {
    type Item = Result<Item>;

    fn next(&mut self) -> Option<Result<Item>> {
        let sent = self.items.recv().ok()?;
        self.position = sent.position;
        self.file = sent.file;
        // Handed over: the caller's to keep or drop from here on.
        self.budget.give_back(sent.weight);
        Some(sent.item)
    }
}
