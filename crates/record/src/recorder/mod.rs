//! `railfuse record`: capture live sources into a crash-safe MCAP log.
//!
//! Each source runs in its own thread with its own bounded queue ([`sources`]); the writer
//! (this module) drains them round-robin, stamps nothing itself (log time is each message's
//! receive time, publish time its sensor time), closes a chunk at least every
//! `chunk_interval` so that a crash loses at most that much (`railfuse recover` salvages the
//! rest), writes its own health on `/recorder/diagnostics`, and finishes the file cleanly when
//! told to stop (SIGINT/SIGTERM in the CLI), when a duration is up or when every source has
//! ended. A write error (a full disk) stops the recording: what was written is kept.
//!
//! A recording is never lost: a `.partial` left by an earlier run that did not finish is moved
//! aside (and said) before a new one starts; a source that fails or panics ends alone; on a
//! stop the sources drain what their peers already sent while the writer keeps writing; and
//! the file of a run that ends abnormally stays as `.partial` for `railfuse recover`.

mod can;
mod link;
pub mod message;
mod serial;
pub mod source_spec;
pub mod sources;
pub mod stream;
mod udp;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use railfuse_catalog::log::{part_path, partial_path, LogWriter};
use railfuse_catalog::messages::{RecorderDiagnostics, SourceStats};
use railfuse_catalog::run::{write_manifest, ManifestFile, ManifestTopic, MANIFEST};
use railfuse_catalog::topics;
use serde::Serialize;

use message::{Item, ItemWriter};
pub use source_spec::{CanAdapter, SourceSpec, SourcesFile, SpecError};
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
    /// What the engineer must hear at once (a `.partial` moved aside, a listener that cannot
    /// accept), in the order it happened.
    pub notices: Vec<String>,
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
    /// The file being written when a write error stopped the recording.
    pub failed_file: Option<PathBuf>,
    /// Messages taken from the sources that never reached the disk (the open chunk when a
    /// write error stopped the recording); not counted in `messages`.
    pub lost_to_write_error: u64,
    /// What was said at once during the recording.
    pub notices: Vec<String>,
}

/// Joins a source's thread; an error that ended it goes on the list as "<source>: <cause>".
fn join_source(name: String, handle: SourceThread, failed: &mut Vec<String>) {
    let joined = handle.join().unwrap_or_else(|_| {
        Err(crate::error::SourceError::Panicked(
            "the source's thread".into(),
        ))
    });
    if let Err(e) = joined {
        failed.push(format!("{name}: {e}"));
    }
}

/// A `.partial` of `path` left by an earlier recording that did not finish, if it holds data,
/// is moved aside (never written over): `run.mcap.partial` → `run-unrecovered-1.mcap.partial`.
/// Returns what to tell the engineer.
fn move_aside_unfinished(path: &Path) -> railfuse_catalog::Result<Option<String>> {
    let partial = partial_path(path);
    let size = match std::fs::metadata(&partial) {
        Ok(m) if m.is_file() && m.len() > 0 => m.len(),
        _ => return Ok(None),
    };
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let ext = path.extension().and_then(|s| s.to_str()).unwrap_or("mcap");
    let aside = (1..)
        .map(|n| partial_path(&path.with_file_name(format!("{stem}-unrecovered-{n}.{ext}"))))
        .find(|p| !p.exists())
        .expect("a free name");
    std::fs::rename(&partial, &aside).map_err(|e| railfuse_catalog::Error::Io {
        path: partial.clone(),
        source: e,
    })?;
    let salvaged = aside.with_extension("");
    Ok(Some(format!(
        "{} ({:.1} MiB) was left by a recording that did not finish: moved to {}; \
         `railfuse recover {} -o {}` salvages it",
        partial.display(),
        size as f64 / (1 << 20) as f64,
        aside.display(),
        aside.display(),
        salvaged.display()
    )))
}

/// Opens one output file with the recorder's channel and the run metadata; a notice when an
/// unfinished file of the same name was moved aside.
fn open_part(
    path: &Path,
    opts: &RecordOptions,
    part: Option<u32>,
) -> railfuse_catalog::Result<(ItemWriter, railfuse_catalog::log::ChannelId, Option<String>)> {
    let notice = move_aside_unfinished(path)?;
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
    Ok((writer, diag, notice))
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(partial_path(path))
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

/// How long a stopping recording waits for its sources (they drain for [`sources::DRAIN`]);
/// one blocked for good (a terminal on standard input) is left behind.
const STOP_WAIT: Duration = Duration::from_secs(4);

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
    /// Bytes of the parts already finished.
    finished_bytes: u64,
    source_stop: Arc<AtomicBool>,
    queues: Vec<flume::Receiver<Item>>,
    alerts: flume::Receiver<String>,
    notices: Vec<String>,
    reported_notices: usize,
    stats: Vec<sources::Stats>,
    /// Each source's name and thread, until it is joined.
    threads: Vec<Option<(String, SourceThread)>>,
    written: Vec<u64>,
    /// `written` and `messages` as of the last chunk known to be on disk.
    written_on_disk: Vec<u64>,
    messages_on_disk: u64,
    open: Vec<bool>,
    started: Instant,
    last_flush: Instant,
    last_status: Instant,
    reported_failures: usize,
    messages: u64,
    per_topic: BTreeMap<String, u64>,
    write_error: Option<String>,
    failed_sources: Vec<String>,
    /// When splitting: the parts finished, and every channel's (type, encoding), for the
    /// manifest.
    finished_parts: Vec<ManifestFile>,
    topics: BTreeMap<String, (String, String)>,
}

