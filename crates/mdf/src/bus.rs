//! CAN bus logging as ASAM's bus logging standard lays it out (and CSS CANedge, Vector and
//! asammdf write it): a channel group per event type, `CAN_DataFrame`, `CAN_RemoteFrame` and
//! `CAN_ErrorFrame`, whose composition's members (`.BusChannel`, `.ID`, `.IDE`, `.DLC`,
//! `.DataLength`, `.DataBytes`, `.EDL`, `.BRS`, `.ESI`, `.ErrorType`) hold each frame, and a
//! master channel its time from the header's start. `DataBytes` is a byte array in the
//! record, or variable-length signal data (a VLSD channel group of the same data group, or an
//! SD block). A frame's bus is `CAN<n>`, its `BusChannel` (as a BLF's channel is named).
//!
//! Frames leave in time order: each data group's records are read in order (a logger's one
//! unsorted group is already in time order), and several data groups are merged by time.

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::path::Path;

use railfuse_can::frame::Frame;

use crate::data::DataStream;
use crate::layout::{self, Channel, ChannelGroup, Layout};
use crate::records::{Kind, Records};
use crate::{MdfError, Result};

/// VLSD payloads held for frames still to come (bounded; a logger writes a frame's data just
/// before its record).
const HELD_VLSD: usize = 4096;

/// What a bus group's channels are.
#[derive(Debug, Clone)]
struct BusGroup {
    kind: Event,
    time: Channel,
    bus: Option<Channel>,
    id: Option<Channel>,
    ide: Option<Channel>,
    dlc: Option<Channel>,
    length: Option<Channel>,
    bytes: Option<Channel>,
    edl: Option<Channel>,
    brs: Option<Channel>,
    esi: Option<Channel>,
    error_type: Option<Channel>,
    /// Where `bytes` is VLSD: the VLSD channel group's index in the data group.
    vlsd_group: Option<usize>,
    /// …or its SD stream.
    sd: Option<u64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Event {
    Data,
    Remote,
    Error,
}

impl BusGroup {
    fn of(group: &ChannelGroup, all: &[ChannelGroup]) -> Option<Self> {
        let kind = match group.name.as_str() {
            "CAN_DataFrame" => Event::Data,
            "CAN_RemoteFrame" => Event::Remote,
            "CAN_ErrorFrame" => Event::Error,
            _ if group.channel("CAN_DataFrame").is_some() => Event::Data,
            _ => return None,
        };
        let time = group.master()?.clone();
        let ch = |n: &str| group.channel(n).cloned();
        let bytes = ch("DataBytes");
        let (mut vlsd_group, mut sd) = (None, None);
        if let Some(b) = bytes.as_ref().filter(|b| b.channel_type == 1) {
            match all.iter().position(|g| g.offset == b.data) {
                Some(i) => vlsd_group = Some(i),
                None => sd = Some(b.data),
            }
        }
        Some(Self {
            kind,
            time,
            bus: ch("BusChannel"),
            id: ch("ID"),
            ide: ch("IDE"),
            dlc: ch("DLC"),
            length: ch("DataLength"),
            bytes,
            edl: ch("EDL"),
            brs: ch("BRS"),
            esi: ch("ESI"),
            error_type: ch("ErrorType"),
            vlsd_group,
            sd,
        })
    }
}

/// What reading a file's bus logging found besides frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BusReport {
    pub records: u64,
    pub frames: u64,
    /// Records of groups that are not CAN bus events (LIN, measured signals), by group name.
    pub other_records: BTreeMap<String, u64>,
    /// Frames not made, by reason.
    pub skipped: BTreeMap<String, u64>,
    /// Where the file stopped being readable (the frames before it are read).
    pub damage: Option<String>,
    /// The header's start was local time with no offset to UTC (taken as UTC).
    pub start_is_local: bool,
    pub finalised: bool,
}

impl BusReport {
    /// Every record that made no frame, by reason (bus groups' records that did not read,
    /// and the records of groups that are not CAN bus logging).
    pub fn not_used(&self) -> BTreeMap<String, u64> {
        let mut out = self.skipped.clone();
        for (group, n) in &self.other_records {
            *out.entry(format!("records of {group} (not CAN bus logging)"))
                .or_insert(0) += n;
        }
        out
    }
}

/// One data group's reader.
struct GroupReader {
    records: Records<File>,
    groups: Vec<ChannelGroup>,
    /// Each channel group's bus logging, where it is a bus group.
    bus: Vec<Option<BusGroup>>,
    /// VLSD payloads by (group, offset), oldest first.
    held: VecDeque<((usize, u64), Vec<u8>)>,
    /// Each SD block's reader, by its link.
    sd: Vec<(u64, SdReader)>,
    head: Option<Frame>,
    /// `CAN<n>` by n, made once.
    bus_names: Vec<(i128, String)>,
}

