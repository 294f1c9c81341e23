//! Streaming MCAP reader yielding schemas, channels, messages, metadata and attachments in file
//! order, borrowing message payloads from the decompressed chunk (no copy per message).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{op, AttachmentHeader, MessageHeader, Metadata, Record};

use super::format::{self, Records, FRAME};
use super::scan::{Chunk, Item, ReadAhead, Scanner, READ_AHEAD_BYTES};
use super::IdMap;

use crate::error::{Error, Result};
use crate::messages::{AnyMessage, ChannelMessage, MessageKind};
use crate::protobuf::Encoding;

#[derive(Debug, Clone, PartialEq)]
pub struct SchemaInfo {
    pub id: u16,
    pub name: String,
    pub encoding: String,
    pub data: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
    pub schema: Option<Arc<SchemaInfo>>,
}

impl ChannelInfo {
    pub fn schema_name(&self) -> &str {
        self.schema.as_ref().map_or("", |s| s.name.as_str())
    }

    /// The catalogue message kind of its schema, if railfuse knows it.
    pub fn kind(&self) -> Option<MessageKind> {
        MessageKind::from_schema(self.schema_name())
    }
}

/// One message, its payload borrowed from the reader.
#[derive(Debug)]
pub struct LogMessage<'a> {
    pub channel: &'a Arc<ChannelInfo>,
    pub sequence: u32,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub data: &'a [u8],
}

impl LogMessage<'_> {
    /// Whether the payload is protobuf (else JSON).
    fn is_protobuf(&self) -> bool {
        self.channel.message_encoding == Encoding::Protobuf.message_encoding()
    }

    /// Decodes the payload (JSON or protobuf, as its channel says) as `M`, naming the file,
    /// topic and time if it does not fit.
    pub fn decode<M: ChannelMessage>(&self, path: &Path) -> Result<M> {
        if self.is_protobuf() {
            return crate::protobuf::decode(self.data)
                .map_err(|cause| self.undecodable(path, M::SCHEMA_NAME, cause));
        }
        serde_json::from_slice(self.data).map_err(|source| Error::Decode {
            path: path.to_owned(),
            topic: self.channel.topic.clone(),
            schema: M::SCHEMA_NAME.to_owned(),
            log_time_ns: self.log_time_ns,
            source,
        })
    }

    /// Decodes the payload as whatever catalogue kind its channel carries; `None` for a
    /// schema the catalogue does not know.
    pub fn decode_any(&self, path: &Path) -> Result<Option<AnyMessage>> {
        let Some(kind) = self.channel.kind() else {
            return Ok(None);
        };
        if self.is_protobuf() {
            return kind
                .decode_protobuf(self.data)
                .map(Some)
                .map_err(|cause| self.undecodable(path, kind.schema_name(), cause));
        }
        kind.decode(self.data)
            .map(Some)
            .map_err(|source| Error::Decode {
                path: path.to_owned(),
                topic: self.channel.topic.clone(),
                schema: kind.schema_name().to_owned(),
                log_time_ns: self.log_time_ns,
                source,
            })
    }

    /// The error of a payload that does not decode as `schema`, for `cause`.
    fn undecodable(&self, path: &Path, schema: &str, cause: String) -> Error {
        Error::Undecodable {
            path: path.to_owned(),
            topic: self.channel.topic.clone(),
            schema: schema.to_owned(),
            log_time_ns: self.log_time_ns,
            cause,
        }
    }

    /// True when the channel's schema is `M`'s.
    pub fn is<M: ChannelMessage>(&self) -> bool {
        self.channel.schema_name() == M::SCHEMA_NAME
    }
}

#[derive(Debug)]
pub enum LogRecord<'a> {
    Schema(Arc<SchemaInfo>),
    Channel(Arc<ChannelInfo>),
    Message(LogMessage<'a>),
    Metadata {
        name: String,
        metadata: BTreeMap<String, String>,
    },
    Attachment {
        name: String,
        media_type: String,
        log_time_ns: u64,
        create_time_ns: u64,
        data: &'a [u8],
    },
}

