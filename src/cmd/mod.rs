pub mod bench;
pub mod bench_can;
pub mod bench_em;
pub mod bench_mdf;
pub mod bench_record;
pub mod bench_runs;
pub mod bench_track;
pub mod bench_tune;
pub mod bench_viz;
pub mod calibrate;
pub mod demo;
pub mod eval;
pub mod export;
pub mod import;
pub mod info;
pub mod measure;
pub mod merge;
pub mod record;
pub mod recover;
pub mod refuse;
pub mod results;
pub mod run_input;
pub mod simulate;
pub mod track;
pub mod tune;
pub mod viz;

/// The pipeline configuration used when none is given: `samples/kalman.toml`.
pub const DEFAULT_PIPELINES: &str = railfuse_experiments::long_runs::KALMAN_PIPELINES;

/// The simulator's presets as `--scenario` and `--simulate` take them, each with what it is.
pub fn scenarios() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(railfuse_record::Scenario::NAMES.iter().map(|n| {
        clap::builder::PossibleValue::new(*n).help(railfuse_record::Scenario::describe(n))
    }))
}

/// `path` can be written: checked before a long run, not found out at its end. A file the
/// check creates is removed again.
pub fn check_writable(path: &std::path::Path) -> anyhow::Result<()> {
    let existed = path.exists();
    let opened = std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path);
    if let Err(e) = opened {
        let why = match path
            .parent()
            .filter(|p| !p.as_os_str().is_empty() && !p.is_dir())
        {
            Some(dir) => format!("its folder {} does not exist", dir.display()),
            None => e.to_string(),
        };
        anyhow::bail!("{}: cannot write: {why}", path.display());
    }
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}
