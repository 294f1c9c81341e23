//! `railfuse._railfuse`: the Python extension behind the `railfuse` package. A thin layer over
//! the library crates (never the Rerun crate, to keep the build short): each function takes
//! paths and settings, releases the GIL while the work runs, and returns its report as JSON
//! text for the Python side to load. Errors raise `railfuse.RailfuseError` with the same one
//! line the command line prints.

use std::path::PathBuf;

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::run::Run;
use railfuse_refuse::config::{ObjectiveKind, OptimiserKind};
use railfuse_refuse::replay::{refuse as refuse_log, RefuseOptions};
use railfuse_refuse::spec::Pipelines;
use railfuse_tune::{TuneRequest, Tuner as RustTuner};

create_exception!(_railfuse, RailfuseError, PyException);

/// Any error as the Python exception, its message the one line the CLI prints.
fn fail(e: impl std::fmt::Display) -> PyErr {
    RailfuseError::new_err(e.to_string())
}

fn json(v: &impl serde::Serialize) -> PyResult<String> {
    serde_json::to_string(v).map_err(fail)
}

/// A config enum from its snake_case name (`nelder-mead` as well as `nelder_mead`).
fn parse_enum<T: serde::de::DeserializeOwned>(what: &str, s: Option<&str>) -> PyResult<Option<T>> {
    s.map(|s| {
        serde_json::from_value(serde_json::Value::String(s.replace('-', "_")))
            .map_err(|_| fail(format!("unknown {what} '{s}'")))
    })
    .transpose()
}