/// A streaming reader over one MCAP file, in file order: top-level records, and the records
/// of each chunk as the read-ahead thread hands the chunk over decompressed.
pub struct LogReader {
    path: PathBuf,
    items: ReadAhead,
    schemas: IdMap<Arc<SchemaInfo>>,
    channels: IdMap<Arc<ChannelInfo>>,
    done: bool,
    /// The chunk being walked and where in its records.
    chunk: Option<Chunk>,
    at: usize,
    /// The top-level record being handed out (unchunked messages, attachments).
    top: Vec<u8>,
    emit: Emit,
    /// The message handed out last, until the next record: a run's merge holds it as the
    /// head of its file while it hands out those of other files.
    held: Option<Held>,
}

/// Where the last message handed out lies.
#[derive(Clone, Copy)]
struct Held {
    header: MessageHeader,
    /// In the chunk's records at `start..end`, else the top-level record's payload.
    in_chunk: Option<(usize, usize)>,
}

/// What `next` hands out, found before the borrow that returns it.
enum Emit {
    Nothing,
    Schema(u16),
    Channel(u16),
    ChunkMessage {
        header: MessageHeader,
        start: usize,
        end: usize,
    },
    TopMessage {
        header: MessageHeader,
    },
    Metadata(Option<Metadata>),
    Attachment {
        header: AttachmentHeader,
        start: usize,
        end: usize,
    },
}

