//! ROS 1 bags (format 2.0, `.bag`): every connection a channel (message encoding `ros1`,
//! schema encoding `ros1msg` with the connection's message definition, as `mcap convert`
//! writes one), every message copied byte for byte at its record time. The channels railfuse
//! reads (NavSatFix, Imu, twists, Odometry: see [`crate::foreign::ros1`]) then read as
//! catalogue messages like a ROS 2 bag's; the others are kept as they are and counted by
//! type. `/tf_static` is read and reported: where each sensor frame sits on the vehicle.
//!
//! The bag is read from its start, record by record, chunks (uncompressed, bz2, lz4)
//! decompressed one at a time: its index is not needed, so a bag whose recording did not
//! finish (no index, `index_pos` 0) reads as `rosbag reindex` would read it, and a bag cut off
//! keeps every message before the cut.
//!
//! Why not the `rosbag` crate: it maps the file and slices it at the header's `index_pos`
//! (a bag without an index panics), allocates each chunk at the size its header claims, and
//! decompresses lz4 without a bound. Here every length is checked against the file and a
//! bound before it is allocated (see [`records`]).

pub mod records;

use std::collections::{BTreeMap, HashMap};
use std::io::{BufReader, Read};
use std::path::Path;

use self::records::{BagRecords, Record, Stop};
use super::Converted;
use crate::error::{Error, Result};
use crate::foreign::ros1;
use crate::log::{LogWriter, WriterOptions};

/// Converts the bag at `input` to MCAP at `output`, streaming.
pub fn convert(input: &Path, output: &Path, writer: &WriterOptions) -> Result<Converted> {
    let file = std::fs::File::open(input).map_err(|e| Error::io(input, e))?;
    let size = file.metadata().map_err(|e| Error::io(input, e))?.len();
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let mut magic = [0u8; records::MAGIC.len()];
    if reader.read_exact(&mut magic).is_err() || magic != records::MAGIC {
        let why = match magic.starts_with(b"#ROSBAG V") {
            true => format!(
                "a ROS bag of format {}: only format 2.0 is read",
                String::from_utf8_lossy(&magic[9..]).trim()
            ),
            false => "no `#ROSBAG V2.0` line: not a ROS 1 bag".to_owned(),
        };
        return Err(Error::run(input, why));
    }
    let mut bag = Bag::new(LogWriter::create_with(output, writer)?);
    let mut records = BagRecords::new(reader, size);
    // The bag header first: where its index is, whose connection records name every
    // connection before a chunk that does not repeat them is read.
    match records.next_record() {
        Ok(Some(header)) if header.fields.op() == Some(records::OP_BAG_HEADER) => {
            bag.top_level(header)?;
            if let Some(at) = bag.index_pos.filter(|p| (1..size).contains(p)) {
                bag.index_connections(input, at, size)?;
            }
        }
        Ok(Some(other)) => bag.top_level(other)?,
        Ok(None) => {}
        Err(Stop::Io(e)) => return Err(Error::run(input, e)),
        Err(Stop::CutOff(d) | Stop::Damaged(d)) => bag.report.damage = Some(d),
    }
    while bag.report.damage.is_none() {
        match records.next_record() {
            Ok(Some(record)) => bag.top_level(record)?,
            Ok(None) => break,
            Err(Stop::CutOff(d) | Stop::Damaged(d)) => {
                bag.report.damage = Some(d);
                break;
            }
            Err(Stop::Io(e)) => return Err(Error::run(input, e)),
        }
    }
    bag.finish(input, size)
}

/// A connection: the channel its messages go on, and its type.
struct Connection {
    channel: u16,
    topic: String,
    ros_type: String,
}

