//! Fuzzing on stable Rust: every decoder of untrusted input is fed real inputs from
//! `tests/fuzz/corpus/<target>/` (seeded from `samples/` and the real recordings) mutated by proptest (bits flipped,
//! bytes set, runs inserted, deleted, duplicated, the input cut short), and must answer with a
//! value or an error, never a panic, and keep its own promises (an NMEA fix is never stamped
//! 1970; a recovered log reads cleanly to its end).
//!
//! The test command runs a bounded number of cases per target from a fixed seed, so CI is
//! repeatable; explore further with, say,
//!
//!     RAILFUSE_FUZZ_CASES=200000 RAILFUSE_FUZZ_SEED=7 cargo test --release --test fuzz
//!
//! and add any input that finds a bug to the corpus.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use railfuse_catalog::log::{read_summary, recover, LogReader};
use railfuse_catalog::messages::SourceStats;
use railfuse_record::recorder::stream::StreamDecoder;
use railfuse_record::recorder::StreamFormat;
use railfuse_refuse::measurement::SensorModel;
use railfuse_refuse::pipeline::AnyPipeline;
use railfuse_refuse::spec::Pipelines;

#[derive(Debug, Clone)]
enum Mutation {
    FlipBit(Index, u8),
    SetByte(Index, u8),
    Insert(Index, Vec<u8>),
    Delete(Index, usize),
    Duplicate(Index, usize, Index),
    Truncate(Index),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<Index>(), 0u8..8).prop_map(|(i, b)| Mutation::FlipBit(i, b)),
        3 => (any::<Index>(), any::<u8>()).prop_map(|(i, v)| Mutation::SetByte(i, v)),
        2 => (any::<Index>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, v)| Mutation::Insert(i, v)),
        2 => (any::<Index>(), 1usize..64).prop_map(|(i, n)| Mutation::Delete(i, n)),
        1 => (any::<Index>(), 1usize..256, any::<Index>())
            .prop_map(|(i, n, j)| Mutation::Duplicate(i, n, j)),
        1 => any::<Index>().prop_map(Mutation::Truncate),
    ]
}

fn apply(mut data: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
    for m in mutations {
        if data.is_empty() {
            break;
        }
        let len = data.len();
        match m {
            Mutation::FlipBit(i, b) => data[i.index(len)] ^= 1 << b,
            Mutation::SetByte(i, v) => data[i.index(len)] = *v,
            Mutation::Insert(i, v) => {
                let at = i.index(len + 1);
                data.splice(at..at, v.iter().copied());
            }
            Mutation::Delete(i, n) => {
                let at = i.index(len);
                data.drain(at..(at + n).min(len));
            }
            Mutation::Duplicate(i, n, j) => {
                let from = i.index(len);
                let run: Vec<u8> = data[from..(from + n).min(len)].to_vec();
                let to = j.index(len + 1);
                data.splice(to..to, run);
            }
            Mutation::Truncate(i) => data.truncate(i.index(len)),
        }
    }
    data
}

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let seeds: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    assert!(!seeds.is_empty(), "{}: empty corpus", dir.display());
    seeds
}

fn setting(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Runs `check` on `cases` mutations of the corpus of `target`; reports the case count.
fn fuzz(target: &str, cases: u64, check: impl Fn(&[u8]) -> Result<(), TestCaseError>) {
    let seeds = corpus(target);
    let cases = setting("RAILFUSE_FUZZ_CASES", cases);
    let config = Config {
        cases: cases as u32,
        failure_persistence: None,
        ..Config::default()
    };
    let mut seed = [0u8; 32];
    seed[..8].copy_from_slice(&setting("RAILFUSE_FUZZ_SEED", 1).to_le_bytes());
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &seed);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let strategy = (0..seeds.len(), prop::collection::vec(mutation(), 0..6));
    let result = runner.run(&strategy, |(k, mutations)| {
        check(&apply(seeds[k].clone(), &mutations))
    });
    if let Err(e) = result {
        panic!("fuzz target {target}: {e}");
    }
    println!("fuzz target {target}: {cases} cases, no panic");
}

