//! The writer's file side: the thread that compresses chunks, writes them with their
//! indexes, and writes the summary at the end, so that the caller's thread only encodes.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::mpsc::Receiver;

use mcap::records::{
    op, ChunkHeader, ChunkIndex, DataEnd, MetadataIndex, Statistics, SummaryOffset,
};

use crate::error::{Error, Result};
use crate::log::format::{self, put_record, MAGIC};

use super::*;

/// The worker's side: the file, its offset and CRC, and the indexes that need offsets.
pub(super) struct FileSide {
    out: BufWriter<File>,
    path: PathBuf,
    offset: u64,
    crc: crc32fast::Hasher,
    compressor: zstd::bulk::Compressor<'static>,
    chunk_indexes: Vec<u8>,
    metadata_indexes: Vec<u8>,
    attachment_indexes: Vec<u8>,
    scratch: Vec<u8>,
    compressed: Vec<u8>,
}

impl FileSide {
    pub(super) fn new(file: File, path: PathBuf, level: u32) -> Self {
        Self {
            // Small: chunks (tens of KiB and more) go to the file without a copy into it.
            out: BufWriter::with_capacity(16 << 10, file),
            path,
            offset: 0,
            crc: crc32fast::Hasher::new(),
            compressor: zstd::bulk::Compressor::new(level as i32).expect("a valid zstd level"),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            attachment_indexes: Vec::new(),
            scratch: Vec::new(),
            compressed: Vec::new(),
        }
    }

    pub(super) fn run(
        &mut self,
        start: Vec<u8>,
        jobs: Receiver<Job>,
        spares: std::sync::mpsc::Sender<Vec<u8>>,
    ) -> Result<()> {
        self.put(&start)?;
        while let Ok(job) = jobs.recv() {
            match job {
                Job::Records(r) => self.put(&r)?,
                Job::Metadata { record, name } => {
                    let index = MetadataIndex {
                        offset: self.offset,
                        length: record.len() as u64,
                        name,
                    };
                    self.put(&record)?;
                    put_record(
                        &mut self.metadata_indexes,
                        op::METADATA_INDEX,
                        &format::body(&index),
                    );
                }
                Job::Attachment { record, mut index } => {
                    index.offset = self.offset;
                    self.put(&record)?;
                    put_record(
                        &mut self.attachment_indexes,
                        op::ATTACHMENT_INDEX,
                        &format::body(&index),
                    );
                }
                Job::Compress {
                    records,
                    index,
                    start,
                    end,
                } => {
                    let mut compressed = std::mem::take(&mut self.compressed);
                    compressed.clear();
                    compressed.reserve(zstd::zstd_safe::compress_bound(records.len()));
                    self.compressor
                        .compress_to_buffer(&records, &mut compressed)
                        .map_err(|e| self.error(e))?;
                    let header = ChunkHeader {
                        message_start_time: start,
                        message_end_time: end,
                        uncompressed_size: records.len() as u64,
                        uncompressed_crc: crc32fast::hash(&records),
                        compression: "zstd".into(),
                        compressed_size: compressed.len() as u64,
                    };
                    // The frame and header, then the compressed records: no copy to join them.
                    let mut head = std::mem::take(&mut self.scratch);
                    head.clear();
                    let body = format::body(&header);
                    head.push(op::CHUNK);
                    head.extend_from_slice(&((body.len() + compressed.len()) as u64).to_le_bytes());
                    head.extend_from_slice(&body);
                    let result = self.put_chunk(&[&head, &compressed], &header, index);
                    self.scratch = head;
                    self.compressed = compressed;
                    let _ = spares.send(records); // the writer may be gone
                    result?;
                }
                Job::Copy { raw, header, index } => self.put_chunk(&[&raw], &header, index)?,
                Job::Flush(done) => {
                    self.out.flush().map_err(|e| self.error(e))?;
                    let _ = done.send(());
                }
                Job::Finish {
                    schemas,
                    channels,
                    statistics,
                } => return self.finish(schemas, channels, statistics),
            }
        }
        Ok(())
    }

    fn error(&self, e: impl std::error::Error) -> Error {
        Error::write(&self.path, e)
    }

