//! MCAP at the byte level: records framed as opcode, length and body; the records inside a
//! chunk; chunk compression. The record types themselves are the `mcap` crate's
//! ([`mcap::records`]), serialised with `binrw` as that crate does.
//!
//! Why railfuse frames records itself: `refuse` and `recover` copy the input's chunks into the
//! output byte for byte (no decompress-recompress of data nobody changed), and `recover`
//! steps past a damaged chunk to the intact ones after it. The `mcap` crate's writer and
//! readers offer neither (0.26), so the framing lives here and the `mcap` crate keeps the
//! record layouts.

use std::io::Cursor;

use binrw::BinWrite;
use mcap::records::{op, ChunkHeader, MessageHeader};

/// The magic bytes at both ends of an MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Opcode and length in front of every record body.
pub const FRAME: usize = 9;
/// A message record's fixed header: channel id, sequence, log time, publish time.
pub const MESSAGE_HEADER: usize = 22;

/// Appends one record to `out`.
pub fn put_record(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
    out.push(opcode);
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
}

/// A `binrw` record body, serialised.
pub fn body<T>(value: &T) -> Vec<u8>
where
    T: for<'a> BinWrite<Args<'a> = ()>,
{
    let mut out = Vec::new();
    value
        .write_le(&mut Cursor::new(&mut out))
        .expect("writing to a Vec cannot fail");
    out
}

/// Appends a message record (as it sits inside a chunk) to `out`.
pub fn put_message(out: &mut Vec<u8>, header: &MessageHeader, data: &[u8]) {
    out.push(op::MESSAGE);
    out.extend_from_slice(&((MESSAGE_HEADER + data.len()) as u64).to_le_bytes());
    out.extend_from_slice(&header.channel_id.to_le_bytes());
    out.extend_from_slice(&header.sequence.to_le_bytes());
    out.extend_from_slice(&header.log_time.to_le_bytes());
    out.extend_from_slice(&header.publish_time.to_le_bytes());
    out.extend_from_slice(data);
}

/// A message record's header and payload, borrowed from its chunk.
#[derive(Debug, Clone, Copy)]
pub struct MessageView<'a> {
    pub header: MessageHeader,
    pub data: &'a [u8],
}

/// Reads a message record body; `None` if it is shorter than the fixed header.
pub fn parse_message(body: &[u8]) -> Option<MessageView<'_>> {
    if body.len() < MESSAGE_HEADER {
        return None;
    }
    let u64_at = |i: usize| u64::from_le_bytes(body[i..i + 8].try_into().expect("8 bytes"));
    Some(MessageView {
        header: MessageHeader {
            channel_id: u16::from_le_bytes([body[0], body[1]]),
            sequence: u32::from_le_bytes(body[2..6].try_into().expect("4 bytes")),
            log_time: u64_at(6),
            publish_time: u64_at(14),
        },
        data: &body[MESSAGE_HEADER..],
    })
}

/// One framed record inside a buffer: its opcode, where it starts, and its body.
#[derive(Debug, Clone, Copy)]
pub struct Framed<'a> {
    pub opcode: u8,
    pub offset: usize,
    pub body: &'a [u8],
}

/// The records of a decompressed chunk, in order. A record running past the end of the
/// buffer ends the walk with an error.
pub struct Records<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Records<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
}

impl<'a> Iterator for Records<'a> {
    type Item = Result<Framed<'a>, String>;

    fn next(&mut self) -> Option<Self::Item> {
        let rest = &self.data[self.pos..];
        if rest.is_empty() {
            return None;
        }
        if rest.len() < FRAME {
            self.pos = self.data.len();
            return Some(Err(format!(
                "a record header is cut off at byte {}",
                self.pos
            )));
        }
        let len = u64::from_le_bytes(rest[1..FRAME].try_into().expect("8 bytes"));
        if len > (rest.len() - FRAME) as u64 {
            let at = self.pos;
            self.pos = self.data.len();
            return Some(Err(format!(
                "a record at byte {at} runs past the end of its chunk"
            )));
        }
        let framed = Framed {
            opcode: rest[0],
            offset: self.pos,
            body: &rest[FRAME..FRAME + len as usize],
        };
        self.pos += FRAME + len as usize;
        Some(Ok(framed))
    }
}

