//! The log writer: messages gathered into chunks, compressed and written on a worker thread,
//! input chunks copied byte for byte, and the summary (schemas, channels, statistics, chunk,
//! metadata and attachment indexes) at the end.
//!
//! The calling thread encodes messages and frames records; the worker owns the file: it
//! compresses, writes, and keeps the offsets the indexes need. A write error stops the worker;
//! the next call returns it, with its cause ("No space left on device").

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use mcap::records::{
    op, AttachmentHeader, AttachmentIndex, Channel, ChunkHeader, Header, MessageHeader,
    MessageIndexEntry, Metadata, SchemaHeader, Statistics,
};

use super::format::{self, put_message, put_record, Records, FRAME, MAGIC};
use super::scan::Chunk;
use super::IdMap;
use crate::error::{Error, Result};
use crate::foxglove::{Twin, TwinKind};
use crate::messages::{AnyMessage, ChannelMessage, MessageKind};
use crate::protobuf::{schema_data, Encoding};

mod file_side;

use file_side::FileSide;

/// A channel registered with a [`LogWriter`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ChannelId(pub u16);

#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Uncompressed bytes per chunk before it is compressed and written.
    pub chunk_size: u64,
    /// zstd level (1 is fast and already shrinks JSON about tenfold).
    pub zstd_level: u32,
    /// Write Foxglove twins of GNSS fixes, the track map and events beside them
    /// ([`crate::foxglove`]).
    pub foxglove: bool,
    /// The encoding of railfuse's channels ([`crate::protobuf`]).
    pub encoding: Encoding,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_size: 1 << 20,
            zstd_level: 1,
            foxglove: crate::foxglove::twins_by_default(),
            encoding: crate::protobuf::encoding_by_default(),
        }
    }
}

type Index = BTreeMap<u16, Vec<MessageIndexEntry>>;

/// What a chunk copied byte for byte brings to the output's indexes, gathered in one walk
/// over its records: each message's index entry, and the schema and channel records it
/// defines. A caller that walks the chunk for its own reasons feeds each record here, so that
/// the copy ([`LogWriter::copy_tallied_chunk`]) needs no second walk.
#[derive(Default)]
pub struct ChunkTally {
    index: Index,
    /// (opcode, id, framed record) of each schema and channel record.
    definitions: Vec<(u8, u16, Vec<u8>)>,
}

impl ChunkTally {
    /// One record of the chunk, in order.
    pub fn record(&mut self, record: &format::Framed<'_>) {
        match record.opcode {
            op::MESSAGE => {
                if let Some(m) = format::parse_message(record.body) {
                    self.message(record.offset, &m.header);
                }
            }
            op::SCHEMA | op::CHANNEL => {
                let mut framed = Vec::with_capacity(FRAME + record.body.len());
                put_record(&mut framed, record.opcode, record.body);
                let id = channel_of(record.body);
                self.definitions.push((record.opcode, id, framed));
            }
            _ => {}
        }
    }

    /// A message record at `offset` in the chunk, its header parsed by the caller.
    pub fn message(&mut self, offset: usize, header: &MessageHeader) {
        self.index
            .entry(header.channel_id)
            .or_default()
            .push(MessageIndexEntry {
                log_time: header.log_time,
                offset: offset as u64,
            });
    }
}

/// Work for the file side.
enum Job {
    /// Framed top-level records (schemas, channels).
    Records(Vec<u8>),
    Metadata {
        record: Vec<u8>,
        name: String,
    },
    Attachment {
        record: Vec<u8>,
        index: AttachmentIndex,
    },
    /// Records to compress into a chunk.
    Compress {
        records: Vec<u8>,
        index: Index,
        start: u64,
        end: u64,
    },
    /// A chunk record to write as it is.
    Copy {
        raw: Vec<u8>,
        header: ChunkHeader,
        index: Index,
    },
    /// Hand everything so far to the OS, then answer.
    Flush(SyncSender<()>),
    Finish {
        schemas: Vec<u8>,
        channels: Vec<u8>,
        statistics: Statistics,
    },
}

