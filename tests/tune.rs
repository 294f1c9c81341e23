//! `railfuse tune` end to end: on simulated logs, its starting figures are `refuse`'s, every
//! optimiser improves a deliberately bad start, a seed fixes the result, and bad requests get
//! one clear line.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use serde_json::Value;

/// A default run of `seed` and `duration_s` in `dir`.
fn default_run(dir: &Path, seed: u32, duration_s: u32) -> PathBuf {
    let log = dir.join(format!("run{seed}.mcap"));
    let (seed, duration) = (seed.to_string(), duration_s.to_string());
    simulate(&["--seed", &seed, "--duration", &duration], &log);
    log
}

/// samples/kalman.toml with its motion noise 100x too high and the radar's and odometers'
/// variances 100x too low.
fn bad_config(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(sample("kalman.toml")).unwrap();
    // Without the resets to absolute fixes, which would rescue the bad start themselves: the
    // optimisers must undo it.
    let bad = text
        .replace("jerk_psd = 0.2", "jerk_psd = 20.0")
        .replace("variance = 0.1\n", "variance = 0.001\n")
        .replace(
            "variance = \"message\"\n",
            "variance = \"message\"\nreset_after = 0\n",
        );
    assert_ne!(text, bad);
    let path = dir.join("bad.toml");
    std::fs::write(&path, bad).unwrap();
    path
}

const PARAMS: [&str; 4] = [
    "--params=motion.jerk_psd=0.001..100",
    "--params=sensor[/radar/speed].variance=1e-4..1",
    "--params=sensor[/odometer/1].variance=1e-4..1",
    "--params=sensor[/odometer/2].variance=1e-4..1",
];

fn tune(log: &Path, config: &Path, out: &Path, extra: &[&str]) -> Value {
    let mut args = vec![
        "tune",
        s(log),
        "-c",
        s(config),
        "--pipeline",
        "kalman",
        "-o",
        s(out),
        "--json",
    ];
    args.extend_from_slice(extra);
    serde_json::from_slice(&ok(&args).stdout).unwrap()
}

#[test]
fn tune_starts_from_refuse_s_figures_and_every_optimiser_improves_a_bad_start() {
    let d = tempfile::tempdir().unwrap();
    let log = default_run(d.path(), 2, 240);
    // The figures tune starts from are those refuse + eval give for the same file.
    let fused = d.path().join("fused.mcap");
    let refused = refuse_json(&log, "kalman.toml", &fused);
    let eval = &refused["eval"]["pipelines"][0];
    let extra = [
        "--reference",
        "/truth",
        "--params=motion.jerk_psd=0.01..10",
        "--max-evals",
        "3",
    ];
    let start = tune(
        &log,
        &sample("kalman.toml"),
        &d.path().join("same.toml"),
        &extra,
    );
    let before = &start["before"];
    // Tune records each measurement once, its place-dependent corrections (a gradient, a
    // lever arm on a curve) taken where the measurements put the train; refuse takes them
    // where its first pipeline estimates it: on the railway the two differ by parts in ten
    // thousand (exactly equal on a flat line with a point train).
    let close = |a: &Value, b: &Value| {
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        (a - b).abs() <= 2e-3 * b.abs().max(1e-9)
    };
    for (tuned, refused) in [
        ("position_rmse_m", &eval["position_error_m"]["rmse"]),
        ("speed_rmse_mps", &eval["speed_error_mps"]["rmse"]),
        ("nees_inside_95", &eval["nees"]["inside_95"]),
        ("nis_inside_95", &eval["nis"]["inside_95"]),
    ] {
        assert!(close(&before[tuned], refused), "{tuned}: {before} {eval}");
    }
    let gated = |v: &Value| v.as_i64().unwrap();
    assert!(
        (gated(&before["gated"]) - gated(&eval["gated"])).abs() <= 2,
        "{before} {eval}"
    );

    let bad = bad_config(d.path());
    // (tests/run builds with the `bayesian` feature)
    for optimiser in ["grid", "nelder-mead", "pso", "bayesian"] {
        let out = d.path().join(format!("{optimiser}.toml"));
        // The grid: 3 points a parameter, 81 in all.
        let steps = if optimiser == "grid" { ",steps=3" } else { "" };
        let params: Vec<String> = PARAMS.iter().map(|p| format!("{p}{steps}")).collect();
        let mut extra = vec![
            "--reference",
            "/truth",
            "--optimiser",
            optimiser,
            "--max-evals",
            "81",
        ];
        extra.extend(params.iter().map(String::as_str));
        let r = tune(&log, &bad, &out, &extra);
        let (b, a) = (
            r["objective_before"].as_f64().unwrap(),
            r["objective_after"].as_f64().unwrap(),
        );
        assert!(a < 0.5 * b, "{optimiser}: {b} -> {a}");
        assert!(
            r["after"]["position_rmse_m"].as_f64() < r["before"]["position_rmse_m"].as_f64(),
            "{optimiser}: {r}"
        );
        only_the_tuned_numbers_changed(&bad, &out);
        // Re-fusing with the tuned file gives the figures the report promised.
        let check = d.path().join(format!("{optimiser}.fused.mcap"));
        let refused: Value =
            ok_json(&["refuse", s(&log), "-c", s(&out), "-o", s(&check), "--json"]);
        assert!(close(
            &refused["eval"]["pipelines"][0]["position_error_m"]["rmse"],
            &r["after"]["position_rmse_m"]
        ));
        the_trace_records_every_evaluation(&out, &r, (b, a));
        let rrd = d.path().join(format!("{optimiser}.rrd"));
        let viz = ok(&[
            "viz",
            s(&out.with_extension("trace.mcap")),
            "--save",
            s(&rrd),
        ]);
        assert!(stderr(&viz).contains("on 6 entities"), "{}", stderr(&viz));
    }
}

