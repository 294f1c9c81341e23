//! `railfuse record`: capture live sources into a crash-safe MCAP log.
//!
//! Each source runs in its own thread with its own bounded queue ([`sources`]); the writer
//! (this module) drains them round-robin, stamps nothing itself (log time is each message's
//! receive time, publish time its sensor time), closes a chunk at least every
//! `chunk_interval` so that a crash loses at most that much (`railfuse recover` salvages the
//! rest), writes its own health on `/recorder/diagnostics`, and finishes the file cleanly when
//! told to stop (SIGINT/SIGTERM in the CLI), when a duration is up or when every source has
//! ended. A write error (a full disk) stops the recording: what was written is kept.

pub mod message;
mod serial;
pub mod source_spec;
pub mod sources;
pub mod stream;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use railfuse_catalog::log::LogWriter;
use railfuse_catalog::messages::{RecorderDiagnostics, SourceStats};
use railfuse_catalog::topics;
use serde::Serialize;

use message::{Item, ItemWriter};
pub use source_spec::{SourceSpec, SourcesFile, SpecError};
pub use stream::StreamFormat;

/// Called with the live figures (the CLI's status display).
pub type StatusHook = Box<dyn FnMut(&Status)>;

pub struct RecordOptions {
    pub output: PathBuf,
    pub sources: Vec<SourceSpec>,
    /// Close a chunk at least this often (bounds what a crash can lose).
    pub chunk_interval: Duration,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Start a new numbered file (`<stem>-001.mcap`, `-002`, …) past this many bytes …
    pub split_bytes: Option<u64>,
    /// … or this much time.
    pub split_every: Option<Duration>,
    /// Per-source queue length.
    pub queue: usize,
    /// Run metadata (run, train, operator, route, notes, sensor configuration).
    pub metadata: BTreeMap<String, String>,
    /// Called about once a second with the live figures (the CLI's status display).
    pub status: Option<StatusHook>,
    /// Called with every message written (a live viewer); must not block.
    pub tap: Option<TapHook>,
}

/// Called with every message written.
pub type TapHook = Box<dyn FnMut(&Item)>;