fn stream(format: StreamFormat, clock_ns: u64, data: &[u8]) -> Result<(), TestCaseError> {
    let mut d = StreamDecoder::new(format);
    let (mut stats, mut items) = (SourceStats::default(), Vec::new());
    // Any split of the stream: feed it in two parts.
    let cut = data.len() / 3;
    d.feed(&data[..cut], clock_ns, &mut stats, &mut items);
    d.feed(&data[cut..], clock_ns, &mut stats, &mut items);
    d.finish(clock_ns, &mut stats, &mut items);
    if format != StreamFormat::JsonLines {
        for item in &items {
            // A receiver's fixes (no clock here) are dated from the stream or not at all.
            prop_assert!(
                item.message.stamp_ns() > 1_000_000_000_000_000_000,
                "{item:?}"
            );
        }
    }
    Ok(())
}

#[test]
fn nmea_stream_decoder() {
    fuzz("nmea", 3000, |data| stream(StreamFormat::Nmea, 0, data));
}

#[test]
fn ubx_stream_decoder() {
    fuzz("ubx", 3000, |data| stream(StreamFormat::Ubx, 0, data));
}

#[test]
fn json_lines_source() {
    // Gateway lines without a stamp take the receive time.
    fuzz("json", 3000, |data| {
        stream(StreamFormat::JsonLines, 1_780_300_800_000_000_000, data)
    });
}

#[test]
fn eth_importer() {
    let d = tempfile::tempdir().unwrap();
    let (input, output) = (d.path().join("node.csv"), d.path().join("node.mcap"));
    fuzz("eth", 300, |data| {
        std::fs::write(&input, data).unwrap();
        if railfuse_record::import::eth::import(&input, &output).is_ok() {
            let mut r = LogReader::open(&output).unwrap();
            while let Some(rec) = r.next() {
                prop_assert!(
                    rec.is_ok(),
                    "the import wrote a log that does not read back"
                );
            }
        }
        Ok(())
    });
}

#[test]
fn mcap_reader_and_recover() {
    let d = tempfile::tempdir().unwrap();
    let (input, fixed) = (d.path().join("in.mcap"), d.path().join("fixed.mcap"));
    fuzz("mcap", 600, |data| {
        std::fs::write(&input, data).unwrap();
        let _ = read_summary(&input);
        if let Ok(mut r) = LogReader::open(&input) {
            while let Some(rec) = r.next() {
                if rec.is_err() {
                    break;
                }
            }
        }
        if let Ok(report) = recover(&input, &fixed) {
            // What recover writes is a complete log that reads to its end.
            let mut r = LogReader::open(&fixed).unwrap();
            let mut messages = 0;
            while let Some(rec) = r.next() {
                let rec = rec.map_err(|e| TestCaseError::fail(format!("recovered: {e}")))?;
                messages += u64::from(matches!(rec, railfuse_catalog::log::LogRecord::Message(_)));
            }
            prop_assert_eq!(messages, report.messages);
        }
        Ok(())
    });
}

/// Every fix a converted file holds reads back, in time order.
fn converted_reads_back(output: &Path) -> Result<(), TestCaseError> {
    let mut r = LogReader::open(output).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let mut last = 0u64;
    while let Some(rec) = r.next() {
        let rec = rec.map_err(|e| TestCaseError::fail(format!("converted: {e}")))?;
        if let railfuse_catalog::log::LogRecord::Message(m) = rec {
            prop_assert!(m.log_time_ns >= last, "out of time order");
            last = m.log_time_ns;
        }
    }
    Ok(())
}

/// Mutations of `target`'s corpus converted as `storage` into a run's MCAP part.
fn conversion(target: &str, storage: railfuse_catalog::formats::Storage, name: &str) {
    use railfuse_catalog::formats::{self, FormatOptions};
    let d = tempfile::tempdir().unwrap();
    let (input, output) = (d.path().join(name), d.path().join("out.mcap"));
    fuzz(target, 600, |data| {
        std::fs::write(&input, data).unwrap();
        let options = FormatOptions::default();
        if formats::convert(storage, &input, &output, &options, &Default::default()).is_ok() {
            converted_reads_back(&output)?;
        }
        Ok(())
    });
}