/// Simulates a run of a scenario preset into `output`; the report as JSON.
#[pyfunction]
#[pyo3(signature = (output, scenario = "default", seed = 0, duration_s = None, faults = Vec::new()))]
fn simulate(
    py: Python<'_>,
    output: PathBuf,
    scenario: &str,
    seed: u64,
    duration_s: Option<f64>,
    faults: Vec<String>,
) -> PyResult<String> {
    let preset = railfuse_record::Scenario::preset(scenario).ok_or_else(|| {
        fail(format!(
            "unknown scenario '{scenario}' (presets: {})",
            railfuse_record::Scenario::NAMES.join(", ")
        ))
    })?;
    let faults = faults
        .iter()
        .map(|f| f.parse::<railfuse_record::simulator::FaultSpec>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(fail)?;
    preset
        .check(duration_s, &faults)
        .map_err(|e| fail(format!("--{e}")))?;
    let report = py
        .detach(|| railfuse_record::simulate(&preset, seed, duration_s, &faults, &output))
        .map_err(fail)?;
    json(&report)
}

/// The run of `inputs` (files, directories of parts, bags), as the command line reads it,
/// its recorders put on one clock with `align = "gnss"`.
fn open_run(inputs: &[PathBuf], align: &str) -> PyResult<Run> {
    open_run_mapped(inputs, align, None)
}

/// [`open_run`] with a logger CSV's column mapping (`--map`).
fn open_run_mapped(inputs: &[PathBuf], align: &str, mapping: Option<PathBuf>) -> PyResult<Run> {
    let csv = match mapping {
        Some(path) => Some(std::sync::Arc::new(
            railfuse_catalog::formats::csv_table::mapping::MappingFile::read(&path)
                .map_err(fail)?,
        )),
        None => None,
    };
    let options = railfuse_catalog::run::RunOptions {
        align: align.parse().map_err(fail)?,
        formats: railfuse_catalog::formats::FormatOptions {
            csv,
            ..Default::default()
        },
        ..Default::default()
    };
    Run::open(inputs, &options).map_err(fail)
}

/// `withhold` hidden in the `outages` (`LEN[:every=PERIOD][:from=T]`, `standard`; the whole
/// run without them), as `--withhold`/`--outages` take them.
fn withhold_of(
    withhold: Option<String>,
    outages: Option<&str>,
) -> PyResult<Option<railfuse_eval::outages::Withhold>> {
    let Some(topic) = withhold else {
        return match outages {
            Some(_) => Err(fail("outages without withhold: name the topic to withhold")),
            None => Ok(None),
        };
    };
    Ok(Some(railfuse_eval::outages::Withhold {
        topic,
        outages: outages.map(str::parse).transpose().map_err(fail)?,
    }))
}

/// The reference `topic`, its GNSS fixes of `quality` counting (`auto`, `all`, `rtk_fixed`, …).
fn reference_of(topic: &str, quality: &str) -> PyResult<railfuse_eval::Reference> {
    Ok(railfuse_eval::Reference {
        topic: topic.to_owned(),
        quality: quality.parse().map_err(fail)?,
    })
}

/// Re-fuses the run `inputs` with the pipelines of `config` into `output`, as `railfuse
/// refuse` does (the same bytes); the refuse report and the accuracy table as JSON.
#[pyfunction]
#[pyo3(signature = (inputs, config, output, reference = "/truth", align = "none", reference_quality = "auto", withhold = None, outages = None))]
#[allow(clippy::too_many_arguments)]
fn refuse(
    py: Python<'_>,
    inputs: Vec<PathBuf>,
    config: PathBuf,
    output: PathBuf,
    reference: &str,
    align: &str,
    reference_quality: &str,
    withhold: Option<String>,
    outages: Option<&str>,
) -> PyResult<String> {
    let reference = reference_of(reference, reference_quality)?;
    let withhold = withhold_of(withhold, outages)?;
    let pipelines = Pipelines::load(&config).map_err(fail)?;
    let run = open_run(&inputs, align)?;
    let (report, eval) = py
        .detach(|| {
            refuse_log(&RefuseOptions {
                run: &run,
                output: &output,
                config: &pipelines,
                config_source: config.display().to_string(),
                reference: &reference,
                withhold: withhold.as_ref(),
                progress: None,
                observer: None,
            })
        })
        .map_err(fail)?;
    json(&serde_json::json!({ "refuse": report, "eval": eval }))
}

/// The accuracy table of a fused run against `reference`, as JSON.
#[pyfunction]
#[pyo3(signature = (inputs, reference = "/truth", align = "none", reference_quality = "auto", withhold = None, outages = None))]
fn evaluate(
    py: Python<'_>,
    inputs: Vec<PathBuf>,
    reference: &str,
    align: &str,
    reference_quality: &str,
    withhold: Option<String>,
    outages: Option<&str>,
) -> PyResult<String> {
    let reference = reference_of(reference, reference_quality)?;
    let run = open_run(&inputs, align)?;
    let placed = match withhold_of(withhold, outages)? {
        Some(w) => {
            let reader = run.reader().map_err(fail)?;
            let span = reader.summary().and_then(|s| s.message_span_ns);
            Some(
                w.place(span)
                    .map_err(|e| fail(format!("{}: {e}", run.display())))?,
            )
        }
        None => None,
    };
    let report = py
        .detach(|| railfuse_eval::evaluate(&run, &reference, placed.as_ref()))
        .map_err(fail)?;
    json(&report)
}

/// Every message of `topic` as newline-delimited JSON, each object with its `log_time_ns`
/// first: what `railfuse.read` turns into a table.
#[pyfunction]
#[pyo3(signature = (inputs, topic, mapping = None))]
fn read_json_lines<'py>(
    py: Python<'py>,
    inputs: Vec<PathBuf>,
    topic: &str,
    mapping: Option<PathBuf>,
) -> PyResult<Bound<'py, PyBytes>> {
    let run = open_run_mapped(&inputs, "none", mapping)?;
    let path = run.name().to_owned();
    let lines = py
        .detach(|| -> Result<Option<Vec<u8>>, railfuse_catalog::Error> {
            let mut out = Vec::new();
            let mut found = false;
            let mut reader = run.reader()?;
            while let Some(record) = reader.next() {
                match record? {
                    LogRecord::Channel(c) if c.topic == topic => found = true,
                    LogRecord::Message(m) if m.channel.topic == topic => {
                        // A protobuf channel of a railfuse type becomes its JSON form.
                        let decoded = match m.channel.message_encoding.as_str() {
                            "json" => None,
                            _ => m.decode_any(&path)?.map(|any| any.to_json()),
                        };
                        let body = decoded.as_deref().unwrap_or(m.data).trim_ascii();
                        out.extend_from_slice(
                            format!("{{\"log_time_ns\":{}", m.log_time_ns).as_bytes(),
                        );
                        match body.strip_prefix(b"{") {
                            Some(rest) if rest.trim_ascii_start() != b"}" => {
                                out.push(b',');
                                out.extend_from_slice(rest);
                            }
                            _ => out.push(b'}'),
                        }
                        out.push(b'\n');
                    }
                    _ => {}
                }
            }
            Ok(found.then_some(out))
        })
        .map_err(fail)?;
    match lines {
        Some(lines) => Ok(PyBytes::new(py, &lines)),
        None => Err(fail(format!("{}: no channel {topic}", run.display()))),
    }
}