    fn put(&mut self, bytes: &[u8]) -> Result<()> {
        self.out
            .write_all(bytes)
            .map_err(|e| Error::write(&self.path, e))?;
        self.crc.update(bytes);
        self.offset += bytes.len() as u64;
        Ok(())
    }

    /// A chunk record, then its message indexes, and its entry for the chunk index.
    fn put_chunk(&mut self, parts: &[&[u8]], header: &ChunkHeader, index: Index) -> Result<()> {
        let chunk_start = self.offset;
        for part in parts {
            self.put(part)?;
        }
        let indexes_start = self.offset;
        let mut offsets = BTreeMap::new();
        let mut records = Vec::new();
        for (channel, entries) in index {
            offsets.insert(channel, indexes_start + records.len() as u64);
            let mut body = Vec::with_capacity(6 + 16 * entries.len());
            body.extend_from_slice(&channel.to_le_bytes());
            body.extend_from_slice(&((16 * entries.len()) as u32).to_le_bytes());
            for e in entries {
                body.extend_from_slice(&e.log_time.to_le_bytes());
                body.extend_from_slice(&e.offset.to_le_bytes());
            }
            put_record(&mut records, op::MESSAGE_INDEX, &body);
        }
        self.put(&records)?;
        let chunk_index = ChunkIndex {
            message_start_time: header.message_start_time,
            message_end_time: header.message_end_time,
            chunk_start_offset: chunk_start,
            chunk_length: indexes_start - chunk_start,
            message_index_offsets: offsets,
            message_index_length: records.len() as u64,
            compression: header.compression.clone(),
            compressed_size: header.compressed_size,
            uncompressed_size: header.uncompressed_size,
        };
        put_record(
            &mut self.chunk_indexes,
            op::CHUNK_INDEX,
            &format::body(&chunk_index),
        );
        Ok(())
    }

    fn finish(
        &mut self,
        schemas: Vec<u8>,
        channels: Vec<u8>,
        statistics: Statistics,
    ) -> Result<()> {
        let data_crc = std::mem::take(&mut self.crc).finalize();
        let mut data_end = Vec::new();
        put_record(
            &mut data_end,
            op::DATA_END,
            &format::body(&DataEnd {
                data_section_crc: data_crc,
            }),
        );
        self.put(&data_end)?;

        let summary_start = self.offset;
        self.crc = crc32fast::Hasher::new();
        let mut stats = Vec::new();
        put_record(&mut stats, op::STATISTICS, &format::body(&statistics));
        let groups = [
            (op::SCHEMA, schemas),
            (op::CHANNEL, channels),
            (op::STATISTICS, stats),
            (op::CHUNK_INDEX, std::mem::take(&mut self.chunk_indexes)),
            (
                op::ATTACHMENT_INDEX,
                std::mem::take(&mut self.attachment_indexes),
            ),
            (
                op::METADATA_INDEX,
                std::mem::take(&mut self.metadata_indexes),
            ),
        ];
        let mut offsets = Vec::new();
        for (opcode, group) in groups.iter().filter(|(_, g)| !g.is_empty()) {
            let offset = SummaryOffset {
                group_opcode: *opcode,
                group_start: self.offset,
                group_length: group.len() as u64,
            };
            put_record(&mut offsets, op::SUMMARY_OFFSET, &format::body(&offset));
            self.put(group)?;
        }
        let summary_offset_start = self.offset;
        self.put(&offsets)?;
        // The footer's CRC covers the summary up to and including the footer's own offsets.
        let mut footer = vec![op::FOOTER];
        footer.extend_from_slice(&20u64.to_le_bytes()); // summary start, offset start, CRC
        footer.extend_from_slice(&summary_start.to_le_bytes());
        footer.extend_from_slice(&summary_offset_start.to_le_bytes());
        self.put(&footer)?;
        let crc = std::mem::take(&mut self.crc).finalize();
        self.put(&crc.to_le_bytes())?;
        self.put(MAGIC)?;
        self.out.flush().map_err(|e| Error::write(&self.path, e))?;
        self.out
            .get_ref()
            .sync_all()
            .map_err(|e| Error::io(&self.path, e))
    }
}
