//! Measured signals (a measurement system's physical values: CANape, INCA, a DAQ, asammdf's
//! `MDF.append`): chosen channels of chosen channel groups, each record a sample of them at
//! its master time, physical values through each channel's conversion. Samples leave in time
//! order: each data group's records in order, several data groups merged by time.

use std::fs::File;
use std::path::Path;

use crate::data::DataStream;
use crate::layout::{self, Channel, Layout};
use crate::records::{Kind, Records};
use crate::{MdfError, Result};

/// A channel group and the channels wanted of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Wanted {
    pub data_group: usize,
    pub channel_group: usize,
    pub channels: Vec<String>,
}

/// One record of a wanted group: its time and the wanted channels' physical values (`None`
/// where a value is not a number this reader converts).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The index of its group among those wanted.
    pub wanted: usize,
    pub stamp_ns: u64,
    pub values: Vec<Option<f64>>,
}

/// A wanted group's channels, found.
struct Bound {
    wanted: usize,
    channel_group: usize,
    master: Channel,
    channels: Vec<Channel>,
}

struct GroupReader {
    records: Records<File>,
    bound: Vec<Bound>,
    head: Option<Sample>,
}

/// The samples of the wanted groups, in time order.
pub struct Signals {
    readers: Vec<GroupReader>,
    start_ns: u64,
    last_ns: u64,
    /// Records read, samples given, samples left out (a time before the one before, or no
    /// time), and where the data stopped early.
    pub records: u64,
    pub samples: u64,
    pub out_of_order: u64,
    pub damage: Option<String>,
}

/// A layout's channel groups that hold measured values (not bus logging, not VLSD): (data
/// group, channel group, name, channel names) for a caller to choose from.
pub fn groups(layout: &Layout) -> Vec<(usize, usize, String, Vec<String>)> {
    let mut out = Vec::new();
    for (d, dg) in layout.data_groups.iter().enumerate() {
        for (c, cg) in dg.groups.iter().enumerate() {
            if cg.is_vlsd() || cg.is_bus_event() || cg.master().is_none() {
                continue;
            }
            let names = cg.channels.iter().map(|ch| ch.name.clone()).collect();
            out.push((d, c, cg.name.clone(), names));
        }
    }
    out
}

impl Signals {
    /// Opens `path` (its layout already read) for the `wanted` groups.
    pub fn open(path: &Path, layout: &Layout, wanted: &[Wanted]) -> Result<Self> {
        let open = || File::open(path).map_err(MdfError::from);
        let open_ended = !layout.finalised && layout.unfinalised_flags & 2 != 0;
        let mut readers = Vec::new();
        for (d, dg) in layout.data_groups.iter().enumerate() {
            let mut bound = Vec::new();
            for (i, w) in wanted.iter().enumerate().filter(|(_, w)| w.data_group == d) {
                let cg = dg.groups.get(w.channel_group).ok_or_else(|| {
                    MdfError::at(dg.offset, format!("no channel group {}", w.channel_group))
                })?;
                let master = cg.master().cloned().ok_or_else(|| {
                    MdfError::at(
                        cg.offset,
                        format!("group {} has no master (time) channel", cg.name),
                    )
                })?;
                let channels = w
                    .channels
                    .iter()
                    .map(|n| {
                        cg.channel(n).cloned().ok_or_else(|| {
                            MdfError::at(cg.offset, format!("group {} has no channel {n}", cg.name))
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                bound.push(Bound {
                    wanted: i,
                    channel_group: w.channel_group,
                    master,
                    channels,
                });
            }
            if bound.is_empty() {
                continue;
            }
            let stream = DataStream::new(open()?, layout.file_len, dg.data, open_ended)?;
            readers.push(GroupReader {
                records: Records::new(dg, stream),
                bound,
                head: None,
            });
        }
        Ok(Self {
            readers,
            start_ns: layout.start_ns,
            last_ns: 0,
            records: 0,
            samples: 0,
            out_of_order: 0,
            damage: None,
        })
    }

    /// Reads the layout of `path`.
    pub fn layout(path: &Path) -> Result<Layout> {
        layout::read(&mut File::open(path)?)
    }
}

impl Iterator for Signals {
    type Item = Sample;
    fn next(&mut self) -> Option<Sample> {
        loop {
            for r in &mut self.readers {
                if r.head.is_none() {
                    r.head = r.next_sample(self.start_ns, &mut self.records, &mut self.damage);
                }
            }
            let i = (0..self.readers.len())
                .filter(|&i| self.readers[i].head.is_some())
                .min_by_key(|&i| self.readers[i].head.as_ref().map(|s| s.stamp_ns))?;
            let s = self.readers[i].head.take()?;
            if s.stamp_ns < self.last_ns {
                self.out_of_order += 1;
                continue;
            }
            self.last_ns = s.stamp_ns;
            self.samples += 1;
            return Some(s);
        }
    }
}

impl GroupReader {
    fn next_sample(
        &mut self,
        start_ns: u64,
        records: &mut u64,
        damage: &mut Option<String>,
    ) -> Option<Sample> {
        loop {
            let Some((g, kind, bytes)) = self.records.next_record() else {
                if let Some(d) = self.records.damage.take() {
                    damage.get_or_insert(d);
                }
                return None;
            };
            *records += 1;
            if matches!(kind, Kind::Vlsd { .. }) {
                continue;
            }
            let Some(b) = self.bound.iter().find(|b| b.channel_group == g) else {
                continue;
            };
            // The master's value is seconds from the header's start.
            let Some(t) = b.master.value(bytes).filter(|t| t.is_finite() && *t >= 0.0) else {
                continue;
            };
            return Some(Sample {
                wanted: b.wanted,
                stamp_ns: start_ns.saturating_add((t * 1e9).round() as u64),
                values: b.channels.iter().map(|c| c.value(bytes)).collect(),
            });
        }
    }
}
