//! Every command tried as a new user would: the README's examples and their obvious
//! variations. Wrong input is one clear line and a non-zero exit, never a silent 0; help
//! lists what the parser takes; no command leaves an output that looks complete after failing.

mod common;

use std::path::Path;

use common::*;

/// `railfuse tune` of samples/kalman.toml's pipeline on samples/short-run.mcap to `out`,
/// with `extra` arguments.
fn tune_short_run(out: &Path, extra: &[&str]) -> std::process::Output {
    let (log, config) = (sample("short-run.mcap"), sample("kalman.toml"));
    let args = [
        &[
            "tune",
            s(&log),
            "-c",
            s(&config),
            "--pipeline",
            "kalman",
            "-o",
            s(out),
        ][..],
        extra,
    ]
    .concat();
    railfuse(&args)
}

fn exists(p: &Path) -> bool {
    p.exists()
}

#[test]
fn every_reading_command_reports_a_damaged_log_as_info_does_and_leaves_no_output() {
    let d = tempfile::tempdir().unwrap();
    let log = sample("short-run.mcap");
    let bytes = std::fs::read(&log).unwrap();
    // Cut short (a recording cut off) and a chunk with a flipped byte (its CRC fails).
    let cut = d.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let flipped = d.path().join("flipped.mcap");
    let mut b = bytes.clone();
    let mid = b.len() / 2;
    b[mid] ^= 0xff;
    std::fs::write(&flipped, &b).unwrap();
    let config = sample("kalman.toml");
    for damaged in [&cut, &flipped] {
        let (fused, rrd, tuned) = (
            d.path().join("o.mcap"),
            d.path().join("o.rrd"),
            d.path().join("t.toml"),
        );
        for args in [
            vec!["info", s(damaged)],
            vec!["refuse", s(damaged), "-c", s(&config), "-o", s(&fused)],
            vec!["eval", s(damaged)],
            vec!["viz", s(damaged), "--save", s(&rrd)],
            vec![
                "tune",
                s(damaged),
                "-c",
                s(&config),
                "--pipeline",
                "kalman",
                "--params",
                "motion.jerk_psd=0.01..1",
                "--max-evals",
                "2",
                "-o",
                s(&tuned),
            ],
        ] {
            let line = fails(&args);
            assert!(
                line.contains("damaged at byte") && line.contains("railfuse recover"),
                "{args:?}: {line}"
            );
        }
        for out in [
            "o.mcap",
            "o.mcap.partial",
            "o.rrd",
            "o.rrd.partial",
            "t.toml",
        ] {
            assert!(!exists(&d.path().join(out)), "{out} left after {damaged:?}");
        }
    }
}

#[test]
fn wrong_input_is_one_line_and_a_non_zero_exit_never_a_silent_zero() {
    let d = tempfile::tempdir().unwrap();
    let p = |name: &str| d.path().join(name);
    let run = sample("short-run.mcap");
    let fused = p("fused.mcap");
    refuse(&run, "kalman.toml", &fused);
    std::fs::write(p("receiver.nmea"), "$GPGGA,junk\n$GPRMC,also junk\n").unwrap();
    std::fs::write(
        p("LICENSE"),
        "Permission is hereby granted, free of charge\n",
    )
    .unwrap();
    std::fs::write(p("map.toml"), "[[message]]\n").unwrap();
    let out = p("e.mcap");
    let config = sample("kalman.toml");
    let (nmea, license, map, rrd) = (p("receiver.nmea"), p("LICENSE"), p("map.toml"), p("v.rrd"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["import", s(&nmea), "-o", s(&out)],
            "no nmea message in it",
        ),
        (
            vec!["import", s(&license), "-o", s(&out)],
            "cannot tell its format",
        ),
        (
            vec!["import", s(&run), "-o", s(&out)],
            "already an MCAP log",
        ),
        (
            vec![
                "import",
                s(&nmea),
                "--format",
                "nmea",
                "--map",
                s(&map),
                "-o",
                s(&out),
            ],
            "--map is the column mapping of --format csv",
        ),
        (
            vec!["eval", s(&fused), "--reference", "/nothere"],
            "no channel /nothere to take as the reference",
        ),
        (
            vec![
                "refuse",
                s(&run),
                "-c",
                s(&config),
                "-o",
                s(&out),
                "--reference",
                "/nothere",
            ],
            "no channel /nothere to take as the reference",
        ),
        (vec!["eval", s(&run)], "no fused pipelines to evaluate"),
    ];
    each_fails_and_leaves_nothing(&cases, &[&out, &rrd]);
}