impl LogReader {
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_owned();
        let scanner = Scanner::open(&path)?;
        Ok(Self {
            path,
            items: ReadAhead::new(scanner, READ_AHEAD_BYTES),
            schemas: IdMap::default(),
            channels: IdMap::default(),
            done: false,
            chunk: None,
            at: 0,
            top: Vec::new(),
            emit: Emit::Nothing,
            held: None,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file consumed so far (for progress and throughput).
    pub fn bytes_read(&self) -> u64 {
        self.items.position()
    }

    pub fn channel(&self, id: u16) -> Option<&Arc<ChannelInfo>> {
        self.channels.get(&id)
    }

    /// The next record in file order, or `None` at the end of the data section.
    #[allow(clippy::should_implement_trait)] // a lending iterator: records borrow the reader
    pub fn next(&mut self) -> Option<Result<LogRecord<'_>>> {
        self.held = None;
        match self.advance() {
            Ok(true) => Some(Ok(self.emitted())),
            Ok(false) => None,
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }

    /// Moves to the next record to hand out; false at the end.
    fn advance(&mut self) -> Result<bool> {
        loop {
            if self.done {
                return Ok(false);
            }
            if let Some(chunk) = &self.chunk {
                let records = &chunk.records;
                if self.at < records.len() {
                    // The scanner checked that every record of the chunk is whole.
                    let framed = Records::new(&records[self.at..])
                        .next()
                        .expect("whole")
                        .expect("checked whole");
                    let start = self.at + FRAME;
                    self.at = start + framed.body.len();
                    let (opcode, end) = (framed.opcode, self.at);
                    if self.accept(opcode, start, end, true)? {
                        return Ok(true);
                    }
                    continue;
                }
                self.chunk = None;
            }
            match self.items.next() {
                None => {
                    self.done = true;
                    return Ok(false);
                }
                Some(Err(e)) => return Err(e),
                Some(Ok(Item::Chunk(c))) => {
                    self.chunk = Some(c);
                    self.at = 0;
                }
                Some(Ok(Item::Record { opcode, body, .. })) => {
                    self.top = body;
                    if self.accept(opcode, 0, self.top.len(), false)? {
                        return Ok(true);
                    }
                }
                Some(Ok(Item::Damage(d))) => {
                    return Err(Error::Damaged {
                        path: self.path.clone(),
                        offset: d.offset,
                        cause: d.cause,
                    })
                }
            }
        }
    }

    /// Takes in the record at `start..end` of the chunk (or of `top`); says whether to hand
    /// it out.
    fn accept(&mut self, opcode: u8, start: usize, end: usize, in_chunk: bool) -> Result<bool> {
        let body = match (in_chunk, &self.chunk) {
            (true, Some(c)) => &c.records[start..end],
            _ => &self.top[start..end],
        };
        let bad = |e: String| Error::mcap(&self.path, e);
        self.emit = match opcode {
            op::MESSAGE => {
                let m = format::parse_message(body)
                    .ok_or_else(|| bad("a message record is cut short".into()))?;
                if !self.channels.contains_key(&m.header.channel_id) {
                    return Err(bad(format!(
                        "message at log time {} on unknown channel {}",
                        m.header.log_time, m.header.channel_id
                    )));
                }
                let start = start + format::MESSAGE_HEADER;
                match in_chunk {
                    true => Emit::ChunkMessage {
                        header: m.header,
                        start,
                        end,
                    },
                    false => Emit::TopMessage { header: m.header },
                }
            }
            op::SCHEMA | op::CHANNEL | op::METADATA | op::ATTACHMENT => {
                let record = mcap::parse_record(opcode, body).map_err(|e| bad(describe(&e)))?;
                match record {
                    Record::Schema { header, data } => {
                        if self.schemas.contains_key(&header.id) {
                            return Ok(false);
                        }
                        let info = SchemaInfo {
                            id: header.id,
                            name: header.name,
                            encoding: header.encoding,
                            data: data.into_owned(),
                        };
                        self.schemas.insert(info.id, Arc::new(info));
                        Emit::Schema(header.id)
                    }
                    Record::Channel(c) => {
                        if self.channels.contains_key(&c.id) {
                            return Ok(false);
                        }
                        let schema = match c.schema_id {
                            0 => None,
                            id => Some(self.schemas.get(&id).cloned().ok_or_else(|| {
                                bad(format!("channel {} names unknown schema {id}", c.topic))
                            })?),
                        };
                        let info = ChannelInfo {
                            id: c.id,
                            topic: c.topic,
                            message_encoding: c.message_encoding,
                            metadata: c.metadata,
                            schema,
                        };
                        self.channels.insert(c.id, Arc::new(info));
                        Emit::Channel(c.id)
                    }
                    Record::Metadata(m) => Emit::Metadata(Some(m)),
                    Record::Attachment { header, data, .. } => {
                        // The data sits just before the trailing CRC.
                        let end = end - 4;
                        Emit::Attachment {
                            start: end - data.len(),
                            end,
                            header,
                        }
                    }
                    _ => return Ok(false),
                }
            }
            _ => return Ok(false),
        };
        Ok(true)
    }

    fn emitted(&mut self) -> LogRecord<'_> {
        let held = match std::mem::replace(&mut self.emit, Emit::Nothing) {
            Emit::Schema(id) => return LogRecord::Schema(self.schemas[&id].clone()),
            Emit::Channel(id) => return LogRecord::Channel(self.channels[&id].clone()),
            Emit::ChunkMessage { header, start, end } => Held {
                header,
                in_chunk: Some((start, end)),
            },
            Emit::TopMessage { header } => Held {
                header,
                in_chunk: None,
            },
            Emit::Metadata(m) => {
                let m = m.expect("set by accept");
                return LogRecord::Metadata {
                    name: m.name,
                    metadata: m.metadata,
                };
            }
            Emit::Attachment { header, start, end } => {
                return LogRecord::Attachment {
                    name: header.name,
                    media_type: header.media_type,
                    log_time_ns: header.log_time,
                    create_time_ns: header.create_time,
                    data: &self.top[start..end],
                }
            }
            Emit::Nothing => unreachable!("emitted() follows a successful advance()"),
        };
        self.held = Some(held);
        LogRecord::Message(self.current_message().expect("just held"))
    }

    /// The message [`next`](Self::next) handed out last, while no other record has followed
    /// it.
    pub fn current_message(&self) -> Option<LogMessage<'_>> {
        let held = self.held?;
        let data = match (held.in_chunk, &self.chunk) {
            (Some((start, end)), Some(chunk)) => &chunk.records[start..end],
            (Some(_), None) => return None,
            (None, _) => &self.top[format::MESSAGE_HEADER..],
        };
        Some(LogMessage {
            channel: &self.channels[&held.header.channel_id],
            sequence: held.header.sequence,
            log_time_ns: held.header.log_time,
            publish_time_ns: held.header.publish_time,
            data,
        })
    }
}

/// The mcap crate's errors, in words a field engineer can act on.
fn describe(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::BadMagic => "it does not start with the MCAP magic bytes".into(),
        mcap::McapError::UnexpectedEof | mcap::McapError::UnexpectedEoc => {
            "the file ends in the middle of a record (truncated: was the recording cut off?)".into()
        }
        other => other.to_string(),
    }
}