#[test]
fn the_same_seed_gives_the_same_tuning_on_one_thread_or_two() {
    let d = tempfile::tempdir().unwrap();
    let log = default_run(d.path(), 3, 120);
    let bad = bad_config(d.path());
    // One optimiser's run: the tuned config, the trace but for its elapsed times, the report.
    let run = |name: &str, optimiser: &str, evals: &str, more: &[&str]| {
        let out = d.path().join(format!("{name}.toml"));
        let mut extra = vec![
            "--reference",
            "/truth",
            "--optimiser",
            optimiser,
            "--max-evals",
            evals,
        ];
        extra.extend(more);
        extra.extend(PARAMS);
        let r = tune(&log, &bad, &out, &extra);
        let trace = std::fs::read_to_string(out.with_extension("trace.csv")).unwrap();
        let trace: Vec<String> = trace
            .lines()
            .map(|l| {
                let mut f: Vec<&str> = l.split(',').collect();
                f.remove(1);
                f.join(",")
            })
            .collect();
        (std::fs::read_to_string(&out).unwrap(), trace, r)
    };
    let pso = |name: &str, seed: &str, threads: &str| {
        run(name, "pso", "40", &["--seed", seed, "--threads", threads])
    };
    let (a, ta, ra) = pso("a", "7", "1");
    // Bayesian optimisation too: its design and model are seeded.
    let bayes = |name: &str| run(name, "bayesian", "25", &[]).0;
    assert_eq!(bayes("bo1"), bayes("bo2"));
    let (b, tb, _) = pso("b", "7", "2");
    let (c, tc, _) = pso("c", "8", "2");
    assert_eq!(a, b);
    assert_eq!(ta, tb);
    assert_ne!(ta, tc, "another seed searches elsewhere");
    assert_ne!(a, c);
    assert_eq!(ra["threads"], 1);
}

#[test]
fn likelihood_tuning_without_a_reference_makes_the_innovations_consistent() {
    let d = tempfile::tempdir().unwrap();
    let log = default_run(d.path(), 4, 180);
    let bad = bad_config(d.path());
    let mut extra = vec!["--max-evals", "120"];
    extra.extend(&PARAMS[1..]);
    let r = tune(&log, &bad, &d.path().join("nll.toml"), &extra);
    assert_eq!(r["objective"]["kind"], "nll");
    assert!(
        r["before"]["position_rmse_m"].is_null(),
        "no reference, no errors"
    );
    let nis = |m: &Value| m["nis_mean"].as_f64().unwrap();
    // Variances 100x too small: the NIS averages far above 1; tuned, it comes near it.
    assert!(nis(&r["before"]) > 5.0, "{r}");
    assert!(
        (nis(&r["after"]) - 1.0).abs() < 0.5 * (nis(&r["before"]) - 1.0),
        "{r}"
    );
    assert!(r["objective_after"].as_f64() < r["objective_before"].as_f64());
}