/// The conversion under way.
struct Bag {
    writer: LogWriter,
    report: Converted,
    connections: HashMap<u32, Connection>,
    /// Channel ids by (topic, type), schema ids by type: connections of one topic from
    /// several publishers share a channel.
    channels: HashMap<(String, String), u16>,
    schemas: HashMap<String, u16>,
    sequence: HashMap<u16, u32>,
    /// Messages of types railfuse does not read, by type.
    kept: BTreeMap<String, u64>,
    /// The header's `index_pos` (0: the recording did not finish).
    index_pos: Option<u64>,
    last_ns: u64,
}

impl Bag {
    fn new(writer: LogWriter) -> Self {
        Self {
            writer,
            report: Converted::default(),
            connections: HashMap::new(),
            channels: HashMap::new(),
            schemas: HashMap::new(),
            sequence: HashMap::new(),
            kept: BTreeMap::new(),
            index_pos: None,
            last_ns: 0,
        }
    }

    /// A record of the file itself (not inside a chunk).
    fn top_level(&mut self, record: Record) -> Result<()> {
        match record.fields.op() {
            Some(records::OP_BAG_HEADER) => {
                self.index_pos = record.fields.u64("index_pos");
                Ok(())
            }
            Some(records::OP_CHUNK) => self.chunk(record),
            Some(records::OP_INDEX | records::OP_CHUNK_INFO) => Ok(()),
            _ => self.record(record, None),
        }
    }

    /// The connection records of the index section (from `at` to the end): read before the
    /// chunks, so a message meets its connection even where its chunk does not repeat it. An
    /// index that does not read is left to the scan, which needs none.
    fn index_connections(&mut self, input: &Path, at: u64, size: u64) -> Result<()> {
        use std::io::{Seek, SeekFrom};
        let mut file = std::fs::File::open(input).map_err(|e| Error::io(input, e))?;
        file.seek(SeekFrom::Start(at))
            .map_err(|e| Error::io(input, e))?;
        let mut index = BagRecords::new(BufReader::new(file), size);
        index.skip_to(at);
        while let Ok(Some(record)) = index.next_record() {
            if record.fields.op() == Some(records::OP_CONNECTION) {
                // A connection the scan meets again is taken once.
                let _ = self.connection(&record);
            }
        }
        Ok(())
    }

    /// A chunk: its records, decompressed.
    fn chunk(&mut self, record: Record) -> Result<()> {
        let compression = record.fields.text("compression").unwrap_or_default();
        let size = record.fields.u32("size").unwrap_or(u32::MAX);
        let data = match records::decompress(&compression, &record.data, size) {
            Ok(d) => d,
            Err(e) => {
                let detail = format!("chunk at byte {}: {e}", record.offset);
                self.report.skip("a chunk that does not decompress", detail);
                return Ok(());
            }
        };
        for inner in records::chunk_records(&data, record.offset) {
            match inner {
                Ok(r) => self.record(r, Some(record.offset))?,
                Err(e) => self.report.skip("a damaged record in a chunk", e),
            }
        }
        Ok(())
    }

    /// A connection or a message (in a chunk at `chunk`, or not).
    fn record(&mut self, record: Record, chunk: Option<u64>) -> Result<()> {
        let at = || match chunk {
            Some(c) => format!("chunk at byte {c}"),
            None => format!("byte {}", record.offset),
        };
        match record.fields.op() {
            Some(records::OP_CONNECTION) => self.connection(&record).or_else(|e| {
                self.report
                    .skip("a connection that does not read", format!("{}: {e}", at()));
                Ok(())
            }),
            Some(records::OP_MESSAGE) => self.message(&record, &at),
            Some(records::OP_INDEX | records::OP_CHUNK_INFO) => Ok(()),
            op => {
                let detail = format!("{}: op {op:?}", at());
                self.report.skip("a record of an unknown kind", detail);
                Ok(())
            }
        }
    }

