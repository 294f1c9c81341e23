//! A log's lines, read one at a time and bounded: a log is untrusted, so a line longer than
//! [`MAX_LINE`] is refused (and skipped to its end) rather than read into memory.

use std::io::{BufRead, Read};

/// The longest line taken: a 64-byte FD frame with the longest stamp, bus name and comment.
pub const MAX_LINE: usize = 1024;

/// A line that could not be taken, or did not parse: its number (from 1) and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {reason}")]
pub struct BadLine {
    pub line: usize,
    pub reason: String,
}

/// Text lines with their numbers, trimmed; blank lines skipped.
pub struct Lines<R> {
    input: R,
    line: usize,
    buf: Vec<u8>,
}

impl<R> Lines<R> {
    /// Lines read so far.
    pub fn count(&self) -> usize {
        self.line
    }
}

impl<R: BufRead> Lines<R> {
    pub fn new(input: R) -> Self {
        Self {
            input,
            line: 0,
            buf: Vec::new(),
        }
    }

    /// The next non-blank line and its number, or why it could not be taken.
    pub fn next_line(&mut self) -> Option<Result<(usize, &str), BadLine>> {
        loop {
            self.buf.clear();
            let n = self
                .input
                .by_ref()
                .take(MAX_LINE as u64 + 1)
                .read_until(b'\n', &mut self.buf);
            let n = match n {
                Ok(0) => return None,
                Ok(n) => n,
                Err(e) => {
                    self.line += 1;
                    return Some(Err(self.bad(format!("unreadable: {e}"))));
                }
            };
            self.line += 1;
            if n > MAX_LINE && !self.buf.ends_with(b"\n") {
                self.skip_rest();
                return Some(Err(self.bad(format!("longer than {MAX_LINE} bytes"))));
            }
            match std::str::from_utf8(&self.buf) {
                Err(_) => return Some(Err(self.bad("not text".into()))),
                Ok(t) if t.trim().is_empty() => continue,
                Ok(_) => {}
            }
            let text = std::str::from_utf8(&self.buf).expect("checked").trim();
            return Some(Ok((self.line, text)));
        }
    }

    /// Skips to the end of an overlong line, a buffer at a time (never holding it whole).
    fn skip_rest(&mut self) {
        loop {
            let (used, done) = match self.input.fill_buf() {
                Ok([]) | Err(_) => return,
                Ok(buf) => match buf.iter().position(|&b| b == b'\n') {
                    Some(i) => (i + 1, true),
                    None => (buf.len(), false),
                },
            };
            self.input.consume(used);
            if done {
                return;
            }
        }
    }

    /// A fault at the current line.
    pub fn bad(&self, reason: String) -> BadLine {
        BadLine {
            line: self.line,
            reason,
        }
    }
}
