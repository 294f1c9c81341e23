//! A data group's data (or a channel's signal data) as one byte stream: the DT, SD and DV
//! blocks a DL or HL list names, in order, and DZ blocks inflated (deflate, or transposed
//! deflate: the records' bytes stored column by column). A DZ inflates to at most
//! [`MAX_INFLATED`]; a block that claims to run past the file's end is read to the end and
//! said (an unfinalised or cut-off file).

use std::collections::HashSet;
use std::io::{Read, Seek, SeekFrom};

use flate2::read::ZlibDecoder;

use crate::block;
use crate::{MdfError, Result};

/// The most one DZ block may inflate to (loggers write 4 MiB or less).
pub const MAX_INFLATED: u64 = 64 << 20;
/// The most data blocks one list may name.
pub const MAX_FRAGMENTS: usize = 1 << 20;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Fragment {
    Raw {
        offset: u64,
        len: u64,
    },
    Zipped {
        offset: u64,
        compressed: u64,
        original: u64,
        columns: Option<u32>,
        block: u64,
    },
}

/// The byte stream of a data link.
pub struct DataStream<F> {
    file: F,
    fragments: Vec<Fragment>,
    next: usize,
    /// The current raw fragment's place and what is left of it.
    raw: Option<(u64, u64)>,
    inflated: Vec<u8>,
    at: usize,
    /// Where the data was found damaged or cut off (read up to there).
    pub damage: Option<String>,
}

impl<F: Read + Seek> DataStream<F> {
    /// The stream of the data blocks from `first` (0: none). `open_ended`: the last DT block's
    /// length was not updated (an unfinalised file's flag): it runs to the file's end.
    pub fn new(mut file: F, file_len: u64, first: u64, open_ended: bool) -> Result<Self> {
        let mut fragments = Vec::new();
        let mut damage = None;
        let mut seen = HashSet::new();
        if first != 0 {
            collect(
                &mut file,
                file_len,
                first,
                &mut fragments,
                &mut seen,
                &mut damage,
            )?;
        }
        if open_ended {
            if let Some(Fragment::Raw { offset, len }) = fragments.last_mut() {
                *len = file_len - *offset;
            }
        }
        Ok(Self {
            file,
            fragments,
            next: 0,
            raw: None,
            inflated: Vec::new(),
            at: 0,
            damage,
        })
    }

    /// Moves to the next fragment; false at the end.
    fn advance(&mut self) -> std::io::Result<bool> {
        let Some(&f) = self.fragments.get(self.next) else {
            return Ok(false);
        };
        self.next += 1;
        self.inflated.clear();
        self.at = 0;
        self.raw = None;
        match f {
            Fragment::Raw { offset, len } => {
                self.file.seek(SeekFrom::Start(offset))?;
                self.raw = Some((offset, len));
            }
            Fragment::Zipped {
                offset,
                compressed,
                original,
                columns,
                block,
            } => {
                self.file.seek(SeekFrom::Start(offset))?;
                let mut z = ZlibDecoder::new((&mut self.file).take(compressed));
                let got = (&mut z).take(original + 1).read_to_end(&mut self.inflated);
                if got.is_err() || self.inflated.len() as u64 != original {
                    let why = format!(
                        "byte {block}: a DZ block that does not inflate to its {original} bytes"
                    );
                    self.damage.get_or_insert(why);
                    self.fragments.truncate(self.next);
                    self.inflated.clear();
                    return Ok(false);
                }
                if let Some(cols) = columns.filter(|c| *c > 1) {
                    untranspose(&mut self.inflated, cols as usize);
                }
            }
        }
        Ok(true)
    }
}

impl<F: Read + Seek> Read for DataStream<F> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        loop {
            if let Some((_, left)) = self.raw.as_mut() {
                if *left > 0 {
                    let n = (*left).min(out.len() as u64) as usize;
                    let n = self.file.read(&mut out[..n])?;
                    if n == 0 {
                        *left = 0;
                        continue;
                    }
                    *left -= n as u64;
                    return Ok(n);
                }
            } else if self.at < self.inflated.len() {
                let n = (self.inflated.len() - self.at).min(out.len());
                out[..n].copy_from_slice(&self.inflated[self.at..self.at + n]);
                self.at += n;
                return Ok(n);
            }
            if !self.advance()? {
                return Ok(0);
            }
        }
    }
}

/// Transposed data back into records: `columns` bytes a record, the first `rows · columns`
/// bytes stored column by column, any rest as it is.
fn untranspose(data: &mut Vec<u8>, columns: usize) {
    let rows = data.len() / columns;
    let body = rows * columns;
    let mut out = vec![0u8; data.len()];
    for c in 0..columns {
        for r in 0..rows {
            out[r * columns + c] = data[c * rows + r];
        }
    }
    out[body..].copy_from_slice(&data[body..]);
    *data = out;
}