#[test]
fn wrong_viz_record_and_simulate_requests_are_one_line_and_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    let (fused, out, rrd) = (
        d.path().join("f.mcap"),
        d.path().join("e.mcap"),
        d.path().join("v.rrd"),
    );
    refuse(&sample("short-run.mcap"), "kalman.toml", &fused);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["viz", s(&fused), "--pipelines", "nope", "--save", s(&rrd)],
            "no pipeline 'nope'",
        ),
        (
            vec!["viz", s(&fused), "--topics", "/nope", "--save", s(&rrd)],
            "no topic /nope",
        ),
        (
            vec!["viz", s(&fused), "--from", "99999", "--save", s(&rrd)],
            "past the end",
        ),
        (
            vec![
                "record",
                "--serial",
                "/dev/nonexistent:115200",
                "-o",
                s(&out),
                "--duration",
                "1",
            ],
            "serial /dev/nonexistent: No such file",
        ),
        (
            vec![
                "simulate",
                "--scenario",
                "seed001",
                "--duration",
                "60",
                "--fault",
                "radar:dropout:200:300",
                "-o",
                s(&out),
            ],
            "starts at 200 s, after the run's end at 60 s",
        ),
    ];
    each_fails_and_leaves_nothing(&cases, &[&out, &rrd]);
}

/// Each `(args, says)`: `railfuse args` fails with one line that says `says`, and none of
/// `outputs` is left behind.
fn each_fails_and_leaves_nothing(cases: &[(Vec<&str>, &str)], outputs: &[&Path]) {
    for (args, says) in cases {
        let line = fails(args);
        assert!(line.contains(says), "{args:?}: {line}");
        for out in outputs {
            assert!(!exists(out), "{args:?} left {out:?}");
        }
    }
}

#[test]
fn help_lists_every_value_the_parser_takes_and_the_csv_mapping_has_an_example_of_every_type() {
    let help = |cmd: &str| String::from_utf8(ok(&[cmd, "--help"]).stdout).unwrap();
    let tune = help("tune");
    for optimiser in ["grid", "nelder_mead", "pso", "bayesian", "em"] {
        assert!(tune.contains(optimiser), "{optimiser}: {tune}");
    }
    let simulate = help("simulate");
    for name in railfuse_record::Scenario::NAMES {
        assert!(
            simulate.contains(&format!("- {name}:")),
            "{name}: {simulate}"
        );
    }
    for device in railfuse_record::simulator::faults::DEVICES {
        assert!(simulate.contains(device), "{device}: {simulate}");
    }
    let import = help("import");
    for key in [
        "[time]",
        "[columns]",
        "[[channel]]",
        "--example-map",
        "samples/",
    ] {
        assert!(import.contains(key), "{key}: {import}");
    }
    // The example mapping names the fields every type needs: its CSV imports one message
    // of each.
    let d = tempfile::tempdir().unwrap();
    ok(&["import", "--example-map", s(d.path())]);
    let out = d.path().join("example.mcap");
    let r: serde_json::Value = ok_json(&[
        "import",
        s(&d.path().join("example.csv")),
        "--map",
        s(&d.path().join("mapping.toml")),
        "-o",
        s(&out),
        "--json",
    ]);
    let kinds = railfuse_catalog::formats::csv_table::example::EXAMPLE_KINDS;
    assert_eq!(r["messages"].as_u64(), Some(kinds.len() as u64), "{r}");
    assert_eq!(
        r["per_topic"].as_object().unwrap().len(),
        kinds.len(),
        "{r}"
    );
}