#[test]
fn bad_tuning_requests_get_one_clear_line_each() {
    let d = tempfile::tempdir().unwrap();
    let log = default_run(d.path(), 5, 30);
    let out = d.path().join("t.toml");
    let kalman = sample("kalman.toml");
    let seed001 = d.path().join("seed001.mcap");
    simulate(&["--scenario", "seed001", "--duration", "20"], &seed001);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["--params", "motion.jerk_pds=0.01..1"],
            "motion.jerk_pds: not found: there is no 'jerk_pds' here",
        ),
        (
            vec!["--params", "motion.jerk_psd=1..10"],
            "bounds 1 … 10 do not contain the file's value 0.2",
        ),
        (
            vec!["--params", "sensor[/loop/position].variance=0.01..1"],
            "is \"message\"",
        ),
        (vec!["--params", "motion.jerk_psd=0.01"], "no MIN..MAX"),
        (
            vec![
                "--params",
                "motion.jerk_psd=0.01..1",
                "--reference",
                "/nope",
            ],
            "has no reference channel /nope",
        ),
        (
            vec!["--params", "motion.jerk_psd=0.01..1", "--objective", "rmse"],
            "the rmse objective needs a reference",
        ),
    ];
    for (extra, expected) in cases {
        tune_refused(&[&log], &kalman, "kalman", &extra, &out, &[expected]);
    }
    // A log without a sensor the pipeline requires, and a pipeline the file does not have.
    let requires_loop = d.path().join("requires_loop.toml");
    std::fs::write(
        &requires_loop,
        std::fs::read_to_string(&kalman).unwrap().replace(
            "topic = \"/loop/position\"",
            "topic = \"/loop/position\"\nrequired = true",
        ),
    )
    .unwrap();
    let jerk = ["--params", "motion.jerk_psd=0.01..1"];
    let expected = ["/loop/position", "is not in the file"];
    tune_refused(
        &[&seed001],
        &requires_loop,
        "kalman",
        &jerk,
        &out,
        &expected,
    );
    let expected = ["no [[pipeline]] of that name (it has kalman)"];
    tune_refused(&[&log], &kalman, "nope", &jerk, &out, &expected);
    assert!(!out.exists(), "nothing written on a refused request");
}

#[test]
fn em_recovers_seed000_s_known_noise_from_a_start_ten_times_off() {
    // seed000 states its noise: jerk variance 0.001, loop and radar variances 0.01.
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<PathBuf> = (1..=3)
        .map(|seed| {
            let log = d.path().join(format!("s{seed}.mcap"));
            let seed = seed.to_string();
            simulate(
                &[
                    "--scenario",
                    "seed000",
                    "--seed",
                    &seed,
                    "--duration",
                    "1000",
                ],
                &log,
            );
            log
        })
        .collect();
    let text = std::fs::read_to_string(sample("seed000.toml")).unwrap();
    let bad = text
        .replace("jerk_variance = 0.001", "jerk_variance = 0.01")
        .replace("variance = 0.01\n", "variance = 0.1\n");
    let config = d.path().join("bad.toml");
    std::fs::write(&config, bad).unwrap();
    let mut args = vec!["tune"];
    args.extend(logs.iter().map(|l| s(l)));
    let out = d.path().join("em.toml");
    args.extend([
        "-c",
        s(&config),
        "--pipeline",
        "kf_no_balise",
        "--optimiser",
        "em",
        "--params=motion.jerk_variance=1e-6..1",
        "--params=sensor[/loop/position].variance=1e-5..1",
        "--params=sensor[/radar/speed].variance=1e-5..1",
        "-o",
        s(&out),
        "--json",
    ]);
    let r = ok_json(&args);
    let found = |name: &str| tuned_value(&r, name);
    // Three 1000 s runs: the variances to 5 %, the jerk (seen only through the motion) to 15 %.
    let jerk = found("motion.jerk_variance") / 0.001 - 1.0;
    let lp = found("sensor[/loop/position].variance") / 0.01 - 1.0;
    let radar = found("sensor[/radar/speed].variance") / 0.01 - 1.0;
    assert!(
        jerk.abs() < 0.15 && lp.abs() < 0.05 && radar.abs() < 0.05,
        "{jerk} {lp} {radar}"
    );
    // The likelihood never falls from one EM iteration to the next.
    let ll: Vec<f64> = serde_json::from_value(r["em_log_likelihood"].clone()).unwrap();
    assert!(
        ll.len() > 3 && ll.windows(2).all(|w| w[1] >= w[0] - 1e-6 * w[0].abs()),
        "{ll:?}"
    );
    // EM refuses what it cannot estimate, in one line.
    let extra = [
        "--optimiser",
        "em",
        "--params=initial.speed_std_mps=0.1..10",
    ];
    let expected = ["em: estimates the motion noise"];
    tune_refused(
        &[&logs[0]],
        &config,
        "kf_no_balise",
        &extra,
        &out,
        &expected,
    );
}