/// What a file's summary section tells without reading the data.
#[derive(Debug, Clone)]
pub struct LogSummary {
    /// Every channel, by id, when the summary repeats them (`None` when it does not: the
    /// channels are then known only from the data section).
    pub channels: Option<Vec<Arc<ChannelInfo>>>,
    /// The longest time span of one chunk (log time), if the file has chunk indexes.
    pub longest_chunk_ns: Option<u64>,
    /// Log times of the first and last message, from the statistics record, if it has one.
    pub message_span_ns: Option<(u64, u64)>,
}

/// The channel table of a file from its summary section (one seek to the end), or `None` when
/// the file has no summary. A file without a valid footer (truncated) is an error.
pub fn read_channels(path: &Path) -> Result<Option<Vec<Arc<ChannelInfo>>>> {
    Ok(read_summary(path)?.and_then(|s| s.channels))
}

/// The summary section of a file (one seek to the end), or `None` when it has none. A file
/// without a valid footer (truncated) is an error.
///
/// The summary may repeat a channel without its schema (the specification allows it, and
/// the official writers do it): such a schema is then taken from the data section, where
/// it must stand before the channel's first message.
pub fn read_summary(path: &Path) -> Result<Option<LogSummary>> {
    let Some(raw) = read_summary_records(path)? else {
        return Ok(None);
    };
    let mut schemas: IdMap<Arc<SchemaInfo>> = IdMap::default();
    let mut channels = Vec::new();
    let (mut longest_chunk_ns, mut message_span_ns) = (None::<u64>, None);
    for framed in Records::new(&raw) {
        let framed = framed.map_err(|e| Error::mcap(path, format!("summary: {e}")))?;
        if !matches!(
            framed.opcode,
            op::SCHEMA | op::CHANNEL | op::CHUNK_INDEX | op::STATISTICS
        ) {
            continue;
        }
        let record = mcap::parse_record(framed.opcode, framed.body)
            .map_err(|e| Error::mcap(path, format!("summary: {}", describe(&e))))?;
        match record {
            Record::Schema { header, data } => {
                let info = SchemaInfo {
                    id: header.id,
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                };
                schemas.insert(info.id, Arc::new(info));
            }
            Record::Channel(c) => channels.push(c),
            Record::ChunkIndex(c) => {
                let span = c.message_end_time.saturating_sub(c.message_start_time);
                longest_chunk_ns = Some(longest_chunk_ns.map_or(span, |l| l.max(span)));
            }
            Record::Statistics(st) if st.message_count > 0 => {
                message_span_ns = Some((st.message_start_time, st.message_end_time));
            }
            _ => {}
        }
    }
    let missing: Vec<u16> = channels
        .iter()
        .map(|c| c.schema_id)
        .filter(|&id| id != 0 && !schemas.contains_key(&id))
        .collect();
    if !missing.is_empty() {
        schemas.extend(schemas_from_data(path, &missing)?);
    }
    let mut channels: Vec<_> = channels
        .into_iter()
        .map(|c| {
            Arc::new(ChannelInfo {
                id: c.id,
                schema: schemas.get(&c.schema_id).cloned(),
                topic: c.topic,
                message_encoding: c.message_encoding,
                metadata: c.metadata,
            })
        })
        .collect();
    channels.sort_by_key(|c| c.id);
    channels.dedup_by_key(|c| c.id);
    Ok(Some(LogSummary {
        channels: (!channels.is_empty()).then_some(channels),
        longest_chunk_ns,
        message_span_ns,
    }))
}

/// The metadata record `name` of a file, found through its summary's metadata index (two
/// seeks, no data read); `None` when the file has no summary or no such record.
pub fn read_metadata(path: &Path, name: &str) -> Result<Option<BTreeMap<String, String>>> {
    use std::io::{Seek, SeekFrom};
    let Some(raw) = read_summary_records(path)? else {
        return Ok(None);
    };
    for framed in Records::new(&raw) {
        let framed = framed.map_err(|e| Error::mcap(path, format!("summary: {e}")))?;
        if framed.opcode != op::METADATA_INDEX {
            continue;
        }
        let Ok(Record::MetadataIndex(index)) = mcap::parse_record(framed.opcode, framed.body)
        else {
            continue;
        };
        if index.name != name {
            continue;
        }
        if index.length > super::RECORD_LENGTH_LIMIT as u64 {
            return Err(Error::mcap(
                path,
                "a metadata record longer than any railfuse reads",
            ));
        }
        let mut file = open_checked(path)?;
        let mut record = vec![0u8; index.length as usize];
        file.seek(SeekFrom::Start(index.offset))
            .and_then(|_| file.read_exact(&mut record))
            .map_err(|e| Error::io(path, e))?;
        let at_index = || {
            Error::mcap(
                path,
                format!("no metadata record where the index puts {name}"),
            )
        };
        let framed = Records::new(&record)
            .next()
            .ok_or_else(at_index)?
            .map_err(|_| at_index())?;
        return match mcap::parse_record(framed.opcode, framed.body) {
            Ok(Record::Metadata(m)) => Ok(Some(m.metadata)),
            _ => Err(at_index()),
        };
    }
    Ok(None)
}

