//! The file's tree, read once: the identification block (version, unfinalised flags), the
//! header (start time), and every data group's channel groups and channels, with their
//! conversions. Lists are walked with a visited set (a link cycle is refused) and a bound on
//! their length.

use std::collections::HashSet;
use std::io::{Read, Seek};

use crate::block::{self, Block};
use crate::{MdfError, Result};

/// The most channels (or groups) read from one file.
pub const MAX_NODES: usize = 100_000;

/// What a file is.
#[derive(Debug, Clone)]
pub struct Layout {
    /// `MDF     ` or `UnFinMF ` (a logger that did not finish the file).
    pub finalised: bool,
    /// 400, 410, 411, 420.
    pub version: u16,
    /// The unfinalised flags (bit 0: cycle counters not updated, bit 1: the last DT block's
    /// length not updated, …).
    pub unfinalised_flags: u16,
    /// The recording's start, ns since the Unix epoch, UTC.
    pub start_ns: u64,
    /// The start was stored as local time with no offset to UTC: taken as UTC.
    pub start_is_local: bool,
    pub data_groups: Vec<DataGroup>,
    pub file_len: u64,
}

#[derive(Debug, Clone)]
pub struct DataGroup {
    pub offset: u64,
    /// Bytes of each record's leading record id (0: sorted, one channel group).
    pub record_id_size: u8,
    /// The first block of its data (DT, DZ, DL, HL), 0 for none.
    pub data: u64,
    pub groups: Vec<ChannelGroup>,
}

#[derive(Debug, Clone)]
pub struct ChannelGroup {
    pub offset: u64,
    pub record_id: u64,
    /// The acquisition name (`CAN_DataFrame` in bus logging).
    pub name: String,
    pub cycle_count: u64,
    pub flags: u16,
    pub data_bytes: u32,
    pub inval_bytes: u32,
    /// Every channel, composition members after their parent.
    pub channels: Vec<Channel>,
}

impl ChannelGroup {
    /// A group of variable-length signal data (records of u32 length and bytes).
    pub fn is_vlsd(&self) -> bool {
        self.flags & 1 != 0
    }
    /// A bus event group (bus logging).
    pub fn is_bus_event(&self) -> bool {
        self.flags & 2 != 0
    }
    /// Bytes of one record after its record id.
    pub fn record_len(&self) -> usize {
        self.data_bytes as usize + self.inval_bytes as usize
    }
    /// The channel named `name`, or ending `.name` (a composition member).
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels
            .iter()
            .find(|c| c.name == name || c.name.strip_suffix(name).is_some_and(|p| p.ends_with('.')))
    }
    /// The master (time) channel.
    pub fn master(&self) -> Option<&Channel> {
        self.channels
            .iter()
            .find(|c| c.channel_type == 2 || c.channel_type == 3)
    }
}

/// How a raw value becomes a physical one.
#[derive(Debug, Clone, PartialEq)]
pub enum Conversion {
    Identity,
    /// `offset + factor · raw`.
    Linear {
        offset: f64,
        factor: f64,
    },
    /// `(p1 x² + p2 x + p3) / (p4 x² + p5 x + p6)`.
    Rational([f64; 6]),
    /// A conversion this reader does not apply (tables, texts): its type.
    Other(u8),
}

impl Conversion {
    pub fn apply(&self, x: f64) -> Option<f64> {
        match self {
            Conversion::Identity => Some(x),
            Conversion::Linear { offset, factor } => Some(offset + factor * x),
            Conversion::Rational([p1, p2, p3, p4, p5, p6]) => {
                let d = p4 * x * x + p5 * x + p6;
                (d != 0.0).then(|| (p1 * x * x + p2 * x + p3) / d)
            }
            Conversion::Other(_) => None,
        }
    }
}

#[derive(Debug, Clone)]
pub struct Channel {
    pub name: String,
    pub unit: String,
    /// 0 fixed length, 1 VLSD, 2 master, 3 virtual master, 4 sync, 5 maximum length, 6
    /// virtual data.
    pub channel_type: u8,
    /// 0/1 unsigned LE/BE, 2/3 signed, 4/5 float, 6–9 strings, 10 bytes.
    pub data_type: u8,
    pub bit_offset: u8,
    pub byte_offset: u32,
    pub bit_count: u32,
    pub conversion: Conversion,
    /// VLSD: its signal data (an SD, DL, DZ or HL block, or the VLSD channel group).
    pub data: u64,
}

impl Channel {
    /// The raw value as an integer (unsigned or signed) of a record's bytes (after the record
    /// id); None where the record is too short or the type is not an integer.
    #[inline]
    pub fn raw_int(&self, record: &[u8]) -> Option<i128> {
        self.raw_int_as(self.data_type, record)
    }

