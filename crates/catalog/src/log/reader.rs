//! Streaming MCAP reader yielding schemas, channels, messages, metadata and attachments in file
//! order, borrowing message payloads from the decoder's buffer (no copy per message).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, Result};
use crate::messages::ChannelMessage;

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

/// A streaming reader over one MCAP file.
pub struct LogReader {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    schemas: HashMap<u16, Arc<SchemaInfo>>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    /// Set once the data section ends: what follows is the summary, which repeats records.
    in_summary: bool,
    done: bool,
    bytes_read: u64,
    // Parsed records whose payload must outlive `next_event`'s borrow (chunk contents are
    // decompressed into the reader and handed out as owned data).
    current: Option<Record<'static>>,
}

impl LogReader {
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_owned();
        let file = open_checked(&path)?;
        let options = LinearReaderOptions::default()
            .with_record_length_limit(super::RECORD_LENGTH_LIMIT)
            .with_validate_chunk_crcs(true);
        Ok(Self {
            path,
            file,
            reader: LinearReader::new_with_options(options),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            in_summary: false,
            done: false,
            bytes_read: 0,
            current: None,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file consumed so far (for progress and throughput).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read
    }

    pub fn channel(&self, id: u16) -> Option<&Arc<ChannelInfo>> {
        self.channels.get(&id)
    }

    /// The next record in file order, or `None` at the end of the file.
    #[allow(clippy::should_implement_trait)] // a lending iterator: records borrow the reader
    pub fn next(&mut self) -> Option<Result<LogRecord<'_>>> {
        loop {
            if self.done {
                return None;
            }
            let event = match self.reader.next_event() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(Error::mcap(&self.path, describe(&e))));
                }
                Some(Ok(ev)) => ev,
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let buf = self.reader.insert(need);
                    let n = loop {
                        match self.file.read(buf) {
                            Ok(n) => break n,
                            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                            Err(e) => {
                                self.done = true;
                                return Some(Err(Error::io(&self.path, e)));
                            }
                        }
                    };
                    self.bytes_read += n as u64;
                    self.reader.notify_read(n);
                }
                LinearReadEvent::Record { data, opcode } => {
                    let record = match mcap::parse_record(opcode, data) {
                        Ok(r) => r.into_owned(),
                        Err(e) => {
                            self.done = true;
                            return Some(Err(Error::mcap(&self.path, describe(&e))));
                        }
                    };
                    self.current = Some(record);
                    // Split borrows: the record lives in `self.current`, the tables beside it.
                    match self.accept() {
                        Ok(true) => return Some(Ok(self.emit())),
                        Ok(false) => continue,
                        Err(e) => {
                            self.done = true;
                            return Some(Err(e));
                        }
                    }
                }
            }
        }
    }

    /// Updates the schema/channel tables from the current record; says whether to emit it.
    fn accept(&mut self) -> Result<bool> {
        let record = self.current.as_ref().expect("set by caller");
        Ok(match record {
            Record::DataEnd(_) => {
                self.in_summary = true;
                false
            }
            _ if self.in_summary => false,
            Record::Schema { header, data } => {
                if self.schemas.contains_key(&header.id) {
                    return Ok(false);
                }
                let info = Arc::new(SchemaInfo {
                    id: header.id,
                    name: header.name.clone(),
                    encoding: header.encoding.clone(),
                    data: data.to_vec(),
                });
                self.schemas.insert(header.id, info);
                true
            }
            Record::Channel(c) => {
                if self.channels.contains_key(&c.id) {
                    return Ok(false);
                }
                let schema = if c.schema_id == 0 {
                    None
                } else {
                    Some(self.schemas.get(&c.schema_id).cloned().ok_or_else(|| {
                        Error::mcap(
                            &self.path,
                            format!("channel {} names unknown schema {}", c.topic, c.schema_id),
                        )
                    })?)
                };
                let info = Arc::new(ChannelInfo {
                    id: c.id,
                    topic: c.topic.clone(),
                    message_encoding: c.message_encoding.clone(),
                    metadata: c.metadata.clone(),
                    schema,
                });
                self.channels.insert(c.id, info);
                true
            }
            Record::Message { header, .. } => {
                if !self.channels.contains_key(&header.channel_id) {
                    return Err(Error::mcap(
                        &self.path,
                        format!(
                            "message at log time {} on unknown channel {}",
                            header.log_time, header.channel_id
                        ),
                    ));
                }
                true
            }
            Record::Metadata(_) | Record::Attachment { .. } => true,
            _ => false,
        })
    }

    fn emit(&self) -> LogRecord<'_> {
        match self.current.as_ref().expect("set by caller") {
            Record::Schema { header, .. } => LogRecord::Schema(self.schemas[&header.id].clone()),
            Record::Channel(c) => LogRecord::Channel(self.channels[&c.id].clone()),
            Record::Message { header, data } => LogRecord::Message(LogMessage {
                channel: &self.channels[&header.channel_id],
                sequence: header.sequence,
                log_time_ns: header.log_time,
                publish_time_ns: header.publish_time,
                data,
            }),
            Record::Metadata(m) => LogRecord::Metadata {
                name: m.name.clone(),
                metadata: m.metadata.clone(),
            },
            Record::Attachment { header, data, .. } => LogRecord::Attachment {
                name: header.name.clone(),
                media_type: header.media_type.clone(),
                log_time_ns: header.log_time,
                create_time_ns: header.create_time,
                data,
            },
            _ => unreachable!("accept() only passes the kinds above"),
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

/// The channel table of a file from its summary section (one seek to the end), or `None` when
/// the file has no summary. A file without a valid footer (truncated) is an error.
pub fn read_channels(path: &Path) -> Result<Option<Vec<Arc<ChannelInfo>>>> {
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
    Ok(Some(channels))
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
