//! What `railfuse results` takes and where its page goes: the arguments shared by every
//! experiment, and the one place a page is written.

use std::path::PathBuf;

use anyhow::{Context, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Runs per experiment, at least 1: seeds 0 … N−1 for sources 000 and 001 and the long
    /// runs, 1 … N for --tuning, --safety, --gnss-ins and --eddy-current (each page says
    /// which).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// Where to write the table (Markdown); default docs/results.md, or docs/tuning.md with
    /// --tuning, docs/safety.md with --safety, docs/gnss_ins.md with --gnss-ins,
    /// docs/eddy_current.md with --eddy-current.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Run the tuning experiments instead: recovery of seed000's known noise values by EM and
    /// each optimiser, the default pipeline tuned and scored on held-out runs, and EM against
    /// pykalman's (needs the test venv's Python, or --python).
    #[arg(long)]
    pub tuning: bool,
    /// Run source 002's safety experiment instead (samples/seed002.toml on the seed002 and
    /// default scenarios, fault-free and faulted): availability, containment of the truth in
    /// U_safe, faults flagged; written to docs/safety.md.
    #[arg(long, conflicts_with = "tuning")]
    pub safety: bool,
    /// Run source 003's GNSS/INS experiment instead (samples/seed003.toml on seed003, on its
    /// railway in three dimensions seed003_3d and that railway's flat twin, and on the default
    /// run and its flat twin; each railway run with the IMU's mounting calibrated from it):
    /// velocity and position errors in the plane and through the 150 s GNSS loss, beside the
    /// source's figures; written to docs/gnss_ins.md.
    #[arg(long, conflicts_with_all = ["tuning", "safety"])]
    pub gnss_ins: bool,
    /// Run source 004's eddy-current experiment instead (samples/seed004.toml on the seed004
    /// preset and on a rougher track): speed error by speed band, acceleration, distance and
    /// sleeper count errors against the goals; written to docs/eddy_current.md.
    #[arg(long, conflicts_with_all = ["tuning", "safety", "gnss_ins"])]
    pub eddy_current: bool,
    /// Python with pykalman, for --tuning (default: $RAILFUSE_PYTHON, then
    /// .venv-interop/bin/python).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Folder for the simulated and fused logs.
    #[arg(long, default_value = "target/results")]
    pub dir: PathBuf,
}

/// Where the page goes: `--output`, else the page kept under docs/.
pub fn page(a: &Args) -> PathBuf {
    let default = match () {
        _ if a.safety => "docs/safety.md",
        _ if a.gnss_ins => "docs/gnss_ins.md",
        _ if a.eddy_current => "docs/eddy_current.md",
        _ if a.tuning => "docs/tuning.md",
        _ => "docs/results.md",
    };
    a.output.clone().unwrap_or_else(|| default.into())
}

/// Runs an experiment of `runs` runs (`run` is told each run done) under a progress bar.
pub fn with_progress<T, E: Into<anyhow::Error>>(
    what: &str,
    runs: u64,
    run: impl FnOnce(&dyn Fn(u64)) -> std::result::Result<T, E>,
) -> Result<T> {
    let bar = crate::progress::Progress::steps(what, runs);
    let out = run(&|done| bar.set(done)).map_err(Into::into)?;
    bar.finish();
    Ok(out)
}

/// Writes the page and prints it.
pub fn write_page(a: &Args, md: &str) -> Result<()> {
    let output = page(a);
    std::fs::write(&output, md).with_context(|| format!("{}: cannot write", output.display()))?;
    print!("{md}");
    crate::say!("-> {}", output.display());
    Ok(())
}

/// A page's text with `{{name}}` holes, filled from the results: the prose lives in the
/// page's template (`pages/*.md`), the figures in the tables and values set here.
pub struct Template {
    text: &'static str,
    values: Vec<(&'static str, String)>,
}

impl Template {
    pub fn new(text: &'static str) -> Self {
        Self {
            text,
            values: Vec::new(),
        }
    }

    pub fn set(mut self, name: &'static str, value: impl std::fmt::Display) -> Self {
        self.values.push((name, value.to_string()));
        self
    }

    /// The page; every hole filled and every value used, or which is not.
    pub fn render(self) -> Result<String> {
        let mut out = self.text.to_owned();
        for (name, value) in &self.values {
            let hole = format!("{{{{{name}}}}}");
            anyhow::ensure!(out.contains(&hole), "page template has no {hole}");
            out = out.replace(&hole, value);
        }
        if let Some(i) = out.find("{{") {
            let hole: String = out[i..].chars().take_while(|c| *c != '}').collect();
            anyhow::bail!("page template: {hole}}}}} is not filled");
        }
        Ok(out)
    }
}