/// Live figures for the status display.
#[derive(Debug, Clone, Serialize)]
pub struct Status {
    pub elapsed_s: f64,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    pub bytes_written: u64,
    pub sources: Vec<SourceStats>,
    /// Sources that ended for good with an error ("<source>: <cause>"), in the order they did.
    pub failed_sources: Vec<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RecordReport {
    pub output: PathBuf,
    pub duration_s: f64,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    pub sources: Vec<SourceStats>,
    /// Why the recording ended.
    pub stopped_by: String,
    /// The write error that ended it, if one did (the file keeps every closed chunk).
    pub write_error: Option<String>,
    /// Sources that ended for good with an error ("<source>: <cause>"); the others kept recording.
    pub failed_sources: Vec<String>,
    /// Every file written, in order (one unless splitting).
    pub files: Vec<PathBuf>,
}

/// Joins a source's thread; an error that ended it goes on the list as "<source>: <cause>".
fn join_source(name: String, handle: SourceThread, failed: &mut Vec<String>) {
    if let Err(e) = handle
        .join()
        .unwrap_or(Err(crate::error::SourceError::Panicked))
    {
        failed.push(format!("{name}: {e}"));
    }
}

/// The path of part `n` (1-based) when splitting: `run.mcap` → `run-001.mcap`.
pub fn part_path(output: &Path, n: u32) -> PathBuf {
    let stem = output.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let ext = output
        .extension()
        .and_then(|s| s.to_str())
        .unwrap_or("mcap");
    output.with_file_name(format!("{stem}-{n:03}.{ext}"))
}

/// Opens one output file with the recorder's channel and the run metadata.
fn open_part(
    path: &Path,
    opts: &RecordOptions,
    part: Option<u32>,
) -> railfuse_catalog::Result<(ItemWriter, railfuse_catalog::log::ChannelId)> {
    let mut writer = ItemWriter::new(LogWriter::create(path)?);
    let diag = writer
        .writer
        .add_channel::<RecorderDiagnostics>(topics::RECORDER_DIAGNOSTICS)?;
    let mut metadata = opts.metadata.clone();
    metadata.insert(
        "sources".into(),
        opts.sources
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join("; "),
    );
    metadata.insert("tool_version".into(), crate::TOOL_VERSION.into());
    metadata.insert("source".into(), "recorded".into());
    if let Some(n) = part {
        metadata.insert("part".into(), n.to_string());
    }
    writer
        .writer
        .write_metadata(topics::metadata::RUN, metadata)?;
    Ok((writer, diag))
}

fn file_size(path: &Path) -> u64 {
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    std::fs::metadata(&partial)
        .or_else(|_| std::fs::metadata(path))
        .map_or(0, |m| m.len())
}

/// Records until `stop` is set, the duration is up, or every source has ended.
pub fn record(
    mut opts: RecordOptions,
    stop: Arc<AtomicBool>,
) -> railfuse_catalog::Result<RecordReport> {
    let mut rec = Recording::start(&opts)?;
    let stopped_by = loop {
        let busy = match rec.drain_queues(&mut opts, 1024) {
            Ok(busy) => busy,
            Err(e) => break rec.write_failed(e),
        };
        if rec.last_flush.elapsed() >= opts.chunk_interval {
            if let Err(e) = rec.close_chunk(&opts) {
                break rec.write_failed(e);
            }
        }
        rec.reap_sources();
        rec.report_status(&mut opts);
        if stop.load(Ordering::Relaxed) {
            break "signal".to_owned();
        }
        if opts.duration.is_some_and(|d| rec.started.elapsed() >= d) {
            break "duration".to_owned();
        }
        if !rec.open.iter().any(|&o| o) {
            break "every source ended".to_owned();
        }
        if !busy {
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    Ok(rec.finish(opts, stopped_by))
}

type SourceThread = std::thread::JoinHandle<Result<(), crate::error::SourceError>>;

/// A recording in progress: the sources' threads and queues, the open output file and the
/// counts.
struct Recording {
    writer: ItemWriter,
    diag: railfuse_catalog::log::ChannelId,
    /// The file being written, and every file so far (several when splitting).
    current: PathBuf,
    files: Vec<PathBuf>,
    part: u32,
    part_started: Instant,
    source_stop: Arc<AtomicBool>,
    queues: Vec<Receiver<Item>>,
    stats: Vec<sources::Stats>,
    /// Each source's name and thread, until it is joined.
    threads: Vec<Option<(String, SourceThread)>>,
    written: Vec<u64>,
    open: Vec<bool>,
    started: Instant,
    last_flush: Instant,
    last_status: Instant,
    reported_failures: usize,
    messages: u64,
    per_topic: BTreeMap<String, u64>,
    write_error: Option<String>,
    failed_sources: Vec<String>,
}

impl Recording {
    /// Opens the first file and starts a thread per source, each with its bounded queue.
    fn start(opts: &RecordOptions) -> railfuse_catalog::Result<Self> {
        let splitting = opts.split_bytes.is_some() || opts.split_every.is_some();
        let current = if splitting {
            part_path(&opts.output, 1)
        } else {
            opts.output.clone()
        };
        let (writer, diag) = open_part(&current, opts, splitting.then_some(1))?;
        let source_stop = Arc::new(AtomicBool::new(false));
        let (mut queues, mut stats, mut threads) = (Vec::new(), Vec::new(), Vec::new());
        for spec in &opts.sources {
            let (tx, rx) = sync_channel(opts.queue.max(1));
            let s = Arc::new(Mutex::new(SourceStats {
                name: spec.to_string(),
                ..Default::default()
            }));
            let (spec, st, stop) = (spec.clone(), s.clone(), source_stop.clone());
            let name = spec.to_string();
            threads.push(Some((
                name,
                std::thread::spawn(move || sources::run(spec, tx, st, stop)),
            )));
            queues.push(rx);
            stats.push(s);
        }
        let now = Instant::now();
        Ok(Self {
            writer,
            diag,
            files: vec![current.clone()],
            current,
            part: 1,
            part_started: now,
            source_stop,
            written: vec![0; queues.len()],
            open: vec![true; queues.len()],
            queues,
            stats,
            threads,
            started: now,
            last_flush: now,
            last_status: now,
            reported_failures: 0,
            messages: 0,
            per_topic: BTreeMap::new(),
            write_error: None,
            failed_sources: Vec::new(),
        })
    }

    /// Writes what the sources queued, at most `turn` items per source (so one flooding
    /// source cannot starve the others); says whether anything came.
    fn drain_queues(
        &mut self,
        opts: &mut RecordOptions,
        turn: usize,
    ) -> railfuse_catalog::Result<bool> {
        let mut busy = false;
        for (i, q) in self.queues.iter().enumerate() {
            for _ in 0..turn {
                match q.try_recv() {
                    Ok(item) => {
                        busy = true;
                        self.writer.write(&item)?;
                        self.written[i] += 1;
                        self.messages += 1;
                        if let Some(tap) = opts.tap.as_mut() {
                            tap(&item);
                        }
                        *self.per_topic.entry(item.topic).or_insert(0) += 1;
                    }
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        self.open[i] = false;
                        break;
                    }
                }
            }
        }
        Ok(busy)
    }

    /// A write error ends the recording: kept for the report.
    fn write_failed(&mut self, e: railfuse_catalog::Error) -> String {
        self.write_error = Some(e.to_string());
        "write error".to_owned()
    }

    /// Every source's figures, with what was written of it.
    fn snapshot(&self) -> Vec<SourceStats> {
        self.stats
            .iter()
            .zip(&self.written)
            .map(|(s, &w)| SourceStats {
                written: w,
                ..s.lock().expect("stats").clone()
            })
            .collect()
    }

    /// Writes `/recorder/diagnostics`, closes the chunk (what a crash can lose ends here) and
    /// starts the next file when this one is full.
    fn close_chunk(&mut self, opts: &RecordOptions) -> railfuse_catalog::Result<()> {
        let d = RecorderDiagnostics {
            stamp_ns: sources::now_ns(),
            sources: self.snapshot(),
            bytes_written: file_size(&self.current),
        };
        self.writer.writer.write(self.diag, d.stamp_ns, &d)?;
        self.writer.writer.flush_chunk()?;
        self.last_flush = Instant::now();
        let full = opts.split_bytes.is_some_and(|b| d.bytes_written >= b)
            || opts
                .split_every
                .is_some_and(|t| self.part_started.elapsed() >= t);
        if full {
            self.part += 1;
            let next = part_path(&opts.output, self.part);
            let (writer, diag) = open_part(&next, opts, Some(self.part))?;
            self.diag = diag;
            std::mem::replace(&mut self.writer, writer)
                .writer
                .finish()?;
            self.current = next;
            self.files.push(self.current.clone());
            self.part_started = Instant::now();
        }
        Ok(())
    }

    /// Joins the threads of sources that ended; the ones that failed go on the list.
    fn reap_sources(&mut self) {
        for slot in self
            .threads
            .iter_mut()
            .filter(|t| t.as_ref().is_some_and(|(_, h)| h.is_finished()))
        {
            let (name, handle) = slot.take().expect("finished source");
            join_source(name, handle, &mut self.failed_sources);
        }
    }

    /// The live status, once a second and at once when a source fails for good.
    fn report_status(&mut self, opts: &mut RecordOptions) {
        let Some(status) = opts.status.as_mut() else {
            return;
        };
        if self.last_status.elapsed() < Duration::from_secs(1)
            && self.failed_sources.len() <= self.reported_failures
        {
            return;
        }
        self.reported_failures = self.failed_sources.len();
        status(&Status {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            messages: self.messages,
            per_topic: self.per_topic.clone(),
            bytes_written: file_size(&self.current),
            sources: self.snapshot(),
            failed_sources: self.failed_sources.clone(),
        });
        self.last_status = Instant::now();
    }

    /// Stops the sources, writes what they still queued (unless the disk is the problem) and
    /// the last diagnostics, and finishes the file.
    fn finish(mut self, mut opts: RecordOptions, stopped_by: String) -> RecordReport {
        self.source_stop.store(true, Ordering::Relaxed);
        for (name, handle) in std::mem::take(&mut self.threads).into_iter().flatten() {
            join_source(name, handle, &mut self.failed_sources);
        }
        if self.write_error.is_none() {
            // Every source has stopped: its queue is all there is.
            opts.tap = None;
            if let Err(e) = self.drain_queues(&mut opts, usize::MAX) {
                self.write_error = Some(e.to_string());
            }
        }
        self.queues.clear();
        let sources = self.snapshot();
        let d = RecorderDiagnostics {
            stamp_ns: sources::now_ns(),
            sources: sources.clone(),
            bytes_written: file_size(&self.current),
        };
        if self.write_error.is_none() {
            if let Err(e) = self.writer.writer.write(self.diag, d.stamp_ns, &d) {
                self.write_error = Some(e.to_string());
            }
        }
        let finished = self.writer.writer.finish();
        if let (Err(e), None) = (&finished, &self.write_error) {
            self.write_error = Some(e.to_string());
        }
        RecordReport {
            output: opts.output,
            duration_s: self.started.elapsed().as_secs_f64(),
            messages: self.messages,
            per_topic: self.per_topic,
            sources,
            stopped_by,
            write_error: self.write_error,
            failed_sources: self.failed_sources,
            files: self.files,
        }
    }
}