/// A channel's SD stream, read forward to each offset asked for.
struct SdReader {
    stream: std::io::BufReader<DataStream<File>>,
    at: u64,
}

impl SdReader {
    fn at(&mut self, offset: u64) -> Option<Vec<u8>> {
        use std::io::Read;
        if offset < self.at {
            return None;
        }
        std::io::copy(
            &mut (&mut self.stream).take(offset - self.at),
            &mut std::io::sink(),
        )
        .ok()?;
        let mut l = [0u8; 4];
        self.stream.read_exact(&mut l).ok()?;
        let n = u32::from_le_bytes(l).min(crate::records::MAX_VLSD);
        let mut b = vec![0u8; n as usize];
        self.stream.read_exact(&mut b).ok()?;
        self.at = offset + 4 + n as u64;
        Some(b)
    }
}

/// The CAN frames of an MDF file, in time order.
pub struct BusFrames {
    layout: Layout,
    readers: Vec<GroupReader>,
    /// The last frame's time: a frame before it (a damaged time) is counted, not given.
    last_ns: u64,
    pub report: BusReport,
}

impl BusFrames {
    pub fn open(path: &Path) -> Result<Self> {
        let open = || File::open(path).map_err(MdfError::from);
        let layout = layout::read(&mut open()?)?;
        let open_ended = !layout.finalised && layout.unfinalised_flags & 2 != 0;
        let mut readers = Vec::new();
        let mut sd_damage = None;
        for dg in &layout.data_groups {
            let stream = DataStream::new(open()?, layout.file_len, dg.data, open_ended)?;
            let bus: Vec<Option<BusGroup>> = dg
                .groups
                .iter()
                .map(|g| BusGroup::of(g, &dg.groups))
                .collect();
            let mut sd = Vec::new();
            for b in bus.iter().flatten() {
                if let Some(link) = b.sd {
                    let mut s = DataStream::new(open()?, layout.file_len, link, false)?;
                    if let Some(d) = s.damage.take() {
                        sd_damage.get_or_insert(format!("the frames' data: {d}"));
                    }
                    let reader = SdReader {
                        stream: std::io::BufReader::new(s),
                        at: 0,
                    };
                    sd.push((link, reader));
                }
            }
            readers.push(GroupReader {
                records: Records::new(dg, stream),
                groups: dg.groups.clone(),
                bus,
                held: VecDeque::new(),
                sd,
                head: None,
                bus_names: Vec::new(),
            });
        }
        let report = BusReport {
            start_is_local: layout.start_is_local,
            finalised: layout.finalised,
            damage: sd_damage,
            ..Default::default()
        };
        Ok(Self {
            layout,
            readers,
            last_ns: 0,
            report,
        })
    }

    /// The recording's start, ns since the Unix epoch.
    pub fn start_ns(&self) -> u64 {
        self.layout.start_ns
    }

    /// Whether any group of the file is CAN bus logging.
    pub fn has_bus_logging(&self) -> bool {
        self.readers
            .iter()
            .any(|r| r.bus.iter().any(Option::is_some))
    }

    /// The names of the file's channel groups.
    pub fn group_names(&self) -> Vec<String> {
        self.readers
            .iter()
            .flat_map(|r| r.groups.iter().map(|g| g.name.clone()))
            .collect()
    }
}

impl Iterator for BusFrames {
    type Item = Frame;
    fn next(&mut self) -> Option<Frame> {
        let start = self.layout.start_ns;
        loop {
            for r in &mut self.readers {
                if r.head.is_none() {
                    r.head = r.next_frame(start, &mut self.report);
                }
            }
            let i = (0..self.readers.len())
                .filter(|&i| self.readers[i].head.is_some())
                .min_by_key(|&i| self.readers[i].head.as_ref().map(|f| f.stamp_ns))?;
            let f = self.readers[i].head.take()?;
            if f.stamp_ns < self.last_ns {
                self.report.frames -= 1;
                *self
                    .report
                    .skipped
                    .entry("a frame earlier than the one before (a damaged time)".into())
                    .or_insert(0) += 1;
                continue;
            }
            self.last_ns = f.stamp_ns;
            return Some(f);
        }
    }
}