/// Messages gathered for the next chunk.
#[derive(Default)]
struct OpenChunk {
    records: Vec<u8>,
    index: Index,
    start: u64,
    end: u64,
}

/// Writes a railfuse log. The output appears under its name only after [`LogWriter::finish`]:
/// until then it is written beside it as `<name>.partial`, so a failed run never leaves a
/// half-written file that looks complete, and never clobbers an existing good file.
pub struct LogWriter {
    path: PathBuf,
    partial: PathBuf,
    chunk_size: usize,
    jobs: Option<SyncSender<Job>>,
    /// Chunk buffers the worker is done with, for the next chunks.
    spares: Receiver<Vec<u8>>,
    worker: Option<JoinHandle<Result<()>>>,
    /// Schema ids by name and encoding (`jsonschema` or `protobuf`).
    schema_ids: HashMap<(String, String), u16>,
    /// The channels whose `message_encoding` is protobuf (registered or copied).
    protobuf_channels: HashSet<u16>,
    /// The encoding of the channels this writer registers.
    encoding: Encoding,
    /// Framed schema and channel records, repeated in the summary.
    schemas: BTreeMap<u16, Vec<u8>>,
    channels: BTreeMap<u16, Vec<u8>>,
    sequences: IdMap<u32>,
    /// Topics by channel id, to name twin channels.
    topics: IdMap<String>,
    /// Foxglove twins: on, and the twin channel of each source channel.
    foxglove: bool,
    twins: IdMap<ChannelId>,
    open: OpenChunk,
    stats: Statistics,
    buf: Vec<u8>,
}

