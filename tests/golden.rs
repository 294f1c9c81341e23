//! Re-fusion output pinned: every channel of the output of every `samples/*.toml` on the run
//! it was written for, on fixed seeds (the copied input channels and the fused ones), is
//! digested per topic and compared with `tests/golden/refuse-digests.txt`, written by the code
//! before the file-to-file fast path (seed002–004 and gnss-s1 added before the refuse crate
//! was taken apart, issue 29).
//! A change to the filters that is meant to change their output re-blesses it:
//!
//!     RAILFUSE_BLESS=1 cargo test --test golden
//!
//! and the diff of the digest file shows which channels moved.

mod common;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use common::*;
use railfuse_catalog::log::{LogReader, LogRecord};
use sha2::{Digest, Sha256};

/// Per topic: message count and SHA-256 over (log time, publish time, content) in file order.
/// A railfuse message's content is its JSON form, whatever its encoding (so the digest moves
/// with what the channel says, not how it is spelled); any other message's is its payload.
fn digests(path: &Path) -> BTreeMap<String, (u64, String)> {
    let mut hashers: BTreeMap<String, (u64, Sha256)> = BTreeMap::new();
    let mut r = LogReader::open(path).unwrap();
    while let Some(rec) = r.next() {
        if let LogRecord::Message(m) = rec.unwrap() {
            let (n, h) = hashers.entry(m.channel.topic.clone()).or_default();
            *n += 1;
            h.update(m.log_time_ns.to_le_bytes());
            h.update(m.publish_time_ns.to_le_bytes());
            let content = m.decode_any(path).unwrap().map(|any| any.to_json());
            let content = content.as_deref().unwrap_or(m.data);
            h.update((content.len() as u64).to_le_bytes());
            h.update(content);
        }
    }
    hashers
        .into_iter()
        .map(|(t, (n, h))| (t, (n, format!("{:x}", h.finalize()))))
        .collect()
}

#[test]
fn refuse_output_of_the_sample_runs_is_unchanged() {
    let d = tempfile::tempdir().unwrap();
    let short = sample("short-run.mcap");
    let seed000 = d.path().join("seed000.mcap");
    let seed001 = d.path().join("seed001.mcap");
    simulate(&["--scenario", "seed000", "--seed", "1"], &seed000);
    simulate(&["--scenario", "seed001", "--seed", "1"], &seed001);
    // Every other sample configuration on the run it was written for (fixed seeds, 300 s).
    let sim = |scenario: &str, name: &str| {
        let out = d.path().join(name);
        simulate(
            &["--scenario", scenario, "--seed", "1", "--duration", "300"],
            &out,
        );
        out
    };
    let (default, seed003, seed004) = (
        sim("default", "default.mcap"),
        sim("seed003", "seed003.mcap"),
        sim("seed004", "seed004.mcap"),
    );
    let sn2 = d.path().join("sn2.mcap");
    import_eth("20221020_1030_R90117_Modena_SN2_sample.csv", &sn2);
    let fused_once = d.path().join("short-run.kalman.mcap");
    // (label, input, config, output name); each output in `d`.
    let runs: [(&str, &Path, &str, &str); 10] = [
        (
            "short-run kalman",
            &short,
            "kalman.toml",
            "short-run.kalman.mcap",
        ),
        ("short-run models", &short, "models.toml", "m.mcap"),
        (
            "short-run sensor-states",
            &short,
            "sensor-states.toml",
            "c.mcap",
        ),
        // Re-fusing a fused file: the re-run pipeline's channels are replaced.
        (
            "short-run kalman again",
            &fused_once,
            "kalman.toml",
            "k2.mcap",
        ),
        ("seed000", &seed000, "seed000.toml", "s0.mcap"),
        ("seed001", &seed001, "seed001.toml", "s1.mcap"),
        ("seed002", &default, "seed002.toml", "s2.mcap"),
        ("seed003", &seed003, "seed003.toml", "s3.mcap"),
        ("seed004", &seed004, "seed004.toml", "s4.mcap"),
        ("gnss-s1", &sn2, "gnss-s1.toml", "g1.mcap"),
    ];
    let mut text = String::new();
    for (label, input, config, output) in runs {
        let output = d.path().join(output);
        refuse(input, config, &output);
        for (topic, (n, h)) in digests(&output) {
            writeln!(text, "{label}\t{topic}\t{n}\t{h}").unwrap();
        }
    }
    same_as_golden_or_bless(&text);
}

/// The digests against tests/golden/refuse-digests.txt, every line that differs shown; with
/// RAILFUSE_BLESS set, written there instead.
fn same_as_golden_or_bless(text: &str) {
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/refuse-digests.txt");
    if std::env::var_os("RAILFUSE_BLESS").is_some() {
        std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
        std::fs::write(&golden, text).unwrap();
        return;
    }
    let want = std::fs::read_to_string(&golden).expect("tests/golden/refuse-digests.txt");
    let differ: Vec<String> = want
        .lines()
        .zip(text.lines())
        .filter(|(a, b)| a != b)
        .map(|(a, b)| format!("  want {a}\n  got  {b}"))
        .collect();
    assert!(
        differ.is_empty() && want.lines().count() == text.lines().count(),
        "re-fusion output changed ({} of {} lines differ, {} vs {} lines):\n{}",
        differ.len(),
        want.lines().count(),
        want.lines().count(),
        text.lines().count(),
        differ.join("\n")
    );
}