/// A chunk record's header and where its compressed records start within the record body.
pub fn parse_chunk_header(body: &[u8]) -> Result<(ChunkHeader, usize), String> {
    let mut cursor = Cursor::new(body);
    let header: ChunkHeader = binrw::BinRead::read_le(&mut cursor)
        .map_err(|e| format!("chunk header does not parse: {e}"))?;
    let start = cursor.position() as usize;
    if header.compressed_size != (body.len() - start) as u64 {
        return Err(format!(
            "chunk says {} compressed bytes but holds {}",
            header.compressed_size,
            body.len() - start
        ));
    }
    Ok((header, start))
}

/// Decompresses a chunk's records and checks them against the chunk's size and CRC. `limit`
/// bounds the size a damaged or hostile header can make us allocate.
pub fn decompress(header: &ChunkHeader, data: &[u8], limit: usize) -> Result<Vec<u8>, String> {
    let mut records = Vec::new();
    Decompressor::new().decompress(header, data, limit, &mut records)?;
    Ok(records)
}

/// Decompresses chunk after chunk with one zstd context, into buffers the caller reuses.
pub struct Decompressor {
    zstd: Option<zstd::bulk::Decompressor<'static>>,
}

impl Default for Decompressor {
    fn default() -> Self {
        Self::new()
    }
}

impl Decompressor {
    pub fn new() -> Self {
        // A context that cannot be made is made again, and reported, at the first zstd chunk.
        Self {
            zstd: zstd::bulk::Decompressor::new().ok(),
        }
    }

    /// [`decompress`] into `records` (cleared first, its capacity reused).
    pub fn decompress(
        &mut self,
        header: &ChunkHeader,
        data: &[u8],
        limit: usize,
        records: &mut Vec<u8>,
    ) -> Result<(), String> {
        let size = usize::try_from(header.uncompressed_size).unwrap_or(usize::MAX);
        if size > limit {
            return Err(format!(
                "chunk claims {size} bytes uncompressed, over the {limit}-byte limit"
            ));
        }
        records.clear();
        match header.compression.as_str() {
            "" => records.extend_from_slice(data),
            "zstd" => {
                let zstd = match &mut self.zstd {
                    Some(z) => z,
                    None => self
                        .zstd
                        .insert(zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?),
                };
                records.reserve(size);
                zstd.decompress_to_buffer(data, records)
                    .map_err(|e| format!("zstd: {e}"))?;
            }
            "lz4" => {
                use std::io::Read;
                records.reserve(size);
                lz4::Decoder::new(data)
                    .and_then(|d| d.take(size as u64 + 1).read_to_end(records))
                    .map_err(|e| format!("lz4: {e}"))?;
            }
            other => return Err(format!("unknown chunk compression '{other}'")),
        }
        if records.len() != size {
            return Err(format!(
                "chunk decompresses to {} bytes, not {size}",
                records.len()
            ));
        }
        if header.uncompressed_crc != 0 {
            let crc = crc32fast::hash(records);
            if crc != header.uncompressed_crc {
                return Err(format!(
                    "chunk CRC mismatch (stored {:08x}, computed {crc:08x})",
                    header.uncompressed_crc
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_record_reads_back_and_the_walk_stops_at_a_cut() {
        let mut buf = Vec::new();
        let h = MessageHeader {
            channel_id: 7,
            sequence: 3,
            log_time: 11,
            publish_time: 10,
        };
        put_message(&mut buf, &h, b"{}");
        put_record(&mut buf, op::METADATA, b"xyz");
        let got: Vec<_> = Records::new(&buf).collect::<Result<_, _>>().unwrap();
        assert_eq!(got.len(), 2);
        let m = parse_message(got[0].body).unwrap();
        assert_eq!((m.header, m.data), (h, &b"{}"[..]));
        assert_eq!((got[1].opcode, got[1].body), (op::METADATA, &b"xyz"[..]));
        let cut = &buf[..buf.len() - 1];
        assert!(Records::new(cut).nth(1).unwrap().is_err());
    }
}