/// A part as the manifest lists it.
fn manifest_file(path: &Path, writer: &ItemWriter) -> ManifestFile {
    ManifestFile {
        name: path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        span_ns: writer.span_ns,
        messages: writer.messages,
    }
}

/// The folder of a split recording's parts, where its manifest goes.
fn manifest_dir(output: &Path) -> PathBuf {
    match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    }
}

impl Recording {
    /// Opens the first file and starts a thread per source, each with its bounded queue.
    fn start(opts: &RecordOptions) -> railfuse_catalog::Result<Self> {
        let splitting = opts.split_bytes.is_some() || opts.split_every.is_some();
        let manifest = manifest_dir(&opts.output).join(MANIFEST);
        if splitting && manifest.exists() {
            return Err(railfuse_catalog::Error::Run {
                path: manifest,
                cause: "holds the manifest of another run: record a split run into a folder \
                        of its own"
                    .into(),
            });
        }
        let current = if splitting {
            part_path(&opts.output, 1)
        } else {
            opts.output.clone()
        };
        let (writer, diag, notice) = open_part(&current, opts, splitting.then_some(1))?;
        let source_stop = Arc::new(AtomicBool::new(false));
        let (alert_tx, alerts) = flume::unbounded();
        let (mut queues, mut stats, mut threads) = (Vec::new(), Vec::new(), Vec::new());
        let mut failed_sources = Vec::new();
        for spec in &opts.sources {
            let (tx, rx) = flume::bounded(opts.queue.max(1));
            let s = Arc::new(Mutex::new(SourceStats {
                name: spec.to_string(),
                ..Default::default()
            }));
            let link = sources::Link {
                queue: tx,
                stats: s.clone(),
                stop: source_stop.clone(),
                alerts: alert_tx.clone(),
            };
            let (spec, name) = (spec.clone(), spec.to_string());
            match std::thread::Builder::new()
                .name(name.clone())
                .spawn(move || sources::run(spec, link))
            {
                Ok(handle) => threads.push(Some((name, handle))),
                Err(e) => failed_sources.push(format!("{name}: cannot start its thread: {e}")),
            }
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
            finished_bytes: 0,
            source_stop,
            alerts,
            notices: notice.into_iter().collect(),
            reported_notices: 0,
            written: vec![0; queues.len()],
            written_on_disk: vec![0; queues.len()],
            messages_on_disk: 0,
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
            failed_sources,
            finished_parts: Vec::new(),
            topics: BTreeMap::new(),
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
                        let item = self.writer.write(item)?;
                        self.written[i] += 1;
                        self.messages += 1;
                        if let Some(tap) = opts.tap.as_mut() {
                            tap(item);
                        }
                        match self.per_topic.get_mut(&item.topic) {
                            Some(n) => *n += 1,
                            None => {
                                self.per_topic.insert(item.topic.clone(), 1);
                            }
                        }
                    }
                    Err(flume::TryRecvError::Empty) => break,
                    Err(flume::TryRecvError::Disconnected) => {
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
                ..sources::lock(s).clone()
            })
            .collect()
    }

    /// Writes `/recorder/diagnostics`, closes the chunk (what a crash can lose ends here) and
    /// starts the next file when this one is full.
    fn close_chunk(&mut self, opts: &RecordOptions) -> railfuse_catalog::Result<()> {
        let d = RecorderDiagnostics {
            stamp_ns: sources::now_ns(),
            sources: self.snapshot(),
            bytes_written: self.bytes_written(),
        };
        self.writer.writer.write(self.diag, d.stamp_ns, &d)?;
        self.writer.spans(d.stamp_ns);
        self.writer.writer.flush_chunk()?;
        self.written_on_disk.clone_from(&self.written);
        self.messages_on_disk = self.messages;
        self.last_flush = Instant::now();
        let part_bytes = file_size(&self.current);
        let full = opts.split_bytes.is_some_and(|b| part_bytes >= b)
            || opts
                .split_every
                .is_some_and(|t| self.part_started.elapsed() >= t);
        if full {
            self.part += 1;
            let next = part_path(&opts.output, self.part);
            let (writer, diag, notice) = open_part(&next, opts, Some(self.part))?;
            self.notices.extend(notice);
            self.diag = diag;
            let finished = std::mem::replace(&mut self.writer, writer);
            self.finished_parts
                .push(manifest_file(&self.current, &finished));
            self.topics.extend(finished.channels().map(|(t, k, c)| {
                let encoding = finished.writer.encoding_of(c).message_encoding();
                (
                    t.to_owned(),
                    (k.schema_name().to_owned(), encoding.to_owned()),
                )
            }));
            // The finished part is complete before the next is written to: a write error in
            // the next one names that one and leaves this one whole.
            let state = finished.latched_items();
            finished.writer.finish()?;
            self.finished_bytes += file_size(&self.current);
            self.current = next;
            self.files.push(self.current.clone());
            self.part_started = Instant::now();
            self.writer.repeat_latched(state)?;
            self.write_manifest(opts)?;
        }
        Ok(())
    }

    /// The run's manifest (a bag directory's metadata.yaml beside the parts), rewritten at
    /// every split and at the end: a recording cut off mid-run still opens as one run (its
    /// last part named as not there until `railfuse recover` salvages it).
    fn write_manifest(&self, opts: &RecordOptions) -> railfuse_catalog::Result<()> {
        let mut files = self.finished_parts.clone();
        files.push(manifest_file(&self.current, &self.writer));
        let mut topics = self.topics.clone();
        topics.extend(self.writer.channels().map(|(t, k, c)| {
            let encoding = self.writer.writer.encoding_of(c).message_encoding();
            (
                t.to_owned(),
                (k.schema_name().to_owned(), encoding.to_owned()),
            )
        }));
        let topics: Vec<ManifestTopic> = topics
            .into_iter()
            .map(|(name, (type_name, encoding))| ManifestTopic {
                messages: self.per_topic.get(&name).copied().unwrap_or(0),
                name,
                type_name,
                encoding,
            })
            .collect();
        write_manifest(&manifest_dir(&opts.output), &files, &topics)
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

    /// Bytes on disk so far, every part together.
    fn bytes_written(&self) -> u64 {
        self.finished_bytes + file_size(&self.current)
    }

    /// The live status, once a second, and at once when a source fails for good or there is
    /// something to say.
    fn report_status(&mut self, opts: &mut RecordOptions) {
        self.notices.extend(self.alerts.try_iter());
        let Some(status) = opts.status.as_mut() else {
            return;
        };
        if self.last_status.elapsed() < Duration::from_secs(1)
            && self.failed_sources.len() <= self.reported_failures
            && self.notices.len() <= self.reported_notices
        {
            return;
        }
        self.reported_failures = self.failed_sources.len();
        self.reported_notices = self.notices.len();
        status(&Status {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            messages: self.messages,
            per_topic: self.per_topic.clone(),
            bytes_written: self.bytes_written(),
            sources: self.snapshot(),
            failed_sources: self.failed_sources.clone(),
            notices: self.notices.clone(),
        });
        self.last_status = Instant::now();
    }

    /// Stops the sources and keeps writing while they drain what their peers already sent
    /// (unless the disk is the problem), then writes the last diagnostics and finishes the
    /// file.
    fn finish(mut self, mut opts: RecordOptions, stopped_by: String) -> RecordReport {
        self.source_stop.store(true, Ordering::Relaxed);
        opts.tap = None;
        let waited = Instant::now();
        loop {
            if self.write_error.is_none() {
                if let Err(e) = self.drain_queues(&mut opts, 1024) {
                    self.write_error = Some(e.to_string());
                }
            }
            self.reap_sources();
            if self.threads.iter().all(Option::is_none) || waited.elapsed() >= STOP_WAIT {
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if self.write_error.is_none() {
            // The sources have stopped (or are left behind): their queues are all there is.
            if let Err(e) = self.drain_queues(&mut opts, usize::MAX) {
                self.write_error = Some(e.to_string());
            }
        }
        self.queues.clear();
        self.notices.extend(self.alerts.try_iter());
        let sources = self.snapshot();
        let d = RecorderDiagnostics {
            stamp_ns: sources::now_ns(),
            sources: sources.clone(),
            bytes_written: self.bytes_written(),
        };
        if self.write_error.is_none() {
            match self.writer.writer.write(self.diag, d.stamp_ns, &d) {
                Ok(()) => self.writer.spans(d.stamp_ns),
                Err(e) => self.write_error = Some(e.to_string()),
            }
        }
        let splitting = opts.split_bytes.is_some() || opts.split_every.is_some();
        let manifest = splitting.then(|| self.write_manifest(&opts));
        let finished = self.writer.writer.finish();
        if let (Err(e), None) = (&finished, &self.write_error) {
            self.write_error = Some(e.to_string());
        }
        if let (Some(Err(e)), None) = (manifest, &self.write_error) {
            self.write_error = Some(e.to_string());
        }
        // After a write error only what reached the disk counts as written.
        let (mut sources, mut lost) = (sources, 0);
        if self.write_error.is_some() {
            lost = self.messages - self.messages_on_disk;
            self.messages = self.messages_on_disk;
            for (s, &w) in sources.iter_mut().zip(&self.written_on_disk) {
                s.written = w;
            }
        }
        RecordReport {
            output: opts.output,
            duration_s: self.started.elapsed().as_secs_f64(),
            messages: self.messages,
            per_topic: self.per_topic,
            sources,
            stopped_by,
            failed_file: self.write_error.is_some().then(|| self.current.clone()),
            write_error: self.write_error,
            failed_sources: self.failed_sources,
            files: self.files,
            lost_to_write_error: lost,
            notices: self.notices,
        }
    }
}
