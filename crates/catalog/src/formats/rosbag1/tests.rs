use super::records::*;
use super::*;

/// A record: its header fields and data, each with its length.
fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let mut header = Vec::new();
    for (name, value) in fields {
        let field = [name.as_bytes(), b"=", value].concat();
        header.extend_from_slice(&(field.len() as u32).to_le_bytes());
        header.extend_from_slice(&field);
    }
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&header);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out
}

/// A bag of one uncompressed chunk: a connection of `ros_type` on `topic` and `n` messages.
fn bag(ros_type: &str, topic: &str, payload: &[u8], n: u32, index_pos: u64) -> Vec<u8> {
    let conn = 7u32.to_le_bytes();
    let info = record(
        &[
            ("topic", topic.as_bytes()),
            ("type", ros_type.as_bytes()),
            ("md5sum", b"*"),
        ],
        b"",
    );
    // A connection's data is a header's fields (without the header's own length).
    let info = &info[4..info.len() - 4];
    let mut chunk = record(
        &[
            ("op", &[OP_CONNECTION]),
            ("conn", &conn),
            ("topic", topic.as_bytes()),
        ],
        info,
    );
    for k in 0..n {
        let time = [100u32.to_le_bytes(), (k * 1000).to_le_bytes()].concat();
        chunk.extend(record(
            &[("op", &[OP_MESSAGE]), ("conn", &conn), ("time", &time)],
            payload,
        ));
    }
    let size = (chunk.len() as u32).to_le_bytes();
    let mut out = MAGIC.to_vec();
    out.extend(record(
        &[
            ("op", &[OP_BAG_HEADER]),
            ("index_pos", &index_pos.to_le_bytes()),
            ("conn_count", &1u32.to_le_bytes()),
            ("chunk_count", &1u32.to_le_bytes()),
        ],
        &[b' '; 16],
    ));
    out.extend(record(
        &[
            ("op", &[OP_CHUNK]),
            ("compression", b"none"),
            ("size", &size),
        ],
        &chunk,
    ));
    out
}

fn convert_bytes(bytes: &[u8]) -> Result<(Converted, PathBuf)> {
    let d = tempfile::tempdir().unwrap().keep();
    let (input, output) = (d.join("t.bag"), d.join("t.mcap"));
    std::fs::write(&input, bytes).unwrap();
    convert(&input, &output, &WriterOptions::default()).map(|c| (c, output))
}

use std::path::PathBuf;

#[test]
fn a_hand_built_bag_converts_and_a_cut_keeps_the_messages_before_it() {
    let bytes = bag("std_msgs/String", "/notes", &[2, 0, 0, 0, b'h', b'i'], 5, 0);
    let (c, _) = convert_bytes(&bytes).unwrap();
    assert_eq!((c.messages, c.per_topic["/notes"]), (5, 5));
    assert!(
        c.warnings.iter().any(|w| w.contains("no index")),
        "{:?}",
        c.warnings
    );
    assert!(
        c.warnings.iter().any(|w| w.contains("5 std_msgs/String")),
        "{:?}",
        c.warnings
    );
    // Cut inside the one chunk: nothing before it to keep, so the whole file is refused.
    let e = convert_bytes(&bytes[..bytes.len() - 3])
        .unwrap_err()
        .to_string();
    assert!(e.contains("cut off"), "{e}");
}

#[test]
fn lengths_past_the_file_or_a_bound_are_refused_before_allocating() {
    let mut bytes = bag("std_msgs/String", "/notes", b"\0\0\0\0", 1, 0);
    // The chunk record's data length (4 bytes before its data, the file's last `size`
    // bytes), claiming 3 GiB.
    let size_at = bytes.windows(5).position(|w| w == b"size=").unwrap() + 5;
    let size = u32::from_le_bytes(bytes[size_at..size_at + 4].try_into().unwrap()) as usize;
    let at = bytes.len() - size - 4;
    bytes[at..at + 4].copy_from_slice(&(3u32 << 30).to_le_bytes());
    let e = convert_bytes(&bytes).unwrap_err().to_string();
    assert!(e.contains("runs past the end of the file"), "{e}");
    assert!(decompress("none", b"abc", MAX_DATA + 1)
        .unwrap_err()
        .contains("256 MiB"));
    assert!(decompress("zstd", b"abc", 3)
        .unwrap_err()
        .contains("'zstd'"));
    assert!(decompress("none", b"abcd", 3)
        .unwrap_err()
        .contains("says 3"));
    let e = Fields::parse(&[9, 0, 0, 0, b'a']).unwrap_err();
    assert!(e.contains("runs past"), "{e}");
}

#[test]
fn a_ros1_header_decodes_with_its_sequence_and_unsigned_seconds() {
    use crate::foreign::ros1::{from_ros1, Header};
    let mut payload = 42u32.to_le_bytes().to_vec();
    payload.extend(1_780_300_800u32.to_le_bytes());
    payload.extend(250_000_000u32.to_le_bytes());
    payload.extend(3u32.to_le_bytes());
    payload.extend(b"gps");
    let h: Header = from_ros1(&payload, "std_msgs/Header").unwrap();
    assert_eq!(
        (h.seq, h.stamp.secs, h.stamp.nsecs, h.frame_id.as_str()),
        (42, 1_780_300_800, 250_000_000, "gps")
    );
    // A string longer than the payload is refused, not allocated.
    payload[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(from_ros1::<Header>(&payload, "std_msgs/Header").is_err());
}

#[test]
fn connections_only_in_the_index_name_the_chunks_messages() {
    let conn = 7u32.to_le_bytes();
    let info = record(
        &[
            ("topic", b"/notes"),
            ("type", b"std_msgs/String"),
            ("md5sum", b"*"),
        ],
        b"",
    );
    let info = &info[4..info.len() - 4];
    let connection = record(
        &[
            ("op", &[OP_CONNECTION]),
            ("conn", &conn),
            ("topic", b"/notes"),
        ],
        info,
    );
    let mut chunk = Vec::new();
    for k in 0..3u32 {
        let time = [100u32.to_le_bytes(), (k * 1000).to_le_bytes()].concat();
        chunk.extend(record(
            &[("op", &[OP_MESSAGE]), ("conn", &conn), ("time", &time)],
            b"\0\0\0\0",
        ));
    }
    let chunk = record(
        &[
            ("op", &[OP_CHUNK]),
            ("compression", b"none"),
            ("size", &(chunk.len() as u32).to_le_bytes()),
        ],
        &chunk,
    );
    let header_len = record(
        &[("op", &[OP_BAG_HEADER]), ("index_pos", &0u64.to_le_bytes())],
        &[b' '; 16],
    )
    .len();
    let index_pos = (MAGIC.len() + header_len + chunk.len()) as u64;
    let mut bytes = MAGIC.to_vec();
    bytes.extend(record(
        &[
            ("op", &[OP_BAG_HEADER]),
            ("index_pos", &index_pos.to_le_bytes()),
        ],
        &[b' '; 16],
    ));
    bytes.extend(chunk);
    bytes.extend(connection);
    let (c, _) = convert_bytes(&bytes).unwrap();
    assert_eq!(c.per_topic.get("/notes"), Some(&3), "{c:?}");
    assert!(
        !c.warnings.iter().any(|w| w.contains("no index")),
        "{:?}",
        c.warnings
    );
    // Without its index the same messages have no connection: counted, and said.
    let cut = &bytes[..index_pos as usize];
    let e = convert_bytes(cut).unwrap_err().to_string();
    assert!(
        e.contains("no message read: 3 a message of no known connection"),
        "{e}"
    );
}