#[test]
fn outputs_are_checked_before_the_work_and_seeds_zero_is_refused() {
    let d = tempfile::tempdir().unwrap();
    // Outside the repository there is no docs/: said at once, not after the runs.
    let started = std::time::Instant::now();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args(["results", "--safety", "--seeds", "1"])
        .current_dir(d.path())
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("docs/safety.md: cannot write: its folder docs does not exist"),
        "{err}"
    );
    assert!(!d.path().join("target").exists(), "work started: {err}");
    assert!(started.elapsed().as_secs() < 10);
    // tune: a trace path it cannot write stops it before the search, and nothing is written.
    let tuned = d.path().join("t.toml");
    let o = tune_short_run(
        &tuned,
        &[
            "--params",
            "motion.jerk_psd=0.01..1",
            "--trace",
            "/nonexistent/dir/t.csv",
        ],
    );
    assert!(!o.status.success());
    let line = stderr(&o);
    assert!(
        line.contains("/nonexistent/dir/t.csv: cannot write"),
        "{line}"
    );
    assert!(!tuned.exists());
    let o = railfuse(&["results", "--seeds", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--seeds"), "{}", stderr(&o));
}

#[test]
fn a_short_live_run_refuses_with_the_sample_config_a_missing_sensor_said_not_fatal() {
    let d = tempfile::tempdir().unwrap();
    let live = d.path().join("live.mcap");
    ok(&[
        "record",
        "--simulate",
        "default",
        "--speed",
        "10",
        "--duration",
        "3",
        "-q",
        "-o",
        s(&live),
    ]);
    let fused = d.path().join("live.fused.mcap");
    let o = refuse(&live, "kalman.toml", &fused);
    let err = stderr(&o);
    let warnings: Vec<&str> = err.lines().filter(|l| l.contains("/balise")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(
        warnings[0].starts_with("warning: ") && warnings[0].contains("runs without it"),
        "{err}"
    );
    // (How many states a 3 s live run yields depends on when its first position came.)
    assert!(fused.exists());
    // Marked required, the same sensor stops the run in one line.
    let text = std::fs::read_to_string(sample("kalman.toml")).unwrap();
    let required = d.path().join("required.toml");
    std::fs::write(
        &required,
        text.replace(
            "topic = \"/balise\"",
            "topic = \"/balise\"\nrequired = true",
        ),
    )
    .unwrap();
    let line = fails(&["refuse", s(&live), "-c", s(&required), "-o", s(&fused)]);
    assert!(
        line.contains("/balise") && line.contains("is not in the file"),
        "{line}"
    );
}

#[test]
fn a_first_tune_without_params_tunes_the_pipelines_noise_values_and_says_which() {
    let d = tempfile::tempdir().unwrap();
    let tuned = d.path().join("tuned.toml");
    let o = tune_short_run(&tuned, &["--max-evals", "20", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    let said = err
        .lines()
        .find(|l| l.starts_with("no --params: tuning the pipeline's noise values"))
        .unwrap_or_else(|| panic!("{err}"));
    // The process noise and every sensor variance given as a number ("message" ones are
    // each message's own).
    for name in [
        "motion.jerk_psd",
        "sensor[/radar/speed].variance",
        "sensor[/odometer/1].variance",
        "sensor[/odometer/2].variance",
    ] {
        assert!(said.contains(name), "{name}: {said}");
    }
    assert!(!said.contains("/loop/position"), "{said}");
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["params"].as_array().unwrap().len(), 4, "{r}");
    assert_ne!(
        std::fs::read_to_string(&tuned).unwrap(),
        std::fs::read_to_string(sample("kalman.toml")).unwrap()
    );
}

#[test]
fn the_smaller_things_quiet_counts_folders_bench_flags_and_memory_in_mib() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("q.mcap");
    // -q: nothing on stderr but warnings and errors.
    let o = simulate(&["--scenario", "seed001", "--duration", "5", "-q"], &out);
    assert_eq!(stderr(&o), "");
    let o = ok(&[
        "record",
        "--simulate",
        "default",
        "--speed",
        "10",
        "--duration",
        "1",
        "-q",
        "-o",
        s(&d.path().join("r.mcap")),
    ]);
    assert_eq!(stderr(&o), "");
    // Counts that must be at least 1 name their flag.
    for flag in ["--threads", "--max-evals"] {
        let o = tune_short_run(&d.path().join("t.toml"), &[flag, "0"]);
        let err = stderr(&o);
        assert!(!o.status.success());
        assert!(
            err.contains(&format!("'0' for '{flag}")) && err.contains("at least 1"),
            "{err}"
        );
    }
    // A missing output folder is named as the user wrote it.
    let line = fails(&["simulate", "--duration", "2", "-o", "nodir/x.mcap"]);
    assert!(
        line.contains("nodir/x.mcap: cannot write MCAP: its folder nodir does not exist"),
        "{line}"
    );
    assert!(!line.contains(".partial"), "{line}");
    // bench: one measurement a run, and --json only where it is read.
    let o = railfuse(&["bench", "--safety", "1", "--viz", "1"]);
    assert!(
        !o.status.success() && stderr(&o).contains("cannot be used with"),
        "{}",
        stderr(&o)
    );
    let o = railfuse(&["bench", "--json"]);
    assert!(
        !o.status.success() && stderr(&o).contains("--em"),
        "{}",
        stderr(&o)
    );
    // Memory in MiB, as the README gives it.
    let o = ok(&["bench", "--tune", "5", "--dir", s(&d.path().join("bench"))]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("peak RSS") && text.contains(" MiB") && !text.contains("KiB"),
        "{text}"
    );
}
