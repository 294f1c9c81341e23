//! Progress of long commands on stderr: on a terminal an indicatif bar with the rate and the
//! time left; otherwise (CI logs, field scripts) a plain line at most every 10 s; nothing at all
//! with `--quiet`.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

static QUIET: AtomicBool = AtomicBool::new(false);

/// `--quiet`: no progress output at all.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether `--quiet` was given: informational lines on stderr are left out too.
pub fn is_quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// A command's informational line on stderr (what it did, where it wrote), left out with
/// `--quiet`; warnings and errors are always said, results always printed.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        if !$crate::progress::is_quiet() {
            eprintln!($($arg)*);
        }
    };
}

const PLAIN_EVERY: Duration = Duration::from_secs(10);

#[derive(Clone, Copy)]
enum Unit {
    Bytes,
    Steps,
}

/// One task's progress: `set` it as the work goes, `finish` it at the end.
pub struct Progress {
    bar: Option<ProgressBar>,
    plain: Option<Mutex<Plain>>,
}

struct Plain {
    label: String,
    total: u64,
    unit: Unit,
    started: Instant,
    last: Instant,
}

impl Progress {
    /// Through `total` bytes of a file.
    pub fn bytes(label: &str, total: u64) -> Self {
        Self::new(label, total, Unit::Bytes)
    }

    /// Through `total` steps (runs, files).
    pub fn steps(label: &str, total: u64) -> Self {
        Self::new(label, total, Unit::Steps)
    }

    fn new(label: &str, total: u64, unit: Unit) -> Self {
        if QUIET.load(Ordering::Relaxed) {
            return Self {
                bar: None,
                plain: None,
            };
        }
        if std::io::stderr().is_terminal() {
            let template = match unit {
                Unit::Bytes => {
                    "{msg} [{bar:30}] {bytes}/{total_bytes} {binary_bytes_per_sec} eta {eta}"
                }
                Unit::Steps => "{msg} [{bar:30}] {pos}/{len} eta {eta}",
            };
            let style = ProgressStyle::with_template(template)
                .expect("a valid template")
                .progress_chars("=> ");
            let bar = ProgressBar::new(total)
                .with_style(style)
                .with_message(label.to_owned());
            return Self {
                bar: Some(bar),
                plain: None,
            };
        }
        let now = Instant::now();
        let plain = Plain {
            label: label.to_owned(),
            total,
            unit,
            started: now,
            last: now,
        };
        Self {
            bar: None,
            plain: Some(Mutex::new(plain)),
        }
    }

    /// Work done so far.
    pub fn set(&self, done: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
        }
        if let Some(plain) = &self.plain {
            let mut p = plain.lock().expect("progress");
            if p.last.elapsed() >= PLAIN_EVERY && p.total > 0 {
                p.last = Instant::now();
                let share = done as f64 / p.total as f64;
                let elapsed = p.started.elapsed().as_secs_f64();
                let left = elapsed * (1.0 - share) / share.max(1e-9);
                let amount = match p.unit {
                    Unit::Bytes => format!(
                        "{:.1} of {:.1} MiB",
                        done as f64 / (1 << 20) as f64,
                        p.total as f64 / (1 << 20) as f64
                    ),
                    Unit::Steps => format!("{done} of {}", p.total),
                };
                eprintln!(
                    "{}: {:.0} % ({amount}), about {left:.0} s left",
                    p.label,
                    100.0 * share
                );
            }
        }
    }

    /// Work done so far, with a word on how it goes (the best value of a search).
    pub fn set_with(&self, done: u64, detail: &str) {
        if let Some(bar) = &self.bar {
            bar.set_message(detail.to_owned());
        }
        if let Some(plain) = &self.plain {
            let due = plain.lock().expect("progress").last.elapsed() >= PLAIN_EVERY;
            if due {
                eprintln!("{detail}");
            }
        }
        self.set(done);
    }

    /// Clears the bar (the command's own report follows).
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