    /// A connection: its channel and schema (once per id; the index repeats them).
    fn connection(&mut self, record: &Record) -> std::result::Result<(), String> {
        let id = record.fields.u32("conn").ok_or("no `conn` field")?;
        if self.connections.contains_key(&id) {
            return Ok(());
        }
        let topic = record.fields.text("topic").ok_or("no `topic` field")?;
        let info = records::Fields::parse(&record.data)?;
        let ros_type = info.text("type").ok_or("no `type` field")?;
        let definition = info.get("message_definition").unwrap_or_default();
        let next = self.schemas.len() as u16 + 1;
        let schema = *self.schemas.entry(ros_type.clone()).or_insert(next);
        let copy = self
            .writer
            .copy_schema(schema, &ros_type, ros1::SCHEMA_ENCODING, definition);
        copy.map_err(|e| e.to_string())?;
        let key = (topic.clone(), ros_type.clone());
        let next = u16::try_from(self.channels.len() + 1).map_err(|_| "over 65 535 channels")?;
        let channel = *self.channels.entry(key).or_insert(next);
        let metadata: BTreeMap<String, String> = ["md5sum", "callerid", "latching"]
            .iter()
            .filter_map(|k| Some(((*k).to_owned(), info.text(k)?)))
            .collect();
        self.writer
            .copy_channel(channel, schema, &topic, ros1::ENCODING, &metadata)
            .map_err(|e| e.to_string())?;
        self.connections.insert(
            id,
            Connection {
                channel,
                topic,
                ros_type,
            },
        );
        Ok(())
    }

    /// A message, copied onto its connection's channel at its record time.
    fn message(&mut self, record: &Record, at: &dyn Fn() -> String) -> Result<()> {
        self.report.rows += 1;
        let conn = record.fields.u32("conn");
        let (Some(c), Some(time)) = (
            conn.and_then(|id| self.connections.get(&id)),
            record.fields.time_ns("time"),
        ) else {
            let why = "a message of no known connection, or without a time";
            self.report.skip(why, format!("{}: conn {conn:?}", at()));
            return Ok(());
        };
        // A run is read in time order: a message recorded before one already written (a bag
        // merged or filtered out of order) is counted, not written.
        if time < self.last_ns {
            let why = "a message earlier than one before it (the bag is not in time order)";
            self.report
                .skip(why, format!("{}: {} at {time} ns", at(), c.topic));
            return Ok(());
        }
        self.last_ns = time;
        let seq = self.sequence.entry(c.channel).or_insert(0);
        *seq += 1;
        self.writer
            .write_raw(c.channel, *seq, time, time, &record.data)?;
        self.report.count(&c.topic);
        if !ros1::reads(&c.ros_type) {
            *self.kept.entry(c.ros_type.clone()).or_insert(0) += 1;
        } else if c.topic == "/tf_static" && c.ros_type == ros1::TF_MESSAGE {
            match ros1::transforms(&record.data) {
                Ok(t) => super::add_frames(&mut self.report.frames, t),
                Err(e) => self
                    .report
                    .skip("a /tf_static message that does not read", e),
            }
        }
        Ok(())
    }

    fn finish(mut self, input: &Path, size: u64) -> Result<Converted> {
        if self.index_pos.is_none_or(|p| p == 0 || p >= size) && self.report.messages > 0 {
            self.report.warnings.push(
                "no index (the recording did not finish): read by scanning, as `rosbag reindex` would".into(),
            );
        }
        if !self.kept.is_empty() {
            let types: Vec<String> = self.kept.iter().map(|(t, n)| format!("{n} {t}")).collect();
            self.report.warnings.push(format!(
                "kept as they are, of types railfuse does not read: {}",
                types.join(", ")
            ));
        }
        if self.report.messages == 0 {
            let why = match (&self.report.damage, self.report.skipped.is_empty()) {
                (Some(d), _) => d.clone(),
                (None, true) => "no message in the bag".to_owned(),
                (None, false) => format!("no message read: {}", self.report.reasons()),
            };
            return Err(Error::run(input, why));
        }
        self.writer.finish()?;
        Ok(self.report)
    }
}

#[cfg(test)]
mod tests;