impl GroupReader {
    fn next_frame(&mut self, start_ns: u64, report: &mut BusReport) -> Option<Frame> {
        // The fields one by one: a record borrowed from the reader, the rest changed beside it.
        let GroupReader {
            records,
            groups,
            bus,
            held,
            sd,
            bus_names,
            ..
        } = self;
        loop {
            let Some((g, kind, bytes)) = records.next_record() else {
                if let Some(d) = records.damage.take() {
                    report.damage.get_or_insert(d);
                }
                return None;
            };
            report.records += 1;
            if let Kind::Vlsd { offset } = kind {
                if held.len() >= HELD_VLSD {
                    held.pop_front();
                }
                held.push_back(((g, offset), bytes.to_vec()));
                continue;
            }
            let Some(bus) = bus.get(g).and_then(Option::as_ref) else {
                *report
                    .other_records
                    .entry(groups[g].name.clone())
                    .or_insert(0) += 1;
                continue;
            };
            match frame(bus, bytes, start_ns, held, sd, bus_names) {
                Ok(f) => {
                    report.frames += 1;
                    return Some(f);
                }
                Err(why) => *report.skipped.entry(why.to_owned()).or_insert(0) += 1,
            }
        }
    }
}

/// `CAN<n>`, made once for each n.
fn bus_name(names: &mut Vec<(i128, String)>, n: i128) -> String {
    if let Some((_, name)) = names.iter().find(|(k, _)| *k == n) {
        return name.clone();
    }
    let name = format!("CAN{n}");
    names.push((n, name.clone()));
    name
}

/// One record of a bus group as a frame, or why it is not one.
fn frame(
    g: &BusGroup,
    record: &[u8],
    start_ns: u64,
    held: &mut VecDeque<((usize, u64), Vec<u8>)>,
    sd: &mut [(u64, SdReader)],
    bus_names: &mut Vec<(i128, String)>,
) -> std::result::Result<Frame, &'static str> {
    let int = |c: &Option<Channel>| c.as_ref().and_then(|c| c.raw_int(record));
    let flag = |c: &Option<Channel>| int(c).unwrap_or(0) != 0;
    let seconds = g.time.value(record).ok_or("a time that does not read")?;
    // A record's time is within a few centuries of its file's start, or it is damage.
    if !(seconds.is_finite() && seconds.abs() <= 1e10) {
        return Err("a time that does not read");
    }
    let stamp_ns =
        (start_ns as i128 + (seconds * 1e9).round() as i128).clamp(0, u64::MAX as i128) as u64;
    let raw_id = int(&g.id).unwrap_or(0) as u32;
    // Some loggers mark a 29-bit id in the id's top bit instead of IDE.
    let extended = flag(&g.ide) || raw_id & 0x8000_0000 != 0;
    let mut f = Frame {
        stamp_ns,
        bus: bus_name(bus_names, int(&g.bus).unwrap_or(0)),
        id: raw_id & 0x1FFF_FFFF,
        extended,
        rtr: g.kind == Event::Remote,
        error: g.kind == Event::Error,
        fd: flag(&g.edl),
        brs: flag(&g.brs),
        esi: flag(&g.esi),
        data: Vec::new(),
    };
    match g.kind {
        Event::Error => f.id = int(&g.error_type).unwrap_or(0) as u32,
        Event::Remote => {}
        Event::Data => {
            let length = match (int(&g.length), int(&g.dlc)) {
                (Some(l), _) => l as usize,
                (None, Some(dlc)) => railfuse_can::frame::FD_LENGTHS[(dlc as usize).min(15)],
                (None, None) => 64,
            };
            let bytes = g.bytes.as_ref().ok_or("a data frame without DataBytes")?;
            let mut data = match (bytes.channel_type, g.vlsd_group, g.sd) {
                (1, Some(vg), _) => {
                    let offset = bytes
                        .vlsd_offset(record)
                        .ok_or("a VLSD offset that does not read")?;
                    let i = held
                        .iter()
                        .position(|(k, _)| *k == (vg, offset))
                        .ok_or("DataBytes whose VLSD record is not in the file")?;
                    // Held in order: every payload before it belongs to no frame still to come.
                    let (_, d) = held.drain(..=i).last().expect("position found");
                    d
                }
                (1, None, Some(link)) => {
                    let offset = bytes
                        .vlsd_offset(record)
                        .ok_or("a VLSD offset that does not read")?;
                    sd.iter_mut()
                        .find(|s| s.0 == link)
                        .and_then(|s| s.1.at(offset))
                        .ok_or("DataBytes whose signal data is not in the file")?
                }
                _ => bytes
                    .bytes(record)
                    .ok_or("DataBytes past the record's end")?
                    .to_vec(),
            };
            data.truncate(length.min(64));
            f.data = data;
        }
    }
    Ok(f)
}