    /// [`raw_int`](Self::raw_int) read as if of `data_type`.
    #[inline]
    fn raw_int_as(&self, data_type: u8, record: &[u8]) -> Option<i128> {
        let start = self.byte_offset as usize;
        let bits = self.bit_count.min(64);
        let bytes = (self.bit_offset as usize + bits as usize).div_ceil(8);
        let src = record.get(start..start + bytes)?;
        // The common case (an unsigned little-endian field within 8 bytes) in one word.
        if data_type == 0 && bytes <= 8 {
            let mut word = [0u8; 8];
            word[..bytes].copy_from_slice(src);
            let v = u64::from_le_bytes(word) >> self.bit_offset;
            let v = if bits >= 64 {
                v
            } else {
                v & ((1u64 << bits) - 1)
            };
            return Some(v as i128);
        }
        let mut word = [0u8; 16];
        match data_type {
            0 | 2 | 4 => word[..bytes].copy_from_slice(src),
            1 | 3 | 5 => {
                for (i, b) in src.iter().rev().enumerate() {
                    word[i] = *b;
                }
            }
            _ => return None,
        }
        let v = u128::from_le_bytes(word) >> self.bit_offset;
        let mask = if bits >= 128 {
            u128::MAX
        } else {
            (1u128 << bits) - 1
        };
        let v = v & mask;
        Some(match data_type {
            2 | 3 if bits > 0 && v >> (bits - 1) & 1 == 1 => v as i128 - (1i128 << bits),
            _ => v as i128,
        })
    }

    /// A VLSD channel's offset into its signal data (an unsigned integer in the record,
    /// whatever type its values are).
    pub fn vlsd_offset(&self, record: &[u8]) -> Option<u64> {
        self.raw_int_as(0, record).map(|v| v as u64)
    }

    /// The value, converted: integers and floats (32 and 64 bits).
    pub fn value(&self, record: &[u8]) -> Option<f64> {
        let raw = match (self.data_type, self.bit_count) {
            (4 | 5, 32) => f32::from_bits(self.raw_int(record)? as u32) as f64,
            (4 | 5, 64) => f64::from_bits(self.raw_int(record)? as u64),
            (4 | 5, _) => return None,
            _ => self.raw_int(record)? as f64,
        };
        self.conversion.apply(raw)
    }

    /// A byte array's bytes in the record.
    pub fn bytes<'r>(&self, record: &'r [u8]) -> Option<&'r [u8]> {
        let start = self.byte_offset as usize;
        record.get(start..start + (self.bit_count / 8) as usize)
    }
}

/// Reads the tree of the file behind `file`.
pub fn read<F: Read + Seek>(file: &mut F) -> Result<Layout> {
    let file_len = file.seek(std::io::SeekFrom::End(0))?;
    if file_len < 64 + block::HEADER {
        return Err(MdfError::at(0, "shorter than an MDF file's first blocks"));
    }
    let mut layout = identification(file, file_len)?;
    let hd = block::read(file, file_len, 64, true)?;
    if &hd.id != b"##HD" {
        return Err(MdfError::at(
            64,
            format!("{} where the header block belongs", hd.id()),
        ));
    }
    let time_flags = hd.u8(12);
    let (local, offsets_valid) = (time_flags & 1 != 0, time_flags & 2 != 0);
    layout.start_ns = hd.u64(0);
    if local && offsets_valid {
        let minutes = hd.i16(8) as i64 + hd.i16(10) as i64;
        layout.start_ns = (layout.start_ns as i64 - minutes * 60_000_000_000) as u64;
    }
    layout.start_is_local = local && !offsets_valid;
    let (mut seen, mut nodes) = (HashSet::new(), 0usize);
    let mut dg = hd.link(0);
    while dg != 0 {
        let b = visit(file, file_len, dg, b"##DG", &mut seen, &mut nodes)?;
        let mut group = DataGroup {
            offset: dg,
            record_id_size: b.u8(0),
            data: b.link(2),
            groups: Vec::new(),
        };
        if ![0, 1, 2, 4, 8].contains(&group.record_id_size) {
            return Err(MdfError::at(
                dg,
                format!("a record id of {} bytes", group.record_id_size),
            ));
        }
        let mut cg = b.link(1);
        while cg != 0 {
            let c = visit(file, file_len, cg, b"##CG", &mut seen, &mut nodes)?;
            group
                .groups
                .push(channel_group(file, file_len, &c, &mut seen, &mut nodes)?);
            cg = c.link(0);
        }
        layout.data_groups.push(group);
        dg = b.link(0);
    }
    Ok(layout)
}

