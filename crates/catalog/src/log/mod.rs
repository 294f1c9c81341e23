//! Reading and writing railfuse logs (MCAP, JSON messages, jsonschema schemas).
//!
//! Both sides stream: the reader pulls bytes from the file as it needs them, so memory scales
//! with the largest chunk, never with the file; the writer emits zstd-compressed, indexed
//! chunks with a summary, into a temporary file that only becomes the output once it is
//! complete.

pub mod format;
mod parts;
mod reader;
mod recover;
pub mod scan;
mod writer;

pub use parts::{part_path, PartWriter, SplitRule};
pub use reader::{
    read_channels, read_metadata, read_summary, ChannelInfo, LogMessage, LogReader, LogRecord,
    LogSummary, SchemaInfo,
};
pub use recover::{recover, RecoverReport};
pub use writer::{partial_path, ChannelId, ChunkTally, LogWriter, WriterOptions};

/// A map keyed by MCAP channel or schema id (u16), looked up once or more per message: the
/// standard map with a fast fixed hash (SipHash cost a few percent of a replay; u16 keys
/// from a file cannot be chosen to collide in bulk).
pub type IdMap<V> = std::collections::HashMap<u16, V, foldhash::fast::FixedState>;

/// MCAP profile name railfuse writes (no ROS semantics: plain JSON channels).
pub const PROFILE: &str = "railfuse";
/// Message encoding of every railfuse channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every railfuse channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Largest record the reader accepts (a bound on untrusted input), 256 MiB.
pub const RECORD_LENGTH_LIMIT: usize = 256 << 20;

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::messages::{ChannelMessage, RadarSpeed};

    #[test]
    fn a_writer_dropped_on_an_error_path_keeps_a_partial_that_holds_messages() {
        let d = tempfile::tempdir().unwrap();
        let (path, empty) = (d.path().join("run.mcap"), d.path().join("empty.mcap"));
        let mut w = LogWriter::create(&path).unwrap();
        let ch = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
        for k in 0..100u64 {
            let m = RadarSpeed {
                stamp_ns: k,
                speed_mps: 1.0,
                quality: 1.0,
                valid: true,
                speed_variance_m2ps2: None,
            };
            w.write(ch, k, &m).unwrap();
        }
        drop(w); // as a panic unwinding through the recorder would
        let partial = partial_path(&path);
        let fixed = d.path().join("fixed.mcap");
        assert_eq!(recover(&partial, &fixed).unwrap().messages, 100);
        // One with nothing in it is cleaned up.
        drop(LogWriter::create(&empty).unwrap());
        assert!(!partial_path(&empty).exists());
    }

    #[test]
    fn what_is_written_reads_back_record_for_record() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("t.mcap");
        let mut w = LogWriter::create(&path).unwrap();
        let ch = w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
        for k in 0..5000u64 {
            let m = RadarSpeed {
                stamp_ns: k * 1000,
                speed_mps: k as f64 * 0.01,
                quality: 1.0,
                valid: k % 7 != 0,
                speed_variance_m2ps2: None,
            };
            w.write(ch, k * 1000 + 5, &m).unwrap();
        }
        w.write_metadata(
            "railfuse.test",
            BTreeMap::from([("a".to_owned(), "b".to_owned())]),
        )
        .unwrap();
        w.attach("notes.txt", "text/plain", 1, 2, b"hello").unwrap();
        assert!(!path.exists(), "the output must not appear before finish()");
        w.finish().unwrap();

        let mut r = LogReader::open(&path).unwrap();
        let (mut messages, mut schemas, mut channels, mut metadata, mut attachments) =
            (0u64, 0, 0, 0, 0);
        while let Some(rec) = r.next() {
            match rec.unwrap() {
                LogRecord::Schema(s) => {
                    assert_eq!(s.name, RadarSpeed::SCHEMA_NAME);
                    schemas += 1
                }
                LogRecord::Channel(c) => {
                    assert_eq!(c.topic, "/radar/speed");
                    channels += 1
                }
                LogRecord::Message(m) => {
                    let v: RadarSpeed = m.decode(&path).unwrap();
                    assert_eq!(v.stamp_ns, messages * 1000);
                    assert_eq!(
                        (m.log_time_ns, m.publish_time_ns),
                        (messages * 1000 + 5, messages * 1000)
                    );
                    assert_eq!(v.valid, messages % 7 != 0);
                    messages += 1;
                }
                LogRecord::Metadata { name, metadata: m } => {
                    assert_eq!((name.as_str(), m["a"].as_str()), ("railfuse.test", "b"));
                    metadata += 1
                }
                LogRecord::Attachment { name, data, .. } => {
                    assert_eq!((name.as_str(), data), ("notes.txt", &b"hello"[..]));
                    attachments += 1
                }
            }
        }
        assert_eq!(
            (messages, schemas, channels, metadata, attachments),
            (5000, 1, 1, 1, 1)
        );
        let known = read_channels(&path).unwrap().unwrap();
        assert_eq!(known.len(), 1);
        assert_eq!(known[0].schema_name(), RadarSpeed::SCHEMA_NAME);
    }

    #[test]
    fn a_writer_dropped_without_finish_leaves_nothing_behind() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("t.mcap");
        {
            let mut w = LogWriter::create(&path).unwrap();
            w.add_channel::<RadarSpeed>("/radar/speed").unwrap();
        }
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
    }
}