/// The data blocks a link leads to, in order.
fn collect<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    offset: u64,
    out: &mut Vec<Fragment>,
    seen: &mut HashSet<u64>,
    damage: &mut Option<String>,
) -> Result<()> {
    if !seen.insert(offset) {
        return Err(MdfError::at(
            offset,
            "a data list that links back to itself",
        ));
    }
    if out.len() >= MAX_FRAGMENTS {
        return Err(MdfError::at(
            offset,
            format!("more than {MAX_FRAGMENTS} data blocks"),
        ));
    }
    let head = block::read(file, file_len, offset, false)?;
    match &head.id {
        b"##DT" | b"##SD" | b"##DV" | b"##RD" => {
            let start = head.data_offset();
            let mut len = head.data_length();
            if start + len > file_len {
                damage.get_or_insert(format!(
                    "byte {offset}: {} claims {} bytes past the file's end (cut off, or not \
                     finalised): read to the end",
                    head.id(),
                    start + len - file_len
                ));
                len = file_len.saturating_sub(start);
            }
            out.push(Fragment::Raw { offset: start, len });
        }
        b"##DZ" => {
            if let Some(f) = zipped(file, file_len, &head, damage)? {
                out.push(f);
            }
        }
        b"##DL" => list(file, file_len, offset, out, seen, damage)?,
        b"##HL" => {
            let first = head.link(0);
            if first != 0 {
                collect(file, file_len, first, out, seen, damage)?;
            }
        }
        other => {
            return Err(MdfError::at(
                offset,
                format!("{} where data belongs", String::from_utf8_lossy(other)),
            ))
        }
    }
    Ok(())
}

/// A DZ block's fragment: its compressed bytes' place and what they inflate to; none where
/// it runs past the file's end (said as damage).
fn zipped<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    b: &block::Block,
    damage: &mut Option<String>,
) -> Result<Option<Fragment>> {
    let (offset, start) = (b.offset, b.data_offset());
    if start + 24 > file_len {
        damage.get_or_insert(format!("byte {offset}: a DZ block cut off"));
        return Ok(None);
    }
    file.seek(SeekFrom::Start(start))?;
    let mut h = [0u8; 24];
    file.read_exact(&mut h)?;
    let zip_type = h[2];
    let columns = u32::from_le_bytes(h[4..8].try_into().expect("4 bytes"));
    let original = u64::from_le_bytes(h[8..16].try_into().expect("8 bytes"));
    let compressed = u64::from_le_bytes(h[16..24].try_into().expect("8 bytes"));
    if original > MAX_INFLATED {
        return Err(MdfError::at(
            offset,
            format!(
                "a DZ block claims to inflate to {original} bytes (more than {} MiB)",
                MAX_INFLATED >> 20
            ),
        ));
    }
    if zip_type > 1 {
        return Err(MdfError::at(
            offset,
            format!("DZ compression {zip_type}: not deflate"),
        ));
    }
    if compressed > b.data_length().saturating_sub(24) || start + 24 + compressed > file_len {
        damage.get_or_insert(format!(
            "byte {offset}: a DZ block runs past the file's end"
        ));
        return Ok(None);
    }
    Ok(Some(Fragment::Zipped {
        offset: start + 24,
        compressed,
        original,
        columns: (zip_type == 1).then_some(columns),
        block: offset,
    }))
}

/// The data blocks of a DL list and the lists it links on to.
fn list<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    first: u64,
    out: &mut Vec<Fragment>,
    seen: &mut HashSet<u64>,
    damage: &mut Option<String>,
) -> Result<()> {
    let mut dl = first;
    while dl != 0 {
        if dl != first && !seen.insert(dl) {
            return Err(MdfError::at(dl, "a data list that links back to itself"));
        }
        let b = block::read(file, file_len, dl, false)?;
        for &d in b.links.iter().skip(1).filter(|&&d| d != 0) {
            collect(file, file_len, d, out, seen, damage)?;
        }
        dl = b.link(0);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn transposed_bytes_come_back_as_records() {
        // Three records of two bytes (a1 a2, b1 b2, c1 c2) stored by column, and a rest.
        let mut d = vec![b'a', b'b', b'c', 1, 2, 3, 9];
        super::untranspose(&mut d, 2);
        assert_eq!(d, vec![b'a', 1, b'b', 2, b'c', 3, 9]);
    }
}