/// The identification block: finalised or not, the version, the unfinalised flags.
fn identification<F: Read + Seek>(file: &mut F, file_len: u64) -> Result<Layout> {
    file.seek(std::io::SeekFrom::Start(0))?;
    let mut id = [0u8; 64];
    file.read_exact(&mut id)?;
    let file_id = String::from_utf8_lossy(&id[0..8]).into_owned();
    let finalised = match file_id.as_str() {
        "MDF     " => true,
        "UnFinMF " => false,
        _ => {
            return Err(MdfError::at(
                0,
                format!("'{}' is not an MDF file's mark", file_id.trim()),
            ))
        }
    };
    let version = u16::from_le_bytes([id[28], id[29]]);
    if !(400..500).contains(&version) {
        return Err(MdfError::at(
            28,
            format!("MDF version {version}: only MDF 4 (4.00–4.20) is read"),
        ));
    }
    Ok(Layout {
        finalised,
        version,
        unfinalised_flags: u16::from_le_bytes([id[60], id[61]]),
        start_ns: 0,
        start_is_local: false,
        data_groups: Vec::new(),
        file_len,
    })
}

/// A channel group's block read with its channels.
fn channel_group<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    c: &Block,
    seen: &mut HashSet<u64>,
    nodes: &mut usize,
) -> Result<ChannelGroup> {
    let mut channels = Vec::new();
    channel_list(file, file_len, c.link(1), "", seen, nodes, &mut channels)?;
    Ok(ChannelGroup {
        offset: c.offset,
        record_id: c.u64(0),
        name: block::text(file, file_len, c.link(2))?,
        cycle_count: c.u64(8),
        flags: c.u16(16),
        data_bytes: c.u32(24),
        inval_bytes: c.u32(28),
        channels,
    })
}

/// A block of a list, once: a second visit is a cycle.
fn visit<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    offset: u64,
    id: &[u8; 4],
    seen: &mut HashSet<u64>,
    nodes: &mut usize,
) -> Result<Block> {
    if !seen.insert(offset) {
        return Err(MdfError::at(
            offset,
            "a link back to a block already read (a cycle)",
        ));
    }
    *nodes += 1;
    if *nodes > MAX_NODES {
        return Err(MdfError::at(
            offset,
            format!("more than {MAX_NODES} groups and channels"),
        ));
    }
    let b = block::read(file, file_len, offset, true)?;
    if &b.id != id {
        return Err(MdfError::at(
            offset,
            format!("{} where {} belongs", b.id(), String::from_utf8_lossy(id)),
        ));
    }
    Ok(b)
}

/// The channels of a list from `first`, each followed by its composition's members (named
/// `parent.member` where the member's own name does not already say so).
fn channel_list<F: Read + Seek>(
    file: &mut F,
    file_len: u64,
    first: u64,
    parent: &str,
    seen: &mut HashSet<u64>,
    nodes: &mut usize,
    out: &mut Vec<Channel>,
) -> Result<()> {
    let mut cn = first;
    while cn != 0 {
        let b = visit(file, file_len, cn, b"##CN", seen, nodes)?;
        let mut name = block::text(file, file_len, b.link(2))?;
        if !parent.is_empty() && !name.starts_with(&format!("{parent}.")) {
            name = format!("{parent}.{name}");
        }
        let unit = block::text(file, file_len, b.link(6)).unwrap_or_default();
        out.push(Channel {
            name: name.clone(),
            unit,
            channel_type: b.u8(0),
            data_type: b.u8(2),
            bit_offset: b.u8(3),
            byte_offset: b.u32(4),
            bit_count: b.u32(8),
            conversion: conversion(file, file_len, b.link(4))?,
            data: b.link(5),
        });
        let composition = b.link(1);
        if composition != 0 {
            let head = block::read(file, file_len, composition, false)?;
            // A structure's members are channels; an array (CA) is not read.
            if &head.id == b"##CN" {
                channel_list(file, file_len, composition, &name, seen, nodes, out)?;
            }
        }
        cn = b.link(0);
    }
    Ok(())
}

fn conversion<F: Read + Seek>(file: &mut F, file_len: u64, offset: u64) -> Result<Conversion> {
    if offset == 0 {
        return Ok(Conversion::Identity);
    }
    let b = block::read(file, file_len, offset, true)?;
    if &b.id != b"##CC" {
        return Err(MdfError::at(
            offset,
            format!("{} where a conversion was linked", b.id()),
        ));
    }
    let val = |i: usize| b.f64(24 + 8 * i);
    Ok(match b.u8(0) {
        0 => Conversion::Identity,
        1 => Conversion::Linear {
            offset: val(0),
            factor: val(1),
        },
        2 => Conversion::Rational([val(0), val(1), val(2), val(3), val(4), val(5)]),
        t => Conversion::Other(t),
    })
}
