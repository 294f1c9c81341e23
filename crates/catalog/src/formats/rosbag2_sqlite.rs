//! rosbag2's sqlite3 storage (the default before ROS 2 Jazzy): a directory of `.db3` files
//! (with its `metadata.yaml`), converted to MCAP as `ros2 bag convert` would: one channel per
//! topic keeping its name, type (the schema name, `ros2msg`), serialisation format (the
//! message encoding, `cdr`) and offered QoS profiles (channel metadata, as rosbag2's own MCAP
//! storage keeps them), every message with its receive time as log and publish time, in time
//! order, file by file. A message definition the bag carries (`message_definitions`, newer
//! bags) becomes the schema's data, else the one railfuse knows for the type, else none.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use rusqlite::{Connection, OpenFlags};

use super::Converted;
use crate::error::{Error, Result};
use crate::foreign::ros2;
use crate::log::LogWriter;

/// The `.db3` files of a bag directory, in name order (rosbag2 numbers its splits).
fn db3_files(bag: &Path) -> Result<Vec<PathBuf>> {
    let io = |source| Error::Io {
        path: bag.to_owned(),
        source,
    };
    if bag.is_file() {
        return Ok(vec![bag.to_owned()]);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(bag)
        .map_err(io)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "db3"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::Mcap {
            path: bag.to_owned(),
            cause: "no .db3 file: not a rosbag2 sqlite3 bag".into(),
        });
    }
    Ok(files)
}

fn sql(path: &Path, e: rusqlite::Error) -> Error {
    Error::Mcap {
        path: path.to_owned(),
        cause: format!("not a rosbag2 sqlite3 file: {e}"),
    }
}

/// The definition the bag gives for each type, where it has the table.
fn definitions(db: &Connection, path: &Path) -> Result<HashMap<String, (String, String)>> {
    let has = db
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'message_definitions'",
            [],
            |r| r.get::<_, i64>(0),
        )
        .map_err(|e| sql(path, e))?;
    if has == 0 {
        return Ok(HashMap::new());
    }
    let mut q = db
        .prepare("SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")
        .map_err(|e| sql(path, e))?;
    let rows = q
        .query_map([], |r| Ok((r.get(0)?, (r.get(1)?, r.get(2)?))))
        .map_err(|e| sql(path, e))?;
    rows.collect::<std::result::Result<_, _>>()
        .map_err(|e| sql(path, e))
}

/// Converts the bag at `input` (a directory, or one `.db3` file) to MCAP at `output`,
/// streaming (one row at a time).
pub fn convert(input: &Path, output: &Path) -> Result<Converted> {
    let mut report = Converted::default();
    let mut writer = LogWriter::create(output)?;
    // Channel (and schema) ids by topic name, the same across the bag's files.
    let (mut channels, mut schemas): (HashMap<String, u16>, HashMap<String, u16>) =
        Default::default();
    for path in db3_files(input)? {
        let db = Connection::open_with_flags(&path, OpenFlags::SQLITE_OPEN_READ_ONLY)
            .map_err(|e| sql(&path, e))?;
        let topics = copy_topics(&db, &path, &mut writer, &mut channels, &mut schemas)?;
        copy_messages(&db, &path, &topics, &mut writer, &mut report)?;
    }
    writer.finish()?;
    Ok(report)
}

/// The bag file's topics as channels (and their types as schemas), with ids by name and type
/// kept across the bag's files; its topic ids mapped to channel id and name.
fn copy_topics(
    db: &Connection,
    path: &Path,
    writer: &mut LogWriter,
    channels: &mut HashMap<String, u16>,
    schemas: &mut HashMap<String, u16>,
) -> Result<BTreeMap<i64, (u16, String)>> {
    let defs = definitions(db, path)?;
    let mut topics: BTreeMap<i64, (u16, String)> = BTreeMap::new();
    let mut q = db
        .prepare("SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics")
        .map_err(|e| sql(path, e))?;
    let rows = q
        .query_map([], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, String>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, String>(3)?,
                r.get::<_, String>(4)?,
            ))
        })
        .map_err(|e| sql(path, e))?;
    for row in rows {
        let (id, name, ty, format, qos) = row.map_err(|e| sql(path, e))?;
        let next = schemas.len() as u16 + 1;
        let schema = *schemas.entry(ty.clone()).or_insert(next);
        let (encoding, text) = defs.get(&ty).cloned().unwrap_or_else(|| {
            (
                "ros2msg".into(),
                ros2::definition(&ty).unwrap_or_default().to_owned(),
            )
        });
        writer.copy_schema(schema, &ty, &encoding, text.as_bytes())?;
        let next = channels.len() as u16 + 1;
        let channel = *channels.entry(name.clone()).or_insert(next);
        let metadata = BTreeMap::from([("offered_qos_profiles".to_owned(), qos)]);
        writer.copy_channel(channel, schema, &name, &format, &metadata)?;
        topics.insert(id, (channel, name));
    }
    Ok(topics)
}

/// The bag file's messages in time order, copied byte for byte (CDR) onto their channels.
fn copy_messages(
    db: &Connection,
    path: &Path,
    topics: &BTreeMap<i64, (u16, String)>,
    writer: &mut LogWriter,
    report: &mut Converted,
) -> Result<()> {
    let mut q = db
        .prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
        .map_err(|e| sql(path, e))?;
    let mut rows = q.query([]).map_err(|e| sql(path, e))?;
    let mut sequence: HashMap<u16, u32> = HashMap::new();
    while let Some(r) = rows.next().map_err(|e| sql(path, e))? {
        let (topic, time, data): (i64, i64, Vec<u8>) = (
            r.get(0).map_err(|e| sql(path, e))?,
            r.get(1).map_err(|e| sql(path, e))?,
            r.get(2).map_err(|e| sql(path, e))?,
        );
        report.rows += 1;
        let (Some((channel, name)), Ok(time)) = (topics.get(&topic), u64::try_from(time)) else {
            *report
                .skipped
                .entry("message of an unknown topic or a negative time".into())
                .or_insert(0) += 1;
            continue;
        };
        let seq = sequence.entry(*channel).or_insert(0);
        *seq += 1;
        writer.write_raw(*channel, *seq, time, time, &data)?;
        report.messages += 1;
        *report.per_topic.entry(name.clone()).or_insert(0) += 1;
    }
    Ok(())
}
