//! The records of a ROS 1 bag (format 2.0): each a header (fields `name=value`, each with
//! its length) and data, both with their length. Read streaming from the file's start, so a
//! bag without its index (a recording that did not finish) reads the same as one with it.
//! Every length is checked against the bytes left and a bound before anything is allocated.

use std::io::{BufRead, Read};

/// The bag's first line.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// Longest record header read (a connection's fields; its definition is in the data).
pub const MAX_HEADER: u32 = 1 << 20;
/// Largest record data read, and largest chunk once decompressed (rosbag writes 768 KiB
/// chunks by default; a bag recorded with a larger `--chunksize` still fits).
pub const MAX_DATA: u32 = 256 << 20;

pub const OP_MESSAGE: u8 = 0x02;
pub const OP_BAG_HEADER: u8 = 0x03;
pub const OP_INDEX: u8 = 0x04;
pub const OP_CHUNK: u8 = 0x05;
pub const OP_CHUNK_INFO: u8 = 0x06;
pub const OP_CONNECTION: u8 = 0x07;

/// A record's header fields.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Fields(pub Vec<(String, Vec<u8>)>);

impl Fields {
    /// Parses a header: fields of `u32 length` then `name=value`.
    pub fn parse(mut bytes: &[u8]) -> Result<Self, String> {
        let mut fields = Vec::new();
        while !bytes.is_empty() {
            let len = take_u32(&mut bytes).ok_or("a header field's length is cut off")? as usize;
            if len > bytes.len() {
                return Err(format!(
                    "a header field of {len} bytes runs past its header"
                ));
            }
            let (field, rest) = bytes.split_at(len);
            bytes = rest;
            let eq = field
                .iter()
                .position(|b| *b == b'=')
                .ok_or("a header field without '='")?;
            let name = String::from_utf8_lossy(&field[..eq]).into_owned();
            fields.push((name, field[eq + 1..].to_vec()));
        }
        Ok(Self(fields))
    }

    pub fn get(&self, name: &str) -> Option<&[u8]> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| &v[..])
    }

    pub fn op(&self) -> Option<u8> {
        self.get("op").filter(|v| v.len() == 1).map(|v| v[0])
    }

    pub fn u32(&self, name: &str) -> Option<u32> {
        let v = self.get(name)?;
        Some(u32::from_le_bytes(v.try_into().ok()?))
    }

    pub fn u64(&self, name: &str) -> Option<u64> {
        let v = self.get(name)?;
        Some(u64::from_le_bytes(v.try_into().ok()?))
    }

    pub fn text(&self, name: &str) -> Option<String> {
        self.get(name)
            .map(|v| String::from_utf8_lossy(v).into_owned())
    }

    /// A message record's time (`uint32 secs`, `uint32 nsecs`) in ns since the epoch.
    pub fn time_ns(&self, name: &str) -> Option<u64> {
        let v = self.get(name).filter(|v| v.len() == 8)?;
        let secs = u32::from_le_bytes(v[..4].try_into().ok()?);
        let nsecs = u32::from_le_bytes(v[4..].try_into().ok()?);
        (nsecs < 1_000_000_000).then(|| u64::from(secs) * 1_000_000_000 + u64::from(nsecs))
    }
}

fn take_u32(bytes: &mut &[u8]) -> Option<u32> {
    let (head, rest) = bytes.split_first_chunk::<4>()?;
    *bytes = rest;
    Some(u32::from_le_bytes(*head))
}

/// One record: its header fields and data, and the byte it starts at.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub offset: u64,
    pub fields: Fields,
    pub data: Vec<u8>,
}

/// Why the records stop before the end of the file.
#[derive(Debug, Clone, PartialEq)]
pub enum Stop {
    /// The file ends inside a record: cut off (what came before is kept).
    CutOff(String),
    /// A record that cannot be a record (a length past any bound).
    Damaged(String),
    Io(String),
}

/// The records of a bag file in file order.
pub struct BagRecords<R> {
    reader: R,
    offset: u64,
    /// Bytes of the file (a length is checked against what is left).
    size: u64,
}

impl<R: BufRead> BagRecords<R> {
    /// After the magic line: the caller has checked it.
    pub fn new(reader: R, size: u64) -> Self {
        Self {
            reader,
            offset: MAGIC.len() as u64,
            size,
        }
    }

    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The reader stands at byte `offset` of the file (it was seeked there).
    pub fn skip_to(&mut self, offset: u64) {
        self.offset = offset;
    }

