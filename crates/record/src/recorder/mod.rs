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
fn join_source(
    name: String,
    handle: std::thread::JoinHandle<Result<(), String>>,
    failed: &mut Vec<String>,
) {
    if let Err(e) = handle
        .join()
        .unwrap_or_else(|_| Err("the source's thread panicked".to_owned()))
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
    let splitting = opts.split_bytes.is_some() || opts.split_every.is_some();
    let mut part = 1u32;
    let mut current = if splitting {
        part_path(&opts.output, part)
    } else {
        opts.output.clone()
    };
    let (mut writer, mut diag) = open_part(&current, &opts, splitting.then_some(part))?;
    let mut files = vec![current.clone()];
    let mut part_started = Instant::now();

    let source_stop = Arc::new(AtomicBool::new(false));
    let mut queues: Vec<Receiver<Item>> = Vec::new();
    let mut stats: Vec<sources::Stats> = Vec::new();
    let mut threads = Vec::new();
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
    let mut written = vec![0u64; queues.len()];
    let mut open = vec![true; queues.len()];
    let started = Instant::now();
    let mut last_flush = Instant::now();
    let mut last_status = Instant::now();
    let mut reported_failures = 0;
    let (mut messages, mut per_topic) = (0u64, BTreeMap::<String, u64>::new());
    let mut write_error: Option<String> = None;
    let mut failed_sources = Vec::new();
    let stopped_by;
    'run: loop {
        let mut busy = false;
        for (i, q) in queues.iter().enumerate() {
            // Bounded turns keep one flooding source from starving the others.
            for _ in 0..1024 {
                match q.try_recv() {
                    Ok(item) => {
                        busy = true;
                        if let Err(e) = writer.write(&item) {
                            write_error = Some(e.to_string());
                            stopped_by = "write error".to_owned();
                            break 'run;
                        }
                        written[i] += 1;
                        messages += 1;
                        if let Some(tap) = opts.tap.as_mut() {
                            tap(&item);
                        }
                        *per_topic.entry(item.topic).or_insert(0) += 1;
                    }
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        open[i] = false;
                        break;
                    }
                }
            }
        }
        let snapshot = || -> Vec<SourceStats> {
            stats
                .iter()
                .zip(&written)
                .map(|(s, &w)| SourceStats {
                    written: w,
                    ..s.lock().expect("stats").clone()
                })
                .collect()
        };
        if last_flush.elapsed() >= opts.chunk_interval {
            let d = RecorderDiagnostics {
                stamp_ns: sources::now_ns(),
                sources: snapshot(),
                bytes_written: file_size(&current),
            };
            let r = writer
                .writer
                .write(diag, d.stamp_ns, &d)
                .and_then(|()| writer.writer.flush_chunk());
            if let Err(e) = r {
                write_error = Some(e.to_string());
                stopped_by = "write error".to_owned();
                break 'run;
            }
            last_flush = Instant::now();
            let full = opts.split_bytes.is_some_and(|b| d.bytes_written >= b)
                || opts
                    .split_every
                    .is_some_and(|t| part_started.elapsed() >= t);
            if full {
                part += 1;
                let next = part_path(&opts.output, part);
                let r = std::mem::replace(
                    &mut writer,
                    open_part(&next, &opts, Some(part)).map(|(w, c)| {
                        diag = c;
                        w
                    })?,
                )
                .writer
                .finish();
                if let Err(e) = r {
                    write_error = Some(e.to_string());
                    stopped_by = "write error".to_owned();
                    break 'run;
                }
                current = next;
                files.push(current.clone());
                part_started = Instant::now();
            }
        }
        for slot in threads
            .iter_mut()
            .filter(|t| t.as_ref().is_some_and(|(_, h)| h.is_finished()))
        {
            let (name, handle) = slot.take().expect("finished source");
            join_source(name, handle, &mut failed_sources);
        }
        if let Some(status) = opts.status.as_mut() {
            if last_status.elapsed() >= Duration::from_secs(1)
                || failed_sources.len() > reported_failures
            {
                reported_failures = failed_sources.len();
                status(&Status {
                    elapsed_s: started.elapsed().as_secs_f64(),
                    messages,
                    per_topic: per_topic.clone(),
                    bytes_written: file_size(&current),
                    sources: snapshot(),
                    failed_sources: failed_sources.clone(),
                });
                last_status = Instant::now();
            }
        }
        if stop.load(Ordering::Relaxed) {
            stopped_by = "signal".to_owned();
            break;
        }
        if opts.duration.is_some_and(|d| started.elapsed() >= d) {
            stopped_by = "duration".to_owned();
            break;
        }
        if !open.iter().any(|&o| o) {
            stopped_by = "every source ended".to_owned();
            break;
        }
        if !busy {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    source_stop.store(true, Ordering::Relaxed);
    // Let the sources notice the stop, then write what they still queued (unless the disk is
    // the problem).
    for (name, handle) in threads.into_iter().flatten() {
        join_source(name, handle, &mut failed_sources);
    }
    if write_error.is_none() {
        for (i, q) in queues.iter().enumerate() {
            while let Ok(item) = q.try_recv() {
                if let Err(e) = writer.write(&item) {
                    write_error = Some(e.to_string());
                    break;
                }
                written[i] += 1;
                messages += 1;
                *per_topic.entry(item.topic).or_insert(0) += 1;
            }
        }
    }
    drop(queues);
    let sources: Vec<SourceStats> = stats
        .iter()
        .zip(&written)
        .map(|(s, &w)| SourceStats {
            written: w,
            ..s.lock().expect("stats").clone()
        })
        .collect();
    let d = RecorderDiagnostics {
        stamp_ns: sources::now_ns(),
        sources: sources.clone(),
        bytes_written: file_size(&current),
    };
    if write_error.is_none() {
        if let Err(e) = writer.writer.write(diag, d.stamp_ns, &d) {
            write_error = Some(e.to_string());
        }
    }
    let finished = writer.writer.finish();
    if let (Err(e), None) = (&finished, &write_error) {
        write_error = Some(e.to_string());
    }
    Ok(RecordReport {
        output: opts.output,
        duration_s: started.elapsed().as_secs_f64(),
        messages,
        per_topic,
        sources,
        stopped_by,
        write_error,
        failed_sources,
        files,
    })
}
