//! Every `railfuse` command in the README, and in the book's pages (docs/, in the order of
//! docs/SUMMARY.md), runs as written, in order, from a clean directory (with `samples/`
//! beside it, as in a checkout). The inputs the README assumes a reader
//! brings (a receiver's NMEA and UBX captures, a ROS 2 bag in both storages, a recording cut
//! off and a damaged one) are made first; a command that needs what a test cannot have (a
//! serial device, a network peer, a viewer window, minutes of experiments) is listed as not
//! run, with why.

mod common;

use std::path::Path;

use common::*;

/// The README's commands: lines of its code blocks that start with `railfuse`, continuation
/// lines joined, comments dropped.
fn commands(readme: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut lines = readme.lines();
    while let Some(line) = lines.next() {
        let Some(mut cmd) = line.strip_prefix("    railfuse ").map(str::to_owned) else {
            continue;
        };
        while cmd.trim_end().ends_with('\\') {
            let next = lines.next().unwrap_or("");
            cmd = format!("{} {}", cmd.trim_end().trim_end_matches('\\'), next.trim());
        }
        let cmd = cmd.split(" #").next().unwrap_or("").trim().to_owned();
        out.push(cmd);
    }
    out
}

/// Why a command is not run here, if it is not.
fn not_run(cmd: &str) -> Option<&'static str> {
    match () {
        _ if cmd.starts_with("record") => {
            Some("records until Ctrl-C, from devices, ports or the real-time simulator (tests/record*.rs)")
        }
        _ if cmd.contains("--spawn") || cmd.contains("--viz spawn") || cmd.contains("--connect") => {
            Some("needs a viewer window")
        }
        _ if cmd.starts_with("results") => Some("minutes of simulated experiments"),
        _ => None,
    }
}

/// The inputs the README assumes the reader has, in `dir`: the checkout's samples/, and
/// shared/ beside the checkout (`../shared`, as CI lays it: the real recordings).
fn inputs(dir: &Path) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::os::unix::fs::symlink(root.join("samples"), dir.join("samples")).unwrap();
    std::os::unix::fs::symlink(root.join("../shared"), dir.join("../shared")).unwrap();
    let (nmea, ubx) = captures(dir);
    std::fs::rename(&nmea, dir.join("receiver.nmea")).unwrap();
    std::fs::rename(&ubx, dir.join("receiver.ubx")).unwrap();
    let text = std::fs::read_to_string(dir.join("receiver.nmea")).unwrap();
    let gga: String = text
        .lines()
        .filter(|l| l.starts_with("$GNGGA") && !l.contains("*00"))
        .map(|l| format!("{l}\r\n"))
        .collect();
    std::fs::write(dir.join("gga-only.nmea"), gga).unwrap();
    // A ROS 2 bag (bag/ and its track line.geojson) and an older one in sqlite3 storage.
    let short = sample("short-run.mcap");
    for storage in [&[][..], &["sqlite3"]] {
        let py = python("ros2_bag.py", &[&[s(&short), s(dir)][..], storage].concat());
        assert!(
            py.status.success(),
            "{}",
            String::from_utf8_lossy(&py.stderr)
        );
    }
    std::fs::rename(dir.join("bag-sqlite3"), dir.join("old_bag")).unwrap();
    // A recording cut off (what a crash leaves) and one with a damaged chunk.
    let bytes = std::fs::read(&short).unwrap();
    std::fs::write(
        dir.join("field.mcap.partial"),
        &bytes[..bytes.len() * 2 / 3],
    )
    .unwrap();
    let mut damaged = bytes.clone();
    let mid = damaged.len() / 2;
    damaged[mid] ^= 0xff;
    std::fs::write(dir.join("damaged.mcap"), damaged).unwrap();
}

/// Runs `commands` in order in a clean directory with the reader's inputs: what did not run,
/// with why, and what failed.
fn run_in_order(commands: &[String]) -> (usize, Vec<String>, Vec<String>) {
    let top = tempfile::tempdir().unwrap();
    let d = top.path().join("checkout");
    std::fs::create_dir(&d).unwrap();
    inputs(&d);
    let (mut ran, mut skipped, mut failed) = (0, Vec::new(), Vec::new());
    for cmd in commands {
        if let Some(why) = not_run(cmd) {
            skipped.push(format!("railfuse {cmd}: {why}"));
            continue;
        }
        let o = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!("'{}' {cmd}", env!("CARGO_BIN_EXE_railfuse")))
            .current_dir(&d)
            .output()
            .unwrap();
        ran += 1;
        if !o.status.success() {
            let err = stderr(&o);
            failed.push(format!(
                "railfuse {cmd}\n    {}",
                err.trim().replace('\n', "\n    ")
            ));
        }
    }
    (ran, skipped, failed)
}

#[test]
fn every_railfuse_command_in_the_readme_and_the_book_runs_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = commands(&std::fs::read_to_string(root.join("README.md")).unwrap());
    // The book's pages in the order a reader meets them.
    let summary = std::fs::read_to_string(root.join("docs/SUMMARY.md")).unwrap();
    let mut book = Vec::new();
    for line in summary.lines() {
        if let Some(page) = line.split("](").nth(1).and_then(|r| r.split(')').next()) {
            book.extend(commands(
                &std::fs::read_to_string(root.join("docs").join(page)).unwrap(),
            ));
        }
    }
    assert!(readme.len() >= 10 && book.len() > 40, "{readme:?} {book:?}");
    let mut failed = Vec::new();
    for (what, commands) in [("README", &readme), ("book", &book)] {
        let (ran, skipped, f) = run_in_order(commands);
        println!(
            "{what}: ran {ran} commands; not run:\n{}",
            skipped.join("\n")
        );
        failed.extend(f.into_iter().map(|f| format!("{what}: {f}")));
    }
    assert!(
        failed.is_empty(),
        "{} failed:\n{}",
        failed.len(),
        failed.join("\n")
    );
}
