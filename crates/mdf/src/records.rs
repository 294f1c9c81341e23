//! The records of one data group: in a sorted group each record is its one channel group's;
//! in an unsorted one (a logger's: every bus event as it came) each begins with its record id,
//! and a variable-length signal data (VLSD) group's record is a u32 length and that many
//! bytes. A record cut off at the data's end is the end (said as damage).

use std::collections::HashMap;
use std::io::{BufReader, Read, Seek};

use crate::data::DataStream;
use crate::layout::DataGroup;
use crate::{MdfError, Result};

/// The longest VLSD record taken (a CAN FD frame's data is 64 bytes; an Ethernet frame's
/// 1.5 KiB).
pub const MAX_VLSD: u32 = 16 << 20;

/// One record: its channel group (index in the data group) and its bytes (after the record
/// id), or a VLSD group's payload with its offset in that group's signal data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Fixed,
    /// A VLSD record, and where it starts in its group's signal data.
    Vlsd {
        offset: u64,
    },
}

pub struct Records<F: Read + Seek> {
    data: BufReader<DataStream<F>>,
    id_size: u8,
    /// Record id → (group index, record length, VLSD); a file has a handful of groups.
    by_id: Vec<(u64, (usize, usize, bool))>,
    /// Each VLSD group's next signal-data offset.
    vlsd_offsets: HashMap<usize, u64>,
    buf: Vec<u8>,
    pub records: u64,
    /// Where the records stopped before the data's end, and why.
    pub damage: Option<String>,
    done: bool,
}

impl<F: Read + Seek> Records<F> {
    pub fn new(group: &DataGroup, data: DataStream<F>) -> Self {
        let by_id = group
            .groups
            .iter()
            .enumerate()
            .map(|(i, g)| (g.record_id, (i, g.record_len(), g.is_vlsd())))
            .collect();
        Self {
            data: BufReader::with_capacity(64 << 10, data),
            id_size: group.record_id_size,
            by_id,
            vlsd_offsets: HashMap::new(),
            buf: Vec::new(),
            records: 0,
            damage: None,
            done: false,
        }
    }

    /// The next record: its group, kind and bytes; None at the end (or at damage).
    pub fn next_record(&mut self) -> Option<(usize, Kind, &[u8])> {
        if self.done {
            return None;
        }
        match self.read_one() {
            Ok(Some((group, kind))) => {
                self.records += 1;
                Some((group, kind, &self.buf))
            }
            Ok(None) => {
                self.done = true;
                self.take_stream_damage();
                None
            }
            Err(e) => {
                self.done = true;
                self.take_stream_damage();
                self.damage.get_or_insert(e.to_string());
                None
            }
        }
    }

    fn take_stream_damage(&mut self) {
        if let Some(d) = self.data.get_mut().damage.take() {
            self.damage.get_or_insert(d);
        }
    }

    fn read_one(&mut self) -> Result<Option<(usize, Kind)>> {
        let record = self.records;
        let id = match self.id_size {
            0 => {
                // Sorted: one group; the stream's end is the records' end.
                if self.data.fill_buf_is_empty()? {
                    return Ok(None);
                }
                self.by_id.first().map_or(0, |g| g.0)
            }
            n => {
                let mut raw = [0u8; 8];
                match read_or_end(&mut self.data, &mut raw[..n as usize])? {
                    Filled::End => return Ok(None),
                    Filled::Part => return Err(cut(record)),
                    Filled::Whole => u64::from_le_bytes(raw),
                }
            }
        };
        let Some(&(_, (group, len, vlsd))) = self.by_id.iter().find(|g| g.0 == id) else {
            return Err(MdfError::at(
                0,
                format!("record {record}: record id {id}, which no channel group has (the rest cannot be framed)"),
            ));
        };
        if vlsd {
            let mut l = [0u8; 4];
            if read_or_end(&mut self.data, &mut l)? != Filled::Whole {
                return Err(cut(record));
            }
            let n = u32::from_le_bytes(l);
            if n > MAX_VLSD {
                return Err(MdfError::at(
                    0,
                    format!("record {record}: a VLSD record of {n} bytes"),
                ));
            }
            self.buf.resize(n as usize, 0);
            if read_or_end(&mut self.data, &mut self.buf)? != Filled::Whole {
                return Err(cut(record));
            }
            let offset = self.vlsd_offsets.entry(group).or_insert(0);
            let kind = Kind::Vlsd { offset: *offset };
            *offset += 4 + n as u64;
            return Ok(Some((group, kind)));
        }
        self.buf.resize(len, 0);
        match read_or_end(&mut self.data, &mut self.buf)? {
            Filled::Whole => Ok(Some((group, Kind::Fixed))),
            Filled::End if self.id_size == 0 => Ok(None),
            _ => Err(cut(record)),
        }
    }
}

fn cut(record: u64) -> MdfError {
    MdfError::at(0, format!("record {record} is cut off at the data's end"))
}

#[derive(Debug, PartialEq, Eq)]
enum Filled {
    Whole,
    /// Nothing at all: the end.
    End,
    Part,
}

fn read_or_end(r: &mut impl Read, buf: &mut [u8]) -> Result<Filled> {
    let mut got = 0;
    while got < buf.len() {
        let n = r.read(&mut buf[got..])?;
        if n == 0 {
            return Ok(if got == 0 { Filled::End } else { Filled::Part });
        }
        got += n;
    }
    Ok(Filled::Whole)
}

trait FillEmpty {
    fn fill_buf_is_empty(&mut self) -> Result<bool>;
}

impl<R: Read> FillEmpty for BufReader<R> {
    fn fill_buf_is_empty(&mut self) -> Result<bool> {
        use std::io::BufRead;
        Ok(self.fill_buf()?.is_empty())
    }
}