/// `railfuse tune LOGS -c CONFIG --pipeline PIPELINE EXTRA -o OUT` fails with one line
/// holding every one of `expected`.
fn tune_refused(
    logs: &[&Path],
    config: &Path,
    pipeline: &str,
    extra: &[&str],
    out: &Path,
    expected: &[&str],
) {
    let mut args = vec!["tune"];
    args.extend(logs.iter().map(|l| s(l)));
    args.extend(["-c", s(config), "--pipeline", pipeline, "-o", s(out)]);
    args.extend(extra);
    refused(&args, expected);
}

/// The tuned value of parameter `name` in a `tune --json` report.
fn tuned_value(report: &Value, name: &str) -> f64 {
    let params = report["params"].as_array().unwrap();
    let p = params.iter().find(|p| p["name"] == name).unwrap();
    p["after"].as_f64().unwrap()
}

/// `railfuse args` fails with one line on stderr holding every one of `expected`.
fn refused(args: &[&str], expected: &[&str]) {
    let o = railfuse(args);
    let err = stderr(&o);
    assert!(!o.status.success(), "{args:?}");
    assert!(expected.iter().all(|e| err.contains(e)), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn ctrl_c_ends_the_search_and_writes_the_best_found() {
    let d = tempfile::tempdir().unwrap();
    let log = default_run(d.path(), 7, 120);
    let bad = bad_config(d.path());
    let out = d.path().join("stopped.toml");
    let mut args = vec![
        "tune".to_owned(),
        s(&log).to_owned(),
        "-c".into(),
        s(&bad).to_owned(),
        "--pipeline".into(),
        "kalman".into(),
        "--reference".into(),
        "/truth".into(),
        "--optimiser".into(),
        "pso".into(),
        "--max-evals".into(),
        "10000000".into(),
        "-o".into(),
        s(&out).to_owned(),
        "--json".into(),
    ];
    args.extend(PARAMS.iter().map(|p| p.to_string()));
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .args(&args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(2));
    // SAFETY: signalling our own child by its pid.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["ending"], "interrupted");
    assert!(r["evaluations"].as_u64().unwrap() < 10_000_000);
    assert!(r["objective_after"].as_f64() <= r["objective_before"].as_f64());
    let tuned = std::fs::read_to_string(&out).unwrap();
    assert!(tuned.contains("[[pipeline.sensor]]"));
    assert!(out.with_extension("trace.csv").exists() && out.with_extension("trace.mcap").exists());
}

/// The tuned file is the bad one with only the tuned numbers changed.
fn only_the_tuned_numbers_changed(bad: &Path, out: &Path) {
    let (old, new) = (
        std::fs::read_to_string(bad).unwrap(),
        std::fs::read_to_string(out).unwrap(),
    );
    let changed: Vec<(&str, &str)> = old
        .lines()
        .zip(new.lines())
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(old.lines().count(), new.lines().count());
    assert!(!changed.is_empty() && changed.len() <= 4, "{changed:?}");
    for (a, b) in &changed {
        assert!(
            a.contains("variance") && b.contains("variance")
                || a.contains("jerk_psd") && b.contains("jerk_psd"),
            "{a} -> {b}"
        );
    }
}

/// The trace: one row per evaluation, its best never rising, the first the file's objective
/// `b`, the last the tuned one `a`; the same trace as an MCAP channel, which viz lays out:
/// objective, best, each value.
fn the_trace_records_every_evaluation(out: &Path, r: &Value, (b, a): (f64, f64)) {
    let trace = std::fs::read_to_string(out.with_extension("trace.csv")).unwrap();
    let rows: Vec<Vec<f64>> = trace
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len() as u64, r["evaluations"].as_u64().unwrap());
    assert!(rows.len() <= 81);
    // (serde_json reads floats to within an ulp, not exactly.)
    assert!((rows[0][2] - b).abs() < 1e-12);
    assert!(rows.windows(2).all(|w| w[1][3] <= w[0][3]));
    assert!((rows.last().unwrap()[3] - a).abs() < 1e-12);
    // The same trace as an MCAP channel, which viz lays out: objective, best, each value.
    let mcap = out.with_extension("trace.mcap");
    let trace: Vec<railfuse_catalog::messages::TuneEvaluation> =
        messages(&mcap, "/tune/kalman/trace");
    assert_eq!(trace.len(), rows.len());
    assert!(trace.windows(2).all(|w| w[0].stamp_ns < w[1].stamp_ns));
    assert_eq!(trace[0].values.len(), 4);
    assert_eq!(trace[0].values[0].name, "motion.jerk_psd");
    assert_eq!(trace[0].values[0].value, 20.0);
}