    /// The next record, `Ok(None)` at the end of the file.
    pub fn next_record(&mut self) -> Result<Option<Record>, Stop> {
        let offset = self.offset;
        if self
            .reader
            .fill_buf()
            .map_err(|e| Stop::Io(e.to_string()))?
            .is_empty()
        {
            return Ok(None);
        }
        let header = self.block(offset, "header", MAX_HEADER)?;
        let fields = Fields::parse(&header)
            .map_err(|e| Stop::Damaged(format!("byte {offset}: record header: {e}")))?;
        let data = self.block(offset, "data", MAX_DATA)?;
        Ok(Some(Record {
            offset,
            fields,
            data,
        }))
    }

    /// A length and that many bytes.
    fn block(&mut self, record: u64, what: &str, bound: u32) -> Result<Vec<u8>, Stop> {
        let mut len = [0u8; 4];
        self.read_exact(&mut len, record, what)?;
        let len = u32::from_le_bytes(len);
        let left = self.size.saturating_sub(self.offset);
        if u64::from(len) > left {
            return Err(Stop::CutOff(format!(
                "byte {record}: the record's {what} of {len} bytes runs past the end of the file ({left} bytes left): cut off"
            )));
        }
        if len > bound {
            return Err(Stop::Damaged(format!(
                "byte {record}: the record's {what} claims {len} bytes, more than {} MiB",
                bound >> 20
            )));
        }
        let mut buf = vec![0u8; len as usize];
        self.read_exact(&mut buf, record, what)?;
        Ok(buf)
    }

    fn read_exact(&mut self, buf: &mut [u8], record: u64, what: &str) -> Result<(), Stop> {
        match self.reader.read_exact(buf) {
            Ok(()) => {
                self.offset += buf.len() as u64;
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Err(Stop::CutOff(format!(
                "byte {record}: the file ends inside the record's {what}: cut off"
            ))),
            Err(e) => Err(Stop::Io(e.to_string())),
        }
    }
}

/// The records inside a chunk's (decompressed) data.
pub fn chunk_records(
    data: &[u8],
    chunk_offset: u64,
) -> impl Iterator<Item = Result<Record, String>> + '_ {
    let mut rest = data;
    let mut failed = false;
    std::iter::from_fn(move || {
        if rest.is_empty() || failed {
            return None;
        }
        let at = data.len() - rest.len();
        let mut next = || -> Result<Record, String> {
            let mut block = |what: &str| -> Result<Vec<u8>, String> {
                let len = take_u32(&mut rest).ok_or(format!("its {what} length is cut off"))?;
                if len as usize > rest.len() {
                    return Err(format!("its {what} of {len} bytes runs past the chunk"));
                }
                let (b, r) = rest.split_at(len as usize);
                rest = r;
                Ok(b.to_vec())
            };
            let header = block("header")?;
            let data = block("data")?;
            Ok(Record {
                offset: at as u64,
                fields: Fields::parse(&header)?,
                data,
            })
        };
        let r = next().map_err(|e| format!("chunk at byte {chunk_offset}, record at {at}: {e}"));
        failed = r.is_err();
        Some(r)
    })
}

/// A chunk's data decompressed (`none`, `bz2` or `lz4`), no longer than its stated `size`
/// (itself at most [`MAX_DATA`]).
pub fn decompress(compression: &str, data: &[u8], size: u32) -> Result<Vec<u8>, String> {
    if size > MAX_DATA {
        return Err(format!(
            "it claims {size} bytes decompressed, more than {} MiB",
            MAX_DATA >> 20
        ));
    }
    let mut out = Vec::with_capacity((size as usize).min(16 << 20));
    // One byte past the stated size tells a chunk that says less than it holds.
    let limit = u64::from(size) + 1;
    let read = match compression {
        "none" => {
            out.extend_from_slice(&data[..data.len().min(limit as usize)]);
            Ok(out.len())
        }
        "bz2" => bzip2::read::BzDecoder::new(data)
            .take(limit)
            .read_to_end(&mut out),
        "lz4" => lz4::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out)),
        other => return Err(format!("compression '{other}' (none, bz2 or lz4)")),
    };
    read.map_err(|e| format!("{compression} does not decompress: {e}"))?;
    if out.len() != size as usize {
        return Err(format!(
            "{} bytes decompressed where its header says {size}",
            out.len()
        ));
    }
    Ok(out)
}