#[test]
fn gpx_reader() {
    conversion("gpx", railfuse_catalog::formats::Storage::Gpx, "ride.gpx");
}

#[test]
fn mdf4_bus_reader() {
    conversion("mdf4", railfuse_catalog::formats::Storage::Mdf4, "bus.mf4");
}

#[test]
fn ros1_bag_reader() {
    conversion(
        "rosbag1",
        railfuse_catalog::formats::Storage::Rosbag1,
        "run.bag",
    );
}

#[test]
fn pipeline_config() {
    let path = Path::new("fuzz.toml");
    fuzz("config", 2000, |data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return Ok(());
        };
        if let Ok(config) = Pipelines::parse(text, path) {
            for p in config.pipeline {
                let mut pipeline =
                    AnyPipeline::new(p.clone()).map_err(|e| TestCaseError::fail(e.to_string()))?;
                // Bound to a channel of every kind a sensor model reads.
                for si in 0..p.sensors.len() {
                    for kind in SensorModel::SUPPORTED {
                        if let Ok(b) = p.bind(Path::new("fuzz.mcap"), si, kind.schema_name()) {
                            pipeline.bind(si, &b);
                        }
                    }
                }
            }
        }
        Ok(())
    });
}

/// Every field of every sentence type the assembler reads, replaced by arbitrary bytes
/// (non-ASCII and non-UTF-8 among them) under a checksum that is right: the decoder answers
/// with a fix or a counted reason, never a panic, and the good epochs around it still arrive.
#[test]
fn nmea_fields_of_any_bytes_under_a_good_checksum() {
    const SENTENCES: [&str; 6] = [
        "GNGGA,083559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000",
        "GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V",
        "GNGST,083559.00,0.45,0.020,0.015,77.4,0.018,0.017,0.031",
        "GNVTG,45.0,T,,M,10.0,N,18.52,K,A",
        "GNGSA,A,3,01,02,03,04,,,,,,,,,1.5,0.9,1.2",
        "GNZDA,083559.00,20,10,2022,00,00",
    ];
    let line = |body: &[u8]| {
        let mut l = b"$".to_vec();
        l.extend_from_slice(body);
        l.extend(format!("*{:02X}\r\n", body.iter().fold(0u8, |a, b| a ^ b)).bytes());
        l
    };
    let epoch = |t: &str| {
        let mut out = Vec::new();
        for s in &SENTENCES[..2] {
            out.extend(line(s.replace("083559.00", t).as_bytes()));
        }
        out
    };
    let cases = setting("RAILFUSE_FUZZ_CASES", 3000);
    let config = Config {
        cases: cases as u32,
        failure_persistence: None,
        ..Config::default()
    };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let bytes = prop::collection::vec(any::<u8>().prop_filter("one line", |b| *b != b'\n'), 0..12);
    let strategy = (0..SENTENCES.len(), any::<Index>(), bytes);
    let result = runner.run(&strategy, |(k, field, bytes)| {
        let mut fields: Vec<Vec<u8>> = SENTENCES[k]
            .split(',')
            .map(|f| f.as_bytes().to_vec())
            .collect();
        let i = 1 + field.index(fields.len() - 1);
        fields[i] = bytes;
        let mut stream = epoch("083558.00");
        stream.extend(line(&fields.join(&b","[..])));
        stream.extend(epoch("083600.00"));
        let mut d = StreamDecoder::new(StreamFormat::Nmea);
        let (mut stats, mut items) = (SourceStats::default(), Vec::new());
        d.feed(&stream, 0, &mut stats, &mut items);
        d.finish(0, &mut stats, &mut items);
        prop_assert!(items.len() >= 2, "{stats:?}");
        Ok(())
    });
    if let Err(e) = result {
        panic!("nmea fields: {e}");
    }
    println!("nmea fields: {cases} cases, no panic");
}
