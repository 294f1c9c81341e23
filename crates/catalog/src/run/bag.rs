//! A rosbag2 bag directory's `metadata.yaml`: which files hold the bag, in which storage, and
//! what each holds (rosbag2's `rosbag2_bagfile_information`, versions 1 to 9).

use std::path::Path;

use serde::Deserialize;

use super::Storage;
use crate::error::{Error, Result};

pub const METADATA: &str = "metadata.yaml";

/// Largest metadata.yaml read (a bound on untrusted input; a real one is a few KiB).
const METADATA_LIMIT: u64 = 16 << 20;

/// The parts a bag lists, in its order.
pub struct Listed {
    pub storage: Storage,
    pub parts: Vec<ListedPart>,
}

pub struct ListedPart {
    /// The file's name inside the bag directory.
    pub name: String,
    pub start_ns: Option<u64>,
    pub duration_ns: Option<u64>,
    pub messages: Option<u64>,
}

#[derive(Deserialize)]
struct Document {
    rosbag2_bagfile_information: Information,
}

#[derive(Deserialize)]
struct Information {
    storage_identifier: String,
    relative_file_paths: Vec<String>,
    #[serde(default)]
    compression_mode: Option<String>,
    /// Per file (version 5 on).
    #[serde(default)]
    files: Option<Vec<FileInformation>>,
}

#[derive(Deserialize)]
struct FileInformation {
    path: String,
    starting_time: Option<Stamp>,
    duration: Option<Duration>,
    message_count: Option<u64>,
}

#[derive(Deserialize)]
struct Stamp {
    nanoseconds_since_epoch: u64,
}

#[derive(Deserialize)]
struct Duration {
    nanoseconds: u64,
}

/// Reads a bag's metadata.yaml.
pub fn read(path: &Path) -> Result<Listed> {
    let bad = |cause: String| Error::run(path, format!("not a rosbag2 metadata.yaml: {cause}"));
    let size = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    if size > METADATA_LIMIT {
        return Err(bad(format!("{size} bytes, more than any bag writes")));
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let doc: Document = serde_yaml_ng::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let info = doc.rosbag2_bagfile_information;
    let storage = match info.storage_identifier.as_str() {
        "mcap" => Storage::Mcap,
        "sqlite3" => Storage::Sqlite3,
        other => {
            return Err(bad(format!(
                "storage '{other}': railfuse reads mcap and sqlite3"
            )))
        }
    };
    if info.compression_mode.as_deref() == Some("FILE") {
        return Err(Error::run(
            path,
            "the bag's files are compressed whole (compression_mode FILE): `ros2 bag \
             decompress` it first, or record with MCAP's own chunk compression",
        ));
    }
    if info.relative_file_paths.is_empty() {
        return Err(bad("relative_file_paths lists no file".into()));
    }
    let files = info.files.unwrap_or_default();
    let parts = info
        .relative_file_paths
        .iter()
        .map(|relative| {
            // rosbag2 names files relative to the bag; older versions wrote the bag's own
            // directory in front. Only the name is taken, as rosbag2 does, so a path cannot
            // reach outside the directory.
            let name = Path::new(relative)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .ok_or_else(|| bad(format!("'{relative}' names no file")))?;
            let file = files.iter().find(|f| {
                Path::new(&f.path).file_name().map(|n| n.to_string_lossy())
                    == Some(name.as_str().into())
            });
            Ok(ListedPart {
                start_ns: file
                    .and_then(|f| f.starting_time.as_ref())
                    .map(|s| s.nanoseconds_since_epoch),
                duration_ns: file
                    .and_then(|f| f.duration.as_ref())
                    .map(|d| d.nanoseconds),
                messages: file.and_then(|f| f.message_count),
                name,
            })
        })
        .collect::<Result<_>>()?;
    Ok(Listed { storage, parts })
}

/// One file of a run's manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestFile {
    pub name: String,
    /// Its first and last message's log time (the repeated latched state left out); `None`
    /// for a part with no message of its own yet.
    pub span_ns: Option<(u64, u64)>,
    pub messages: u64,
}

/// One topic of a run's manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestTopic {
    pub name: String,
    pub type_name: String,
    /// The channel's message encoding (json, protobuf, cdr).
    pub encoding: String,
    pub messages: u64,
}

/// Writes the manifest of a run split into `files` as the bag directory's `metadata.yaml` in
/// `dir` (rosbag2's version 5 layout, MCAP storage), whole or not at all: written beside and
/// renamed over the last one, so a crash leaves the previous manifest.
pub fn write_manifest(dir: &Path, files: &[ManifestFile], topics: &[ManifestTopic]) -> Result<()> {
    use std::fmt::Write;
    let start = files.iter().filter_map(|f| f.span_ns).map(|s| s.0).min();
    let end = files.iter().filter_map(|f| f.span_ns).map(|s| s.1).max();
    let (start, end) = (start.unwrap_or(0), end.unwrap_or(0));
    let mut y =
        String::from("rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n");
    let total: u64 = files.iter().map(|f| f.messages).sum();
    let _ = write!(
        y,
        "  duration:\n    nanoseconds: {}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n  message_count: {total}\n",
        end - start
    );
    y.push_str("  topics_with_message_count:\n");
    for t in topics {
        let _ = write!(
            y,
            "    - topic_metadata:\n        name: {}\n        type: {}\n        serialization_format: {}\n        offered_qos_profiles: \"\"\n      message_count: {}\n",
            yaml_string(&t.name),
            yaml_string(&t.type_name),
            yaml_string(&t.encoding),
            t.messages
        );
    }
    y.push_str("  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n");
    for f in files {
        let _ = writeln!(y, "    - {}", yaml_string(&f.name));
    }
    y.push_str("  files:\n");
    for f in files {
        let (a, b) = f.span_ns.unwrap_or((end, end));
        let _ = write!(
            y,
            "    - path: {}\n      starting_time:\n        nanoseconds_since_epoch: {a}\n      duration:\n        nanoseconds: {}\n      message_count: {}\n",
            yaml_string(&f.name),
            b - a,
            f.messages
        );
    }
    let path = dir.join(METADATA);
    let temporary = dir.join(format!(".{METADATA}.partial"));
    std::fs::write(&temporary, y).map_err(|e| Error::io(&temporary, e))?;
    std::fs::rename(&temporary, &path).map_err(|e| Error::io(&path, e))
}

/// A YAML double-quoted string (topic names may hold anything).
fn yaml_string(s: &str) -> String {
    serde_json::to_string(s).expect("a string serialises")
}