impl LogWriter {
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        Self::create_with(path, &WriterOptions::default())
    }

    pub fn create_with(path: impl AsRef<Path>, options: &WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_owned();
        Self::create_working(&path, &partial_path(&path), options)
    }

    /// Writes `path`, by way of `working` (instead of `<path>.partial`) until it is finished.
    pub fn create_working(path: &Path, working: &Path, options: &WriterOptions) -> Result<Self> {
        let (path, partial) = (path.to_owned(), working.to_owned());
        // Named as the user wrote it: the output and its folder, not the working file.
        if let Some(dir) = path
            .parent()
            .filter(|d| !d.as_os_str().is_empty() && !d.is_dir())
        {
            return Err(Error::Write {
                path: path.clone(),
                cause: format!("its folder {} does not exist", dir.display()),
            });
        }
        let file = File::create(&partial).map_err(|e| Error::io(&partial, e))?;
        let mut start = MAGIC.to_vec();
        let header = Header {
            profile: super::PROFILE.into(),
            library: concat!("railfuse ", env!("CARGO_PKG_VERSION")).into(),
        };
        put_record(&mut start, op::HEADER, &format::body(&header));
        let (jobs, rx) = sync_channel(4);
        let (spare_tx, spares) = std::sync::mpsc::channel();
        let mut file_side = FileSide::new(file, partial.clone(), options.zstd_level);
        let worker = std::thread::Builder::new()
            .name("log-writer".into())
            .spawn(move || file_side.run(start, rx, spare_tx))
            .map_err(|e| Error::io(&partial, e))?;
        Ok(Self {
            path,
            partial,
            chunk_size: options.chunk_size as usize,
            jobs: Some(jobs),
            spares,
            worker: Some(worker),
            schema_ids: HashMap::new(),
            protobuf_channels: HashSet::new(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            sequences: IdMap::default(),
            topics: IdMap::default(),
            foxglove: options.foxglove,
            encoding: options.encoding,
            twins: IdMap::default(),
            open: OpenChunk::default(),
            stats: Statistics::default(),
            buf: Vec::with_capacity(1024),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the working file on disk so far (what the worker has written).
    pub fn bytes_on_disk(&self) -> u64 {
        std::fs::metadata(&self.partial).map_or(0, |m| m.len())
    }

    fn send(&mut self, job: Job) -> Result<()> {
        let sent = self
            .jobs
            .as_ref()
            .map(|j| j.send(job).is_ok())
            .unwrap_or(false);
        if sent {
            return Ok(());
        }
        Err(self.stopped())
    }

    /// The worker stopped on an error: that error.
    fn stopped(&mut self) -> Error {
        self.jobs = None;
        match self.worker.take().map(|w| w.join()) {
            Some(Ok(Err(e))) => e,
            _ => Error::Write {
                path: self.partial.clone(),
                cause: "the writer stopped".into(),
            },
        }
    }

    /// Registers a channel of message type `M` on `topic`.
    pub fn add_channel<M: ChannelMessage>(&mut self, topic: &str) -> Result<ChannelId> {
        self.add_channel_of(M::KIND, topic)
    }

    /// Registers a channel of message kind `kind` on `topic`, in the writer's encoding.
    pub fn add_channel_of(&mut self, kind: MessageKind, topic: &str) -> Result<ChannelId> {
        self.add_channel_encoded(kind, topic, self.encoding)
    }

    /// Registers a channel of message kind `kind` on `topic` in `encoding`.
    pub fn add_channel_encoded(
        &mut self,
        kind: MessageKind,
        topic: &str,
        encoding: Encoding,
    ) -> Result<ChannelId> {
        let data = schema_of(kind, encoding);
        self.add_channel_in(kind.schema_name(), &data, topic, encoding)
    }

    /// Registers a channel on `topic` in `encoding` with the schema of that name and encoding
    /// (written on first use), both on the lowest free ids.
    fn add_channel_in(
        &mut self,
        schema: &str,
        data: &[u8],
        topic: &str,
        encoding: Encoding,
    ) -> Result<ChannelId> {
        let key = (schema.to_owned(), encoding.schema_encoding().to_owned());
        let schema_id = match self.schema_ids.get(&key) {
            Some(&id) => id,
            None => {
                let id = (1..=u16::MAX)
                    .find(|i| !self.schemas.contains_key(i))
                    .unwrap_or(0);
                self.copy_schema(id, schema, encoding.schema_encoding(), data)?;
                id
            }
        };
        let id = (1..=u16::MAX)
            .find(|i| !self.channels.contains_key(i))
            .unwrap_or(0);
        self.copy_channel(
            id,
            schema_id,
            topic,
            encoding.message_encoding(),
            &BTreeMap::new(),
        )?;
        Ok(ChannelId(id))
    }

    /// Registers a channel of type `M` with explicit schema and channel ids (for outputs added
    /// beside copied input records, whose ids must stay as they were).
    pub fn add_channel_with_ids<M: ChannelMessage>(
        &mut self,
        schema_id: u16,
        channel_id: u16,
        topic: &str,
    ) -> Result<ChannelId> {
        self.add_channel_of_with_ids(M::KIND, schema_id, channel_id, topic, &BTreeMap::new())
    }

    /// [`add_channel_with_ids`](Self::add_channel_with_ids) for a kind known at run time,
    /// with the channel's metadata.
    pub fn add_channel_of_with_ids(
        &mut self,
        kind: MessageKind,
        schema_id: u16,
        channel_id: u16,
        topic: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<ChannelId> {
        let encoding = self.encoding;
        if !self.schemas.contains_key(&schema_id) {
            let data = schema_of(kind, encoding);
            self.copy_schema(
                schema_id,
                kind.schema_name(),
                encoding.schema_encoding(),
                &data,
            )?;
        }
        let message_encoding = encoding.message_encoding();
        self.copy_channel(channel_id, schema_id, topic, message_encoding, metadata)?;
        Ok(ChannelId(channel_id))
    }

    /// Writes a schema record keeping its id (once per id).
    pub fn copy_schema(&mut self, id: u16, name: &str, encoding: &str, data: &[u8]) -> Result<()> {
        if self.schemas.contains_key(&id) {
            return Ok(());
        }
        let record = schema_record(id, name, encoding, data);
        let key = (name.to_owned(), encoding.to_owned());
        self.schema_ids.entry(key).or_insert(id);
        self.schemas.insert(id, record.clone());
        self.send(Job::Records(record))
    }

    /// Writes a channel record keeping its id (once per id).
    pub fn copy_channel(
        &mut self,
        id: u16,
        schema_id: u16,
        topic: &str,
        encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<()> {
        if self.channels.contains_key(&id) {
            return Ok(());
        }
        self.topics.insert(id, topic.to_owned());
        if Encoding::of_channel(encoding) == Some(Encoding::Protobuf) {
            self.protobuf_channels.insert(id);
        }
        let channel = Channel {
            id,
            schema_id,
            topic: topic.to_owned(),
            message_encoding: encoding.to_owned(),
            metadata: metadata.clone(),
        };
        let mut record = Vec::new();
        put_record(&mut record, op::CHANNEL, &format::body(&channel));
        self.channels.insert(id, record.clone());
        self.send(Job::Records(record))
    }

    /// Writes `msg` with the given receive time (`publish_time` is the message's own stamp),
    /// and its Foxglove twin if twins are on and its kind has one.
    pub fn write<M: ChannelMessage>(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        msg: &M,
    ) -> Result<()> {
        self.write_message(channel, log_time_ns, msg)?;
        match self.foxglove.then(|| Twin::of(msg)).flatten() {
            Some(twin) => self.write_twin_of(channel, log_time_ns, &twin),
            None => Ok(()),
        }
    }

    /// Writes `msg` alone, without a twin (whose channel the caller registers itself).
    pub fn write_message<M: ChannelMessage>(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        msg: &M,
    ) -> Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        if self.protobuf_channels.contains(&channel.0) {
            crate::protobuf::encode(msg, &mut buf);
        } else {
            serde_json::to_writer(&mut buf, msg).map_err(|e| Error::write(&self.partial, e))?;
        }
        let sequence = self.next_sequence(channel.0);
        let result = self.write_raw(channel.0, sequence, log_time_ns, msg.stamp_ns(), &buf);
        self.buf = buf;
        result
    }

    /// Writes a message of any kind (the channel must be of its kind).
    pub fn write_any(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        msg: &AnyMessage,
    ) -> Result<()> {
        let sequence = self.next_sequence(channel.0);
        let data = match self.protobuf_channels.contains(&channel.0) {
            true => msg.to_protobuf(),
            false => msg.to_json(),
        };
        self.write_raw(channel.0, sequence, log_time_ns, msg.stamp_ns(), &data)?;
        match self.foxglove.then(|| Twin::of_any(msg)).flatten() {
            Some(twin) => self.write_twin_of(channel, log_time_ns, &twin),
            None => Ok(()),
        }
    }

    /// The encoding of a channel this writer registered.
    pub fn encoding_of(&self, channel: ChannelId) -> Encoding {
        match self.protobuf_channels.contains(&channel.0) {
            true => Encoding::Protobuf,
            false => Encoding::Json,
        }
    }

    /// Writes the Foxglove twin of a message of `source` on its twin channel (registered on
    /// first use, `/foxglove` + the source's topic, in the source's encoding).
    pub fn write_twin_of(
        &mut self,
        source: ChannelId,
        log_time_ns: u64,
        twin: &Twin,
    ) -> Result<()> {
        let channel = match self.twins.get(&source.0) {
            Some(&c) => c,
            None => {
                let kind = twin.kind();
                let encoding = self.encoding_of(source);
                let topic = self.topics.get(&source.0).map_or("", String::as_str);
                let topic = crate::foxglove::twin_topic(topic);
                let data = kind.schema_bytes(encoding);
                let c = self.add_channel_in(kind.schema_name(), data, &topic, encoding)?;
                self.twins.insert(source.0, c);
                c
            }
        };
        self.write_twin(channel, log_time_ns, twin)
    }

    /// Registers a channel for Foxglove twins in the writer's encoding with explicit ids (beside copied
    /// input records).
    pub fn add_twin_channel_with_ids(
        &mut self,
        kind: TwinKind,
        schema_id: u16,
        channel_id: u16,
        topic: &str,
    ) -> Result<ChannelId> {
        let encoding = self.encoding;
        let data = kind.schema_bytes(encoding);
        let name = kind.schema_name();
        self.copy_schema(schema_id, name, encoding.schema_encoding(), data)?;
        let message_encoding = encoding.message_encoding();
        self.copy_channel(
            channel_id,
            schema_id,
            topic,
            message_encoding,
            &BTreeMap::new(),
        )?;
        Ok(ChannelId(channel_id))
    }

    /// Writes a Foxglove twin on its own channel, in the channel's encoding.
    pub fn write_twin(&mut self, channel: ChannelId, log_time_ns: u64, twin: &Twin) -> Result<()> {
        let data = twin.encode(self.encoding_of(channel));
        self.write_encoded(channel, log_time_ns, twin.stamp_ns(), &data)
    }

    /// Writes a message already encoded in its channel's encoding (a ROS 2 CDR payload), with
    /// the channel's next sequence number.
    pub fn write_encoded(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let sequence = self.next_sequence(channel.0);
        self.write_raw(channel.0, sequence, log_time_ns, publish_time_ns, data)
    }

    fn next_sequence(&mut self, channel: u16) -> u32 {
        let s = self.sequences.entry(channel).or_insert(0);
        *s = s.wrapping_add(1);
        *s
    }

    /// Writes an already-encoded message to a channel, as-is (used to copy input records).
    pub fn write_raw(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let header = MessageHeader {
            channel_id: channel,
            sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        let open = &mut self.open;
        if open.records.is_empty() {
            (open.start, open.end) = (log_time_ns, log_time_ns);
        }
        (open.start, open.end) = (open.start.min(log_time_ns), open.end.max(log_time_ns));
        let offset = open.records.len() as u64;
        open.index
            .entry(channel)
            .or_default()
            .push(MessageIndexEntry {
                log_time: log_time_ns,
                offset,
            });
        put_message(&mut open.records, &header, data);
        count_messages(&mut self.stats, channel, 1, (log_time_ns, log_time_ns));
        if self.open.records.len() >= self.chunk_size {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Sends the messages gathered so far to be compressed as a chunk.
    pub fn close_chunk(&mut self) -> Result<()> {
        if self.open.records.is_empty() {
            return Ok(());
        }
        let open = std::mem::take(&mut self.open);
        self.open.records = self.spares.try_recv().unwrap_or_default();
        self.open.records.clear();
        self.open
            .records
            .reserve(self.chunk_size + (self.chunk_size >> 3));
        self.stats.chunk_count += 1;
        self.send(Job::Compress {
            records: open.records,
            index: open.index,
            start: open.start,
            end: open.end,
        })
    }

    /// Copies an input chunk byte for byte. The schemas and channels it defines are taken
    /// into the summary; its messages count in the statistics and get a message index. The
    /// chunk is taken, so its bytes go to the file without another copy; its decompressed
    /// records come back, for the caller to reuse ([`ReadAhead::recycle`]).
    ///
    /// [`ReadAhead::recycle`]: super::scan::ReadAhead::recycle
    pub fn copy_chunk(&mut self, chunk: Chunk) -> Result<Vec<u8>> {
        let mut tally = ChunkTally::default();
        for record in Records::new(&chunk.records) {
            tally.record(&record.map_err(|e| Error::mcap(&self.partial, e))?);
        }
        self.copy_tallied_chunk(chunk, tally)
    }

    /// [`copy_chunk`](Self::copy_chunk) for a caller that has walked the chunk's records
    /// already and fed each to `tally`.
    pub fn copy_tallied_chunk(&mut self, chunk: Chunk, tally: ChunkTally) -> Result<Vec<u8>> {
        for (&channel, entries) in &tally.index {
            let span = entries.iter().fold((u64::MAX, 0), |(a, b), e| {
                (a.min(e.log_time), b.max(e.log_time))
            });
            if !entries.is_empty() {
                count_messages(&mut self.stats, channel, entries.len() as u64, span);
            }
        }
        for (opcode, id, framed) in tally.definitions {
            let table = match opcode {
                op::SCHEMA => &mut self.schemas,
                _ => &mut self.channels,
            };
            table.entry(id).or_insert(framed);
        }
        self.stats.chunk_count += 1;
        self.send(Job::Copy {
            raw: chunk.raw,
            header: chunk.header,
            index: tally.index,
        })?;
        Ok(chunk.records)
    }

    /// Copies a message record as it was (channel, sequence, times, payload).
    pub fn copy_message(&mut self, m: &format::MessageView<'_>) -> Result<()> {
        let h = &m.header;
        self.write_raw(h.channel_id, h.sequence, h.log_time, h.publish_time, m.data)
    }

    /// Copies the records of a chunk (decompressed) one by one into new chunks, keeping the
    /// channels `keep` says yes to: every schema, the kept channels and their messages.
    /// Returns, per kept channel, how many messages were copied, and how many were left out.
    pub fn copy_records_where(
        &mut self,
        records: &[u8],
        mut keep: impl FnMut(u16) -> bool,
    ) -> Result<(BTreeMap<u16, u64>, u64)> {
        use mcap::records::Record;
        let (mut copied, mut left_out) = (BTreeMap::new(), 0);
        for record in Records::new(records) {
            let record = record.map_err(|e| Error::mcap(&self.partial, e))?;
            let parsed = || mcap::parse_record(record.opcode, record.body).ok();
            match record.opcode {
                op::SCHEMA => {
                    if let Some(Record::Schema { header: h, data }) = parsed() {
                        self.copy_schema(h.id, &h.name, &h.encoding, &data)?;
                    }
                }
                op::CHANNEL => {
                    if let Some(Record::Channel(c)) =
                        parsed().filter(|_| keep(channel_of(record.body)))
                    {
                        self.copy_channel(
                            c.id,
                            c.schema_id,
                            &c.topic,
                            &c.message_encoding,
                            &c.metadata,
                        )?;
                    }
                }
                op::MESSAGE => {
                    let Some(m) = format::parse_message(record.body) else {
                        continue;
                    };
                    if keep(m.header.channel_id) {
                        self.copy_message(&m)?;
                        *copied.entry(m.header.channel_id).or_insert(0) += 1;
                    } else {
                        left_out += 1;
                    }
                }
                _ => {}
            }
        }
        Ok((copied, left_out))
    }

    /// Closes the current chunk and hands everything written so far to the OS: it survives a
    /// crash of this process from here on (the recorder calls this about once a second).
    pub fn flush_chunk(&mut self) -> Result<()> {
        self.close_chunk()?;
        let (tx, rx) = sync_channel(1);
        self.send(Job::Flush(tx))?;
        match rx.recv() {
            Ok(()) => Ok(()),
            Err(_) => Err(self.stopped()),
        }
    }

    pub fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        let mut record = Vec::new();
        let m = Metadata {
            name: name.to_owned(),
            metadata,
        };
        put_record(&mut record, op::METADATA, &format::body(&m));
        self.stats.metadata_count += 1;
        self.send(Job::Metadata {
            record,
            name: name.to_owned(),
        })
    }

    pub fn attach(
        &mut self,
        name: &str,
        media_type: &str,
        log_time_ns: u64,
        create_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let header = AttachmentHeader {
            log_time: log_time_ns,
            create_time: create_time_ns,
            name: name.to_owned(),
            media_type: media_type.to_owned(),
        };
        let mut body = format::body(&header);
        body.extend_from_slice(&(data.len() as u64).to_le_bytes());
        body.extend_from_slice(data);
        let crc = crc32fast::hash(&body);
        body.extend_from_slice(&crc.to_le_bytes());
        let mut record = Vec::new();
        put_record(&mut record, op::ATTACHMENT, &body);
        let index = AttachmentIndex {
            offset: 0,
            length: record.len() as u64,
            log_time: log_time_ns,
            create_time: create_time_ns,
            data_size: data.len() as u64,
            name: name.to_owned(),
            media_type: media_type.to_owned(),
        };
        self.stats.attachment_count += 1;
        self.send(Job::Attachment { record, index })
    }

    /// Writes the summary and index, flushes, and moves the file to its final name.
    pub fn finish(mut self) -> Result<()> {
        self.close_chunk()?;
        let mut statistics = std::mem::take(&mut self.stats);
        statistics.schema_count = self.schemas.len() as u16;
        statistics.channel_count = self.channels.len() as u32;
        let schemas = self.schemas.values().flatten().copied().collect();
        let channels = self.channels.values().flatten().copied().collect();
        self.send(Job::Finish {
            schemas,
            channels,
            statistics,
        })?;
        self.jobs = None;
        if let Some(Ok(Err(e))) = self.worker.take().map(|w| w.join()) {
            return Err(e);
        }
        std::fs::rename(&self.partial, &self.path).map_err(|e| Error::io(&self.path, e))
    }
}

/// Where the log `path` is written until it is finished: `<path>.partial`.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    PathBuf::from(partial)
}

impl Drop for LogWriter {
    fn drop(&mut self) {
        // Dropped without finish(): an error path (or a panic unwinding). A file that holds
        // messages is never deleted: its open chunk is written too, and the `.partial` stays
        // for `railfuse recover`. Only an empty one is removed.
        if self.worker.is_some() {
            let holds_messages = self.stats.message_count > 0;
            if holds_messages {
                let _ = self.close_chunk();
            }
            self.jobs = None;
            if let Some(worker) = self.worker.take() {
                let _ = worker.join();
            }
            if !holds_messages {
                let _ = std::fs::remove_file(&self.partial);
            }
        }
    }
}

/// The id a schema or channel record body starts with.
fn channel_of(body: &[u8]) -> u16 {
    u16::from_le_bytes([body[0], body[1]])
}

/// `n` messages of `channel` logged between `start` and `end` (ns) into the statistics.
fn count_messages(stats: &mut Statistics, channel: u16, n: u64, (start, end): (u64, u64)) {
    if stats.message_count == 0 {
        (stats.message_start_time, stats.message_end_time) = (start, end);
    }
    stats.message_count += n;
    stats.message_start_time = stats.message_start_time.min(start);
    stats.message_end_time = stats.message_end_time.max(end);
    *stats.channel_message_counts.entry(channel).or_insert(0) += n;
}

fn schema_record(id: u16, name: &str, encoding: &str, data: &[u8]) -> Vec<u8> {
    let header = SchemaHeader {
        id,
        name: name.to_owned(),
        encoding: encoding.to_owned(),
    };
    let mut body = format::body(&header);
    body.extend_from_slice(&(data.len() as u32).to_le_bytes());
    body.extend_from_slice(data);
    let mut record = Vec::new();
    put_record(&mut record, op::SCHEMA, &body);
    record
}

/// The schema data of a channel of `kind` in `encoding`: its JSON schema, or the descriptors
/// of its .proto file.
fn schema_of(kind: MessageKind, encoding: Encoding) -> std::borrow::Cow<'static, [u8]> {
    match encoding {
        Encoding::Json => kind.schema_bytes().into(),
        Encoding::Protobuf => schema_data(kind.schema_name()).into(),
    }
}
