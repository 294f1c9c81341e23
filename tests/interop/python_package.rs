//! The Python package (pyo3), its Ray tasks and Ray Tune experiment, and the configuration schema
//! as `jsonschema` reads it.

use super::*;

/// The Python package's `refuse` writes exactly what the CLI writes; its tables, tuning and
/// errors are the CLI's.
#[test]
fn the_python_package_refuses_byte_for_byte_like_the_cli_and_reads_tables() {
    let d = tempfile::tempdir().unwrap();
    let raw = d.path().join("raw.mcap");
    simulate(&["--seed", "6", "--duration", "60"], &raw);
    let config = sample("kalman.toml");
    let cli = d.path().join("cli.fused.mcap");
    ok(&["refuse", s(&raw), "-c", s(&config), "-o", s(&cli)]);
    let v = python_ok(
        "python_package.py",
        &[s(d.path()), s(&config), s(&cli), s(&raw)],
    );
    let py = d.path().join("py.fused.mcap");
    assert_eq!(
        std::fs::read(&cli).unwrap(),
        std::fs::read(&py).unwrap(),
        "railfuse.refuse and railfuse refuse write the same bytes"
    );
    let states: Vec<railfuse_catalog::messages::FusedState> = messages(&cli, "/fused/kalman/state");
    assert_eq!(v["state_rows"].as_u64().unwrap() as usize, states.len());
    assert_eq!(v["first_chainage"].as_f64().unwrap(), states[0].chainage_m);
    assert_eq!(v["covariance_type"], "list<item: double>");
    assert_eq!(v["state_columns"][0], "log_time_ns");
    let radar: Vec<railfuse_catalog::messages::RadarSpeed> = messages(&raw, "/radar/speed");
    assert_eq!(v["radar_rows"].as_u64().unwrap() as usize, radar.len());
    assert_eq!(v["gpx_rows"], 91);
    // A logger's CSV with its column mapping, as --map reads it.
    assert_eq!(v["csv_rows"], 451);
    assert_eq!(v["gpx_first_latitude"], 44.6551002);
    assert!(v["mdf4_frames"].as_u64().unwrap() > 10, "{v}");
    // (refuse scores in the same pass, evaluate from the file: sums in another order)
    close(&v["refuse_rmse"], &v["evaluate_rmse"]);
    // A GNSS reference with the fixes it counts, as --reference-quality all does.
    let cli_all: serde_json::Value = serde_json::from_slice(
        &railfuse(&[
            "eval",
            s(&py),
            "--reference",
            "/gnss/fix",
            "--reference-quality",
            "all",
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert_eq!(
        v["gnss_all"], cli_all["pipelines"][0]["reference_fixes"],
        "{v}"
    );
    assert_eq!(v["gnss_all"]["quality"], "all");
    // Outages scored from Python as `eval --withhold --outages` scores them.
    let cli_outages: serde_json::Value = serde_json::from_slice(
        &railfuse(&[
            "eval",
            s(&py),
            "--withhold",
            "/gnss/fix",
            "--outages",
            "5:every=10:from=5",
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert_eq!(v["outages"], cli_outages["pipelines"][0]["outages"], "{v}");
    assert!(
        v["outages"]["each"]
            .as_array()
            .is_some_and(|e| !e.is_empty()),
        "{v}"
    );
    // Errors: the CLI's one line, as RailfuseError.
    let e = &v["errors"];
    let missing = d.path().join("nope.toml");
    let cli_err = stderr(&railfuse(&[
        "refuse",
        s(&raw),
        "-c",
        s(&missing),
        "-o",
        s(&py),
    ]));
    assert!(
        cli_err.contains(e["missing_config"].as_str().unwrap()),
        "{cli_err} / {e}"
    );
    assert_eq!(v["pandas_rows"], v["state_rows"], "{v}");
    for (case, says) in [
        ("missing_topic", "no channel /nope"),
        ("unknown_reference", "reference /nothere is not in the log"),
        ("unknown_quality", "'rtk' is not a fix quality"),
        (
            "withhold_unfused",
            "withhold /gnss/fix: no pipeline fuses it",
        ),
        ("unknown_param", "motion.jerk_pds: not found"),
        ("unknown_scenario", "unknown scenario 'nope'"),
    ] {
        let said = e[case].as_str().unwrap_or_else(|| panic!("{case}: {e}"));
        assert!(said.contains(says), "{case}: {e}");
    }
    // Tuning from Python finds what the CLI finds.
    let out = d.path().join("cli-tuned.toml");
    let cli_tune: serde_json::Value = ok_json(&[
        "tune",
        s(&raw),
        "-c",
        s(&config),
        "--pipeline",
        "kalman",
        "--reference",
        "/truth",
        "--params",
        "motion.jerk_psd=0.001..10",
        "--optimiser",
        "grid",
        "-o",
        s(&out),
        "--json",
    ]);
    assert_eq!(
        v["tuned"]["motion.jerk_psd"],
        cli_tune["params"][0]["after"]
    );
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(d.path().join("py-tuned.toml")).unwrap()
    );
}

/// railfuse.ray on a local Ray cluster: tasks give the local figures, and the Ray Tune grid
/// search finds the values the local grid search finds.
#[test]
fn the_ray_path_refuses_many_logs_and_tunes_to_the_local_values() {
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<std::path::PathBuf> = (1..=2)
        .map(|seed| {
            let log = d.path().join(format!("r{seed}.mcap"));
            ok(&[
                "simulate",
                "--seed",
                &seed.to_string(),
                "--duration",
                "60",
                "-o",
                s(&log),
            ]);
            log
        })
        .collect();
    let config = sample("kalman.toml");
    let mut args = vec![s(d.path()), s(&config)];
    args.extend(logs.iter().map(|l| s(l)));
    let v = python_ok("ray_fleet.py", &args);
    one_result_from_three_doors(d.path(), &config);
    for (i, log) in logs.iter().enumerate() {
        let local = d.path().join(format!("local{i}.fused.mcap"));
        let r: serde_json::Value = ok_json(&[
            "refuse",
            s(log),
            "-c",
            s(&config),
            "-o",
            s(&local),
            "--json",
        ]);
        close(
            &v["refuse_rmse"][i],
            &r["eval"]["pipelines"][0]["position_error_m"]["rmse"],
        );
        close(&v["evaluate_rmse"][i], &v["refuse_rmse"][i]);
    }
    assert_eq!(v["ray"], v["local"], "{v}");
    let (a, b) = (
        v["ray_objective"].as_f64().unwrap(),
        v["local_objective"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-9 * b.abs(), "{v}");
    assert_eq!(v["trials"], 9);
    assert!(
        v["missing_log"].as_str().unwrap().contains("missing.mcap"),
        "{v}"
    );
}

/// One result, three doors: the first log re-fused by a Ray task (absolute paths), by
/// `railfuse.refuse` and by the CLI from another working directory with relative paths, and
/// by the CLI with absolute paths, gives the same bytes; the provenance it records is the
/// input's file name and digest and the configuration's file name.
fn one_result_from_three_doors(dir: &std::path::Path, config: &std::path::Path) {
    let work = dir.join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::copy(config, work.join("kalman.toml")).unwrap();
    let relative = std::process::Command::new(env!("CARGO_BIN_EXE_railfuse"))
        .current_dir(&work)
        .args([
            "refuse",
            "../r1.mcap",
            "-c",
            "kalman.toml",
            "-o",
            "cli.fused.mcap",
        ])
        .output()
        .unwrap();
    assert!(relative.status.success(), "{}", stderr(&relative));
    let absolute = dir.join("abs.fused.mcap");
    refuse(&dir.join("r1.mcap"), "kalman.toml", &absolute);
    let bytes = |p: &std::path::Path| std::fs::read(p).unwrap();
    let ray = bytes(&dir.join("ray0.fused.mcap"));
    for other in [
        work.join("cli.fused.mcap"),
        dir.join("py0.fused.mcap"),
        absolute,
    ] {
        assert!(
            bytes(&other) == ray,
            "{other:?} differs from the Ray task's output"
        );
    }
    let info = ok_json(&["info", s(&dir.join("ray0.fused.mcap")), "--json"]);
    let meta = info["metadata"].to_string();
    let digest = sha256_hex(&dir.join("r1.mcap"));
    for said in ["\"input\":\"r1.mcap\"", "\"config_source\":\"kalman.toml\""] {
        assert!(meta.contains(said), "{said}: {meta}");
    }
    assert!(meta.contains(&digest), "{digest}: {meta}");
}

/// The SHA-256 of a file, in hex, computed here (not by railfuse).
fn sha256_hex(path: &std::path::Path) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(std::fs::read(path).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The configuration schema (`refuse --config-schema`) checked by `jsonschema`: every sample
/// configuration is valid, a misspelt key, a wrong type and an unknown setting are not.
#[test]
fn every_sample_configuration_is_valid_against_the_schema_jsonschema_reads() {
    let d = tempfile::tempdir().unwrap();
    let schema = d.path().join("schema.json");
    let out = ok(&["refuse", "--config-schema"]);
    std::fs::write(&schema, &out.stdout).unwrap();
    let samples = sample("");
    let py = python("config_schema.py", &[s(&schema), s(&samples)]);
    assert!(
        py.status.success(),
        "{}{}",
        String::from_utf8_lossy(&py.stdout),
        String::from_utf8_lossy(&py.stderr)
    );
    println!("{}", String::from_utf8_lossy(&py.stdout));
}

#[test]
fn the_python_package_aligns_several_recorders_as_the_cli_does() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().join("three");
    ok(&[
        "simulate",
        "--duration",
        "60",
        "--seed",
        "2",
        "--recorder",
        "box",
        "--recorder",
        "rack=+0.35,+20ppm",
        "-o",
        s(&dir),
    ]);
    let files = [dir.join("box.mcap"), dir.join("rack.mcap")];
    let config = sample("kalman.toml");
    let cli = d.path().join("cli.fused.mcap");
    ok(&[
        "refuse",
        s(&files[0]),
        s(&files[1]),
        "--align",
        "gnss",
        "-c",
        s(&config),
        "-o",
        s(&cli),
    ]);
    let py = d.path().join("py.fused.mcap");
    let v = python_ok(
        "python_align.py",
        &[s(&config), s(&py), s(&files[0]), s(&files[1])],
    );
    assert!(v["rmse"].as_f64().unwrap() < 1.0, "{v}");
    assert_eq!(
        std::fs::read(&cli).unwrap(),
        std::fs::read(&py).unwrap(),
        "railfuse.refuse(align=\"gnss\") and railfuse refuse --align gnss write the same bytes"
    );
}
