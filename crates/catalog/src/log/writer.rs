//! MCAP writer for railfuse channels: zstd chunks, message indexes, summary, metadata.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;

use crate::error::{Error, Result};
use crate::messages::ChannelMessage;

/// A channel registered with a [`LogWriter`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ChannelId(pub u16);

#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Uncompressed bytes per chunk before it is compressed and written.
    pub chunk_size: u64,
    /// zstd level (1 is fast and already shrinks JSON about tenfold).
    pub zstd_level: u32,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_size: 1 << 20,
            zstd_level: 1,
        }
    }
}

/// Writes a railfuse log. The output appears under its name only after [`LogWriter::finish`]:
/// until then it is written beside it as `<name>.partial`, so a failed run never leaves a
/// half-written file that looks complete, and never clobbers an existing good file.
pub struct LogWriter {
    path: PathBuf,
    partial: PathBuf,
    inner: Option<mcap::Writer<BufWriter<File>>>,
    schemas: HashMap<&'static str, u16>,
    sequences: HashMap<u16, u32>,
    buf: Vec<u8>,
}

impl LogWriter {
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        Self::create_with(path, &WriterOptions::default())
    }

    pub fn create_with(path: impl AsRef<Path>, options: &WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_owned();
        let mut partial = path.clone().into_os_string();
        partial.push(".partial");
        let partial = PathBuf::from(partial);
        let file = File::create(&partial).map_err(|e| Error::io(&partial, e))?;
        let inner = mcap::WriteOptions::new()
            .profile(super::PROFILE)
            .library(concat!("railfuse ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(options.zstd_level)
            .chunk_size(Some(options.chunk_size))
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|e| Error::write(&partial, e))?;
        Ok(Self {
            path,
            partial,
            inner: Some(inner),
            schemas: HashMap::new(),
            sequences: HashMap::new(),
            buf: Vec::with_capacity(1024),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn inner(&mut self) -> &mut mcap::Writer<BufWriter<File>> {
        self.inner
            .as_mut()
            .expect("only finish() takes the writer, and it consumes self")
    }

    /// Registers a channel of message type `M` on `topic`.
    pub fn add_channel<M: ChannelMessage>(&mut self, topic: &str) -> Result<ChannelId> {
        let schema_id = match self.schemas.get(M::SCHEMA_NAME) {
            Some(&id) => id,
            None => {
                let data = M::schema_bytes();
                let id = self
                    .inner()
                    .add_schema(M::SCHEMA_NAME, super::SCHEMA_ENCODING, &data)
                    .map_err(|e| Error::write(&self.partial, e))?;
                self.schemas.insert(M::SCHEMA_NAME, id);
                id
            }
        };
        let id = self
            .inner()
            .add_channel(schema_id, topic, super::MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(|e| Error::write(&self.partial, e))?;
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
        let data = M::schema_bytes();
        self.inner()
            .add_schema_with_id(schema_id, M::SCHEMA_NAME, super::SCHEMA_ENCODING, &data)
            .map_err(|e| Error::write(&self.partial, e))?;
        self.inner()
            .add_channel_with_id(
                channel_id,
                schema_id,
                topic,
                super::MESSAGE_ENCODING,
                &BTreeMap::new(),
            )
            .map_err(|e| Error::write(&self.partial, e))?;
        Ok(ChannelId(channel_id))
    }

    /// Writes `msg` with the given receive time; `publish_time` is the message's own stamp.
    pub fn write<M: ChannelMessage>(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        msg: &M,
    ) -> Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        serde_json::to_writer(&mut buf, msg).map_err(|e| Error::write(&self.partial, e))?;
        let sequence = self.next_sequence(channel.0);
        let result = self.write_raw(channel.0, sequence, log_time_ns, msg.stamp_ns(), &buf);
        self.buf = buf;
        result
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
        self.inner()
            .write_to_known_channel(&header, data)
            .map_err(|e| Error::write(&self.partial, e))
    }

    /// Closes the current chunk and pushes it to the file: everything written so far survives
    /// a crash from here on (the recorder calls this about once a second).
    pub fn flush_chunk(&mut self) -> Result<()> {
        self.inner()
            .flush()
            .map_err(|e| Error::write(&self.partial, e))
    }

    /// Copies a schema record keeping its id.
    pub fn copy_schema(&mut self, id: u16, name: &str, encoding: &str, data: &[u8]) -> Result<()> {
        self.inner()
            .add_schema_with_id(id, name, encoding, data)
            .map_err(|e| Error::write(&self.partial, e))?;
        Ok(())
    }

    /// Copies a channel record keeping its id.
    pub fn copy_channel(
        &mut self,
        id: u16,
        schema_id: u16,
        topic: &str,
        encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<()> {
        self.inner()
            .add_channel_with_id(id, schema_id, topic, encoding, metadata)
            .map_err(|e| Error::write(&self.partial, e))?;
        Ok(())
    }

    pub fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        let record = mcap::records::Metadata {
            name: name.to_owned(),
            metadata,
        };
        self.inner()
            .write_metadata(&record)
            .map_err(|e| Error::write(&self.partial, e))
    }

    pub fn attach(
        &mut self,
        name: &str,
        media_type: &str,
        log_time_ns: u64,
        create_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let attachment = mcap::Attachment {
            log_time: log_time_ns,
            create_time: create_time_ns,
            name: name.to_owned(),
            media_type: media_type.to_owned(),
            data: std::borrow::Cow::Borrowed(data),
        };
        self.inner()
            .attach(&attachment)
            .map_err(|e| Error::write(&self.partial, e))
    }

    /// Writes the summary and index, flushes, and moves the file to its final name.
    pub fn finish(mut self) -> Result<()> {
        let mut inner = self.inner.take().expect("finish() runs once");
        inner.finish().map_err(|e| Error::write(&self.partial, e))?;
        let file = inner
            .into_inner()
            .into_inner()
            .map_err(|e| Error::io(&self.partial, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&self.partial, e))?;
        std::fs::rename(&self.partial, &self.path).map_err(|e| Error::io(&self.path, e))
    }
}

impl Drop for LogWriter {
    fn drop(&mut self) {
        // Dropped without finish(): an error path. Leave no `.partial` file behind.
        if self.inner.take().is_some() {
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}
