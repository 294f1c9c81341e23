//! ASAM MDF 4 into a run: bus logging (CSS CANedge, Vector, most vehicle loggers), every CAN
//! frame of every `CAN_DataFrame`, `CAN_RemoteFrame` and `CAN_ErrorFrame` group onto
//! `/can/<bus>/frames` (the bus `CAN<n>`, its `BusChannel`), in time order, each stamped with
//! the header's start plus its master time; and, with a mapping (`--map`, the one a logger's
//! CSV takes: see [`super::csv_table`]), measured signals (a measurement system's physical
//! values) as catalogue messages: each mapped channel's columns are channel names of one
//! channel group, each record of that group a row at its master time. Where the mapping
//! states no unit for a column, the MDF channel's own unit is used. The reading is
//! `railfuse-mdf`'s (streamed, every block bounded); a configuration's `[can]` table decodes
//! the frames as it does a live bus's. A drive a logger split into files (CANedge: ten-minute
//! files) is read as one run by naming them all, or their folder.

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_mdf::bus::BusFrames;
use railfuse_mdf::layout::Layout;
use railfuse_mdf::signals::{self, Sample, Signals, Wanted};

use super::csv_table::mapping::{ColumnSpec, MappingFile, TimeSpec};
use super::csv_table::Table;
use super::Converted;
use crate::error::{Error, Result};
use crate::foreign::can::frames_topic;
use crate::log::{ChannelId, LogWriter, WriterOptions};
use crate::messages::CanFrame;

/// The column a measured group's rows carry their time in (ns since the epoch).
const TIME_COLUMN: &str = "<time_ns>";

/// Converts the MDF file `input` to MCAP at `output`; `mapping` reads its measured signals.
pub fn convert(
    input: &Path,
    output: &Path,
    mapping: Option<&MappingFile>,
    writer: &WriterOptions,
) -> Result<Converted> {
    let fault = |e: railfuse_mdf::MdfError| Error::run(input, e);
    let layout = Signals::layout(input).map_err(fault)?;
    let mut frames = BusFrames::open(input).map_err(fault)?;
    let (plan, unmatched) = match mapping {
        Some(m) => plan(m, &layout),
        None => (Vec::new(), Vec::new()),
    };
    if !frames.has_bus_logging() && plan.is_empty() {
        return Err(Error::run(
            input,
            nothing_to_read(&layout, mapping, &unmatched),
        ));
    }
    let mut log = LogWriter::create_with(output, writer)?;
    let wanted: Vec<Wanted> = plan.iter().map(|(w, _)| w.clone()).collect();
    let mut signals = Signals::open(input, &layout, &wanted).map_err(fault)?;
    let mut tables = Vec::new();
    for (w, m) in &plan {
        let header: csv::StringRecord = std::iter::once(TIME_COLUMN)
            .chain(w.channels.iter().map(String::as_str))
            .collect();
        tables.push(Table::bind(m, input, &header, &mut log)?);
    }
    let mut report = Converted::default();
    let mut bus = BusWriter::default();
    let (mut frame, mut sample) = (frames.next(), signals.next());
    loop {
        match (&frame, &sample) {
            (Some(f), s) if s.as_ref().is_none_or(|s| f.stamp_ns <= s.stamp_ns) => {
                bus.write(&mut log, f, &mut report)?;
                frame = frames.next();
            }
            (_, Some(s)) => {
                let record = row(s);
                let line = signals.samples;
                tables[s.wanted].row(line, &record, &mut log, &mut report)?;
                sample = signals.next();
            }
            _ => break,
        }
    }
    for t in &mut tables {
        t.finish(&mut log, &mut report)?;
    }
    finish_report(&mut report, &frames, &signals, &unmatched);
    if report.messages == 0 {
        let why = match &report.damage {
            Some(d) => d.clone(),
            None => format!("{} records but no CAN frame or mapped signal", report.rows),
        };
        return Err(Error::run(input, why));
    }
    log.finish()?;
    Ok(report)
}

/// A sample as a row: its time, then its values (empty where a value does not convert).
fn row(s: &Sample) -> csv::StringRecord {
    let mut r = csv::StringRecord::with_capacity(16 * (s.values.len() + 1), s.values.len() + 1);
    r.push_field(&s.stamp_ns.to_string());
    for v in &s.values {
        match v {
            Some(x) => r.push_field(&x.to_string()),
            None => r.push_field(""),
        }
    }
    r
}

