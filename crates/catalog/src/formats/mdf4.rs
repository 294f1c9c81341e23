//! ASAM MDF 4 bus logging (CSS CANedge, Vector, most vehicle loggers) into a run: every CAN
//! frame of every `CAN_DataFrame`, `CAN_RemoteFrame` and `CAN_ErrorFrame` group onto
//! `/can/<bus>/frames` (the bus `CAN<n>`, its `BusChannel`), in time order, each stamped with
//! the header's start plus its master time. The reading is `railfuse-mdf`'s (streamed, every
//! block bounded); a configuration's `[can]` table decodes the frames as it does a live bus's.
//! A drive a logger split into files (CANedge: ten-minute files) is read as one run by naming
//! them all, or their folder.

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_mdf::bus::BusFrames;

use super::Converted;
use crate::error::{Error, Result};
use crate::foreign::can::frames_topic;
use crate::log::{ChannelId, LogWriter, WriterOptions};
use crate::messages::CanFrame;

/// Converts the MDF file `input` to MCAP at `output`.
pub fn convert(input: &Path, output: &Path, writer: &WriterOptions) -> Result<Converted> {
    let fault = |e: railfuse_mdf::MdfError| Error::run(input, e);
    let mut frames = BusFrames::open(input).map_err(fault)?;
    if !frames.has_bus_logging() {
        return Err(Error::run(
            input,
            format!(
                "no CAN bus logging group (CAN_DataFrame) among its groups ({}): measured \
                 signals' groups are not read yet",
                frames.group_names().join(", ")
            ),
        ));
    }
    let mut log = LogWriter::create_with(output, writer)?;
    let mut channels: BTreeMap<String, ChannelId> = BTreeMap::new();
    let mut report = Converted::default();
    for frame in frames.by_ref() {
        let channel = match channels.get(&frame.bus) {
            Some(&c) => c,
            None => {
                let c = log.add_channel::<CanFrame>(&frames_topic(&frame.bus))?;
                channels.insert(frame.bus.clone(), c);
                c
            }
        };
        log.write(
            channel,
            frame.stamp_ns,
            &CanFrame::from_frame(&frame, frame.stamp_ns),
        )?;
        report.count(&frames_topic(&frame.bus));
    }
    let r = &frames.report;
    report.rows = r.records;
    report.skipped = r.not_used();
    report.damage = r.damage.clone();
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
    if report.messages == 0 {
        let why = match &report.damage {
            Some(d) => d.clone(),
            None => format!("{} records but no CAN frame", report.rows),
        };
        return Err(Error::run(input, why));
    }
    log.finish()?;
    Ok(report)
}
