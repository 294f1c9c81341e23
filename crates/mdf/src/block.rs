//! An MDF 4 block: a 24-byte header (`##XX`, 4 reserved bytes, the block's length, its link
//! count), its links (file offsets, 0 for none) and its data. Every length is checked against
//! the file's size and a bound before it is read.

use std::io::{Read, Seek, SeekFrom};

use crate::{MdfError, Result};

/// The largest block of the file's tree (texts, channels, conversions, lists) read whole.
pub const MAX_TREE_BLOCK: u64 = 16 << 20;
/// The header's bytes.
pub const HEADER: u64 = 24;

/// A block's header and links; its data (for tree blocks) read whole.
#[derive(Debug, Clone)]
pub struct Block {
    pub offset: u64,
    pub id: [u8; 4],
    /// The block's length, header included.
    pub length: u64,
    pub links: Vec<u64>,
    pub data: Vec<u8>,
}

impl Block {
    /// The id as text (`##DG`).
    pub fn id(&self) -> String {
        String::from_utf8_lossy(&self.id).into_owned()
    }

    pub fn link(&self, i: usize) -> u64 {
        self.links.get(i).copied().unwrap_or(0)
    }

    /// Where its data begins in the file.
    pub fn data_offset(&self) -> u64 {
        self.offset + HEADER + 8 * self.links.len() as u64
    }

    /// Bytes of its data, by the header's length.
    pub fn data_length(&self) -> u64 {
        self.length
            .saturating_sub(HEADER + 8 * self.links.len() as u64)
    }

    pub fn u8(&self, at: usize) -> u8 {
        self.data.get(at).copied().unwrap_or(0)
    }
    pub fn u16(&self, at: usize) -> u16 {
        u16::from_le_bytes(self.bytes::<2>(at))
    }
    pub fn u32(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.bytes::<4>(at))
    }
    pub fn u64(&self, at: usize) -> u64 {
        u64::from_le_bytes(self.bytes::<8>(at))
    }
    pub fn i16(&self, at: usize) -> i16 {
        i16::from_le_bytes(self.bytes::<2>(at))
    }
    pub fn f64(&self, at: usize) -> f64 {
        f64::from_le_bytes(self.bytes::<8>(at))
    }
    /// `N` bytes at `at`, zeros past the data's end (a short block reads as zeros there, as
    /// older versions' blocks end before newer fields).
    fn bytes<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut out = [0u8; N];
        if let Some(b) = self.data.get(at..) {
            let n = b.len().min(N);
            out[..n].copy_from_slice(&b[..n]);
        }
        out
    }
}

/// Reads the block at `offset` of a file of `file_len` bytes: its header and links, and its
/// data when `with_data` (bounded by [`MAX_TREE_BLOCK`]).
pub fn read<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    offset: u64,
    with_data: bool,
) -> Result<Block> {
    if offset < 64 || offset.saturating_add(HEADER) > file_len {
        return Err(MdfError::at(
            offset,
            format!("a link to byte {offset}, outside the file of {file_len} bytes"),
        ));
    }
    file.seek(SeekFrom::Start(offset))?;
    let mut head = [0u8; HEADER as usize];
    file.read_exact(&mut head)?;
    let id: [u8; 4] = head[0..4].try_into().expect("4 bytes");
    if &id[0..2] != b"##" {
        return Err(MdfError::at(offset, "not a block (no ## at a link's end)"));
    }
    let length = u64::from_le_bytes(head[8..16].try_into().expect("8 bytes"));
    let link_count = u64::from_le_bytes(head[16..24].try_into().expect("8 bytes"));
    let id_text = String::from_utf8_lossy(&id).into_owned();
    if length < HEADER || link_count > (length - HEADER) / 8 {
        return Err(MdfError::at(
            offset,
            format!("{id_text} claims {link_count} links in a block of {length} bytes"),
        ));
    }
    let links_len = 8 * link_count;
    if links_len > MAX_TREE_BLOCK {
        return Err(MdfError::at(
            offset,
            format!("{id_text} claims {link_count} links"),
        ));
    }
    let mut raw = vec![0u8; links_len as usize];
    file.read_exact(&mut raw)
        .map_err(|_| MdfError::at(offset, format!("{id_text} is cut off in its links")))?;
    let links = raw
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let mut block = Block {
        offset,
        id,
        length,
        links,
        data: Vec::new(),
    };
    if with_data {
        let n = block.data_length();
        if n > MAX_TREE_BLOCK || block.data_offset() + n > file_len {
            return Err(MdfError::at(
                offset,
                format!(
                    "{id_text} claims {length} bytes{}",
                    if n > MAX_TREE_BLOCK {
                        " (more than a tree block can hold)"
                    } else {
                        ", past the file's end"
                    }
                ),
            ));
        }
        block.data = vec![0u8; n as usize];
        file.read_exact(&mut block.data)?;
    }
    Ok(block)
}

/// The text of a TX or MD block (its XML for MD), or empty for no link.
pub fn text<F: Read + Seek>(file: &mut F, file_len: u64, offset: u64) -> Result<String> {
    if offset == 0 {
        return Ok(String::new());
    }
    let b = read(file, file_len, offset, true)?;
    if &b.id != b"##TX" && &b.id != b"##MD" {
        return Err(MdfError::at(
            offset,
            format!("{} where a text was linked", b.id()),
        ));
    }
    let end = b.data.iter().position(|&c| c == 0).unwrap_or(b.data.len());
    Ok(String::from_utf8_lossy(&b.data[..end]).trim().to_owned())
}
