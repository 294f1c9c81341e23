//! Streaming MCAP reader yielding schemas, channels, messages, metadata and attachments in file
//! order, borrowing message payloads from the decompressed chunk (no copy per message).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{op, AttachmentHeader, MessageHeader, Metadata, Record};

use super::format::{self, Records, FRAME};
use super::scan::{Chunk, Item, ReadAhead, Scanner, READ_AHEAD_BYTES};

use crate::error::{Error, Result};
use crate::messages::{AnyMessage, ChannelMessage, MessageKind};

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
    /// Decodes the JSON payload as `M`, naming the file, topic and time if it does not fit.
    pub fn decode<M: ChannelMessage>(&self, path: &Path) -> Result<M> {
        serde_json::from_slice(self.data).map_err(|source| Error::Decode {
            path: path.to_owned(),
            topic: self.channel.topic.clone(),
            schema: M::SCHEMA_NAME.to_owned(),
            log_time_ns: self.log_time_ns,
            source,
        })
    }

    /// Decodes some of the payload's fields (a struct naming a subset of its type's fields):
    /// the others are skipped without being converted, which is cheaper on a hot path.
    pub fn decode_fields<T: serde::de::DeserializeOwned>(&self, path: &Path) -> Result<T> {
        serde_json::from_slice(self.data).map_err(|source| Error::Decode {
            path: path.to_owned(),
            topic: self.channel.topic.clone(),
            schema: self.channel.schema_name().to_owned(),
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
    schemas: HashMap<u16, Arc<SchemaInfo>>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    done: bool,
    /// The chunk being walked and where in its records.
    chunk: Option<Chunk>,
    at: usize,
    /// The top-level record being handed out (unchunked messages, attachments).
    top: Vec<u8>,
    emit: Emit,
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
            schemas: HashMap::new(),
            channels: HashMap::new(),
            done: false,
            chunk: None,
            at: 0,
            top: Vec::new(),
            emit: Emit::Nothing,
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
        let chunk = self.chunk.as_ref().map_or(&[][..], |c| &c.records[..]);
        match std::mem::replace(&mut self.emit, Emit::Nothing) {
            Emit::Schema(id) => LogRecord::Schema(self.schemas[&id].clone()),
            Emit::Channel(id) => LogRecord::Channel(self.channels[&id].clone()),
            Emit::ChunkMessage { header, start, end } => LogRecord::Message(LogMessage {
                channel: &self.channels[&header.channel_id],
                sequence: header.sequence,
                log_time_ns: header.log_time,
                publish_time_ns: header.publish_time,
                data: &chunk[start..end],
            }),
            Emit::TopMessage { header } => LogRecord::Message(LogMessage {
                channel: &self.channels[&header.channel_id],
                sequence: header.sequence,
                log_time_ns: header.log_time,
                publish_time_ns: header.publish_time,
                data: &self.top[format::MESSAGE_HEADER..],
            }),
            Emit::Metadata(m) => {
                let m = m.expect("set by accept");
                LogRecord::Metadata {
                    name: m.name,
                    metadata: m.metadata,
                }
            }
            Emit::Attachment { header, start, end } => LogRecord::Attachment {
                name: header.name,
                media_type: header.media_type,
                log_time_ns: header.log_time,
                create_time_ns: header.create_time,
                data: &self.top[start..end],
            },
            Emit::Nothing => unreachable!("emitted() follows a successful advance()"),
        }
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
    /// Every channel, by id.
    pub channels: Vec<Arc<ChannelInfo>>,
    /// The longest time span of one chunk (log time), if the file has chunk indexes.
    pub longest_chunk_ns: Option<u64>,
    /// Log times of the first and last message, from the statistics record, if it has one.
    pub message_span_ns: Option<(u64, u64)>,
}

/// The channel table of a file from its summary section (one seek to the end), or `None` when
/// the file has no summary. A file without a valid footer (truncated) is an error.
pub fn read_channels(path: &Path) -> Result<Option<Vec<Arc<ChannelInfo>>>> {
    Ok(read_summary(path)?.map(|s| s.channels))
}

/// The summary section of a file (one seek to the end), or `None` when it has none. A file
/// without a valid footer (truncated) is an error.
pub fn read_summary(path: &Path) -> Result<Option<LogSummary>> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    use std::io::Seek;
    let mut file = open_checked(path)?;
    let size = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut options = SummaryReaderOptions::default().with_file_size(size);
    options.record_length_limit = Some(super::RECORD_LENGTH_LIMIT);
    let mut reader = SummaryReader::new_with_options(options);
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| Error::mcap(path, describe(&e)))? {
            SummaryReadEvent::ReadRequest(need) => {
                let n = file
                    .read(reader.insert(need))
                    .map_err(|e| Error::io(path, e))?;
                reader.notify_read(n);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file.seek(to).map_err(|e| Error::io(path, e))?;
                reader.notify_seeked(pos);
            }
        }
    }
    let Some(summary) = reader.finish() else {
        return Ok(None);
    };
    let mut channels: Vec<_> = summary
        .channels
        .values()
        .map(|c| {
            Arc::new(ChannelInfo {
                id: c.id,
                topic: c.topic.clone(),
                message_encoding: c.message_encoding.clone(),
                metadata: c.metadata.clone(),
                schema: c.schema.as_ref().map(|s| {
                    Arc::new(SchemaInfo {
                        id: s.id,
                        name: s.name.clone(),
                        encoding: s.encoding.clone(),
                        data: s.data.to_vec(),
                    })
                }),
            })
        })
        .collect();
    channels.sort_by_key(|c| c.id);
    let longest_chunk_ns = summary
        .chunk_indexes
        .iter()
        .map(|c| c.message_end_time.saturating_sub(c.message_start_time))
        .max();
    let message_span_ns = summary
        .stats
        .as_ref()
        .filter(|s| s.message_count > 0)
        .map(|s| (s.message_start_time, s.message_end_time));
    Ok(Some(LogSummary {
        channels,
        longest_chunk_ns,
        message_span_ns,
    }))
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