/// The records of the summary section, from the footer's offsets; `None` when the file has no
/// summary. A file without a valid footer (truncated) is an error.
fn read_summary_records(path: &Path) -> Result<Option<Vec<u8>>> {
    use std::io::{Seek, SeekFrom};
    // Footer record (opcode, length, summary start, summary offset start, CRC), then magic.
    const FOOTER: u64 = 1 + 8 + 8 + 8 + 4;
    let mut file = open_checked(path)?;
    let size = file.metadata().map_err(|e| Error::io(path, e))?.len();
    // Where a file without its footer is damaged, as `info` says it: the first record a
    // strict scan cannot read, else the missing footer itself.
    let truncated = || {
        let mut scan = match Scanner::open(path) {
            Ok(scan) => scan,
            Err(e) => return e,
        };
        while let Some(item) = scan.next() {
            if let Err(e) = item {
                return e;
            }
        }
        Error::Damaged {
            path: path.to_owned(),
            offset: size,
            cause: "the file ends without its footer (truncated: was the recording cut off?)"
                .into(),
        }
    };
    if size < 8 + FOOTER + 8 {
        return Err(truncated());
    }
    let mut tail = [0u8; (FOOTER + 8) as usize];
    file.seek(SeekFrom::Start(size - FOOTER - 8))
        .and_then(|_| file.read_exact(&mut tail))
        .map_err(|e| Error::io(path, e))?;
    if tail[0] != op::FOOTER || &tail[FOOTER as usize..] != mcap::MAGIC {
        return Err(truncated());
    }
    let at = |i: usize| u64::from_le_bytes(tail[i..i + 8].try_into().expect("8 bytes"));
    let (start, offsets) = (at(9), at(17));
    let end = if offsets != 0 {
        offsets
    } else {
        size - FOOTER - 8
    };
    if start == 0 {
        return Ok(None);
    }
    if start > end || end > size - FOOTER - 8 || end - start > super::RECORD_LENGTH_LIMIT as u64 {
        return Err(Error::mcap(path, "the footer points outside the file"));
    }
    let mut raw = vec![0u8; (end - start) as usize];
    file.seek(SeekFrom::Start(start))
        .and_then(|_| file.read_exact(&mut raw))
        .map_err(|e| Error::io(path, e))?;
    Ok(Some(raw))
}

/// The schemas `ids` as the data section defines them (read until all are found).
fn schemas_from_data(path: &Path, ids: &[u16]) -> Result<Vec<(u16, Arc<SchemaInfo>)>> {
    let mut found = Vec::new();
    let mut reader = LogReader::open(path)?;
    while let Some(record) = reader.next() {
        if let LogRecord::Schema(s) = record? {
            if ids.contains(&s.id) && !found.iter().any(|(id, _)| *id == s.id) {
                found.push((s.id, s));
                if found.len() == ids.len() {
                    break;
                }
            }
        }
    }
    Ok(found)
}

/// Opens a file that must be an MCAP file: not empty, starting with the MCAP magic.
fn open_checked(path: &Path) -> Result<File> {
    use std::io::{Seek, SeekFrom};
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut magic = [0u8; 8];
    let mut got = 0;
    while got < magic.len() {
        match file.read(&mut magic[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    if got == 0 {
        return Err(Error::Empty {
            path: path.to_owned(),
        });
    }
    if magic[..got] != mcap::MAGIC[..got] || got < magic.len() {
        return Err(Error::mcap(
            path,
            "it does not start with the MCAP magic bytes: not an MCAP file",
        ));
    }
    file.seek(SeekFrom::Start(0))
        .map_err(|e| Error::io(path, e))?;
    Ok(file)
}