/// The mapped channels each read from the one channel group that has all their columns:
/// (the group and its columns, the mapping of those channels with the group's time); and
/// the mapped topics no group of this file has every column of.
fn plan(mapping: &MappingFile, layout: &Layout) -> (Vec<(Wanted, MappingFile)>, Vec<String>) {
    let groups = signals::groups(layout);
    let has = |names: &[String], column: &str| {
        names
            .iter()
            .any(|n| n == column || n.strip_suffix(column).is_some_and(|p| p.ends_with('.')))
    };
    let mut plan: Vec<(Wanted, MappingFile)> = Vec::new();
    let mut unmatched = Vec::new();
    for c in &mapping.mapping.channel {
        let columns: Vec<&String> = c.fields.values().collect();
        let Some((d, g, _, _)) = groups
            .iter()
            .find(|(_, _, _, names)| columns.iter().all(|col| has(names, col)))
        else {
            unmatched.push(c.topic.clone());
            continue;
        };
        let at = plan
            .iter()
            .position(|(w, _)| (w.data_group, w.channel_group) == (*d, *g));
        let at = at.unwrap_or_else(|| {
            plan.push((
                Wanted {
                    data_group: *d,
                    channel_group: *g,
                    channels: Vec::new(),
                },
                group_mapping(mapping),
            ));
            plan.len() - 1
        });
        let (w, m) = &mut plan[at];
        for col in columns {
            if !w.channels.contains(col) {
                w.channels.push(col.clone());
            }
            default_unit(
                &mut m.mapping.columns,
                col,
                &layout.data_groups[*d].groups[*g],
                &c.fields,
            );
        }
        // A group's rows carry its master time: a channel's own time is a table's.
        let mut c = c.clone();
        c.time = None;
        m.mapping.channel.push(c);
    }
    (plan, unmatched)
}

/// The mapping for one group's rows: the same columns, no channels yet, the time in the
/// row's first cell.
fn group_mapping(mapping: &MappingFile) -> MappingFile {
    let mut m = mapping.clone();
    m.mapping.channel.clear();
    m.mapping.time = Some(TimeSpec {
        column: Some(TIME_COLUMN.into()),
        unit: Some("ns".into()),
        ..TimeSpec::default()
    });
    m
}

/// Where the mapping states nothing of a column, the MDF channel's unit, if it is one the
/// fields it fills take.
fn default_unit(
    columns: &mut BTreeMap<String, ColumnSpec>,
    column: &str,
    group: &railfuse_mdf::layout::ChannelGroup,
    fields: &BTreeMap<String, String>,
) {
    let Some(unit) = group.channel(column).map(|c| c.unit.trim().to_owned()) else {
        return;
    };
    if columns.contains_key(column) || unit.is_empty() {
        return;
    }
    let fits = fields
        .iter()
        .filter(|(_, c)| *c == column)
        .all(|(field, _)| {
            crate::units::of_field(field)
                .is_some_and(|(units, what)| crate::units::factor(units, &unit, what).is_ok())
        });
    if fits {
        columns.insert(
            column.to_owned(),
            ColumnSpec {
                scale: 1.0,
                offset: 0.0,
                unit: Some(unit),
            },
        );
    }
}

/// Why a file gives nothing: its groups, and what the mapping asked for.
fn nothing_to_read(layout: &Layout, mapping: Option<&MappingFile>, unmatched: &[String]) -> String {
    let groups: Vec<String> = signals::groups(layout)
        .into_iter()
        .map(|(d, g, name, channels)| {
            let name = if name.is_empty() {
                format!("group {d}.{g}")
            } else {
                name
            };
            format!("{name} ({})", channels.join(", "))
        })
        .collect();
    let groups = if groups.is_empty() {
        "none".to_owned()
    } else {
        groups.join("; ")
    };
    match mapping {
        None => format!(
            "no CAN bus logging group (CAN_DataFrame); its measured signals' groups ({groups}) are read with a column mapping: --map MAPPING.toml"
        ),
        Some(m) => format!(
            "no channel group has every column {} maps for {}; its groups: {groups}",
            m.path.display(),
            unmatched.join(", ")
        ),
    }
}

/// The frames' channels, one per bus.
#[derive(Default)]
struct BusWriter {
    channels: BTreeMap<String, ChannelId>,
}

impl BusWriter {
    fn write(
        &mut self,
        log: &mut LogWriter,
        frame: &railfuse_can::frame::Frame,
        report: &mut Converted,
    ) -> Result<()> {
        let channel = match self.channels.get(&frame.bus) {
            Some(&c) => c,
            None => {
                let c = log.add_channel::<CanFrame>(&frames_topic(&frame.bus))?;
                self.channels.insert(frame.bus.clone(), c);
                c
            }
        };
        log.write(
            channel,
            frame.stamp_ns,
            &CanFrame::from_frame(frame, frame.stamp_ns),
        )?;
        report.count(&frames_topic(&frame.bus));
        Ok(())
    }
}

/// What the bus and the signals read, into the conversion's report.
fn finish_report(
    report: &mut Converted,
    frames: &BusFrames,
    signals: &Signals,
    unmatched: &[String],
) {
    let r = &frames.report;
    report.rows = r.records.max(signals.records);
    // The bus reader counts every other group's records as not bus logging; with a mapping
    // those are the measured signals, read.
    let read_signals = signals.samples > 0;
    report.skipped.extend(
        r.not_used()
            .into_iter()
            .filter(|(why, _)| !(read_signals && why.ends_with("(not CAN bus logging)"))),
    );
    report.damage = r.damage.clone().or_else(|| signals.damage.clone());
    if signals.out_of_order > 0 {
        report.skipped.insert(
            "a sample earlier than the one before (a damaged time)".into(),
            signals.out_of_order,
        );
    }
    if !unmatched.is_empty() {
        report.warnings.push(format!(
            "no channel group has every mapped column of {}",
            unmatched.join(", ")
        ));
    }
    if r.start_is_local {
        report
            .warnings
            .push("the header's start is local time with no offset to UTC: taken as UTC".into());
    }
    if !r.finalised {
        report
            .warnings
            .push("not finalised by its logger: read to the end of its data".into());
    }
}