/// A tuning run: the configuration, its parameters and the logs decoded once.
#[pyclass(module = "railfuse._railfuse", frozen)]
struct Tuner {
    inner: RustTuner,
}

#[pymethods]
impl Tuner {
    #[new]
    #[pyo3(signature = (logs, config, pipeline, reference = None, params = Vec::new(), objective = None, optimiser = None, max_evaluations = None, seed = None, withhold = None, outages = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        logs: Vec<PathBuf>,
        config: PathBuf,
        pipeline: String,
        reference: Option<String>,
        params: Vec<String>,
        objective: Option<&str>,
        optimiser: Option<&str>,
        max_evaluations: Option<usize>,
        seed: Option<u64>,
        withhold: Option<String>,
        outages: Option<&str>,
    ) -> PyResult<Self> {
        let request = TuneRequest {
            config,
            pipeline,
            logs,
            reference,
            params,
            objective: parse_enum::<ObjectiveKind>("objective", objective)?,
            optimiser: parse_enum::<OptimiserKind>("optimiser", optimiser)?,
            max_evaluations,
            seed,
            withhold: withhold_of(withhold, outages)?,
            formats: Default::default(),
        };
        let inner = py.detach(|| RustTuner::open(&request)).map_err(fail)?;
        Ok(Self { inner })
    }

    /// The tuned parameters: name, min, max, scale, the file's value, grid steps.
    fn params(&self) -> PyResult<String> {
        json(&self.inner.params)
    }

    /// Per parameter, the values a grid search takes (as the file will hold them).
    fn grid(&self) -> PyResult<String> {
        json(
            &self
                .inner
                .params
                .iter()
                .map(|p| p.grid())
                .collect::<Vec<_>>(),
        )
    }

    /// Searches; the report, the trace and the tuned configuration text as JSON.
    fn run(&self, py: Python<'_>) -> PyResult<String> {
        let outcome = py.detach(|| self.inner.run(None, None)).map_err(fail)?;
        json(&serde_json::json!({
            "report": outcome.report,
            "trace": outcome.trace,
            "tuned_toml": outcome.tuned_toml,
        }))
    }

    /// The objective and figures with `values` (one per parameter), every log pooled, and
    /// each log's own.
    fn evaluate(&self, py: Python<'_>, values: Vec<f64>) -> PyResult<String> {
        let e = py.detach(|| self.inner.evaluate(&values)).map_err(fail)?;
        let objective = self.inner.objective;
        let logs: Vec<_> = e
            .logs
            .iter()
            .map(|s| serde_json::json!({ "objective": objective.value(s), "metrics": s.metrics() }))
            .collect();
        json(&serde_json::json!({
            "objective": e.objective,
            "metrics": e.pooled.metrics(),
            "logs": logs,
        }))
    }

    /// The objective of log `index` alone with `values` (a Ray trial reports log by log).
    fn evaluate_log(&self, py: Python<'_>, index: usize, values: Vec<f64>) -> PyResult<f64> {
        let r = self
            .inner
            .recordings
            .get(index)
            .ok_or_else(|| fail(format!("no log {index}")))?;
        let score = py
            .detach(|| {
                let spec = self.inner.spec_with(&values)?;
                r.replay(&spec)
            })
            .map_err(fail)?;
        Ok(self.inner.objective.value(&score))
    }

    /// The configuration text with `values` written in (comments kept).
    fn tuned_toml(&self, values: Vec<f64>) -> PyResult<String> {
        self.inner.tuned_text(&values).map_err(fail)
    }

    /// How many logs it holds.
    fn logs(&self) -> usize {
        self.inner.recordings.len()
    }
}

#[pymodule]
fn _railfuse(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RailfuseError", m.py().get_type::<RailfuseError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(refuse, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(read_json_lines, m)?)?;
    m.add_class::<Tuner>()?;
    Ok(())
}
