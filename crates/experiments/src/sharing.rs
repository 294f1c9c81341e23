//! What the information-sharing coefficients change: source 000's α and source 001's β, as
//! each source tables them by speed, against equal shares, under the two ways a master can
//! use them (`federated.fusion`): as each sub-filter's share of the fused information
//! (Carlson's information sharing, under which they can only act between master fusions) and
//! as the weights of the local estimates (the sources' weighting).

use std::path::Path;

use railfuse_refuse::config::embedded_path;
use railfuse_refuse::spec::{PipelineSpec, Pipelines};
use serde::Serialize;

use crate::{envelopes, run, Envelope, Error, Result};

/// One source's federated pipeline in one run: (source, scenario, pipeline, its sharing
/// table's name).
pub const EXPERIMENTS: &[(&str, &str, &str, &str)] = &[
    (
        "000",
        "seed000_loop_drift",
        "fpf_drift_balise",
        "source_000",
    ),
    ("001", "seed001", "fkf", "source_001"),
];

/// The variants of each pipeline: (name suffix, fusion, sharing as the source or even).
const VARIANTS: &[(&str, &str, bool)] = &[
    ("", "information", true),
    ("_even", "information", false),
    ("_shares", "shares", true),
    ("_shares_even", "shares", false),
];

#[derive(Debug, Clone, Serialize)]
pub struct SharingRow {
    pub source: &'static str,
    pub scenario: &'static str,
    pub pipeline: String,
    pub fusion: &'static str,
    /// The sharing table: the source's, or "even".
    pub sharing: &'static str,
    pub envelope: Envelope,
}

/// `base` with its federated table's fusion and sharing set, under `name`.
fn variant(base: &PipelineSpec, name: &str, fusion: &str, sharing: &str) -> Result<String> {
    let mut doc: toml::Table = toml::from_str(&base.to_toml()).map_err(Error::Toml)?;
    let pipeline = doc
        .get_mut("pipeline")
        .and_then(|p| p.as_array_mut())
        .and_then(|p| p.first_mut())
        .and_then(|p| p.as_table_mut())
        .expect("a serialised pipeline");
    pipeline.insert("name".into(), name.into());
    let federated = pipeline
        .entry("federated")
        .or_insert_with(|| toml::Table::new().into())
        .as_table_mut()
        .expect("a federated table");
    federated.insert("fusion".into(), fusion.into());
    federated.insert("sharing".into(), sharing.into());
    federated.remove("band");
    Ok(toml::to_string(&doc).expect("a table serialises"))
}

/// Every variant of every experiment over `seeds` seeds; `seed000` and `seed001` are the
/// parsed `samples/seed000.toml` and `samples/seed001.toml`.
pub fn run_all(
    dir: &Path,
    seeds: u64,
    seed000: &Pipelines,
    seed001: &Pipelines,
    step: &mut dyn FnMut(),
) -> Result<Vec<SharingRow>> {
    let mut rows = Vec::new();
    for &(source, scenario, base, table) in EXPERIMENTS {
        let samples = match source {
            "000" => seed000,
            _ => seed001,
        };
        let spec = samples
            .pipeline
            .iter()
            .find(|p| p.name == base)
            .expect("the experiment's pipeline is in its sample");
        let mut config = String::new();
        let mut names = Vec::new();
        for &(suffix, fusion, as_source) in VARIANTS {
            let name = format!("{base}{suffix}");
            let sharing = if as_source { table } else { "even" };
            config.push_str(&variant(spec, &name, fusion, sharing)?);
            config.push('\n');
            names.push((name, fusion, sharing));
        }
        let pipelines = Pipelines::parse(&config, &embedded_path("sharing variants"))?;
        let list: Vec<&str> = names.iter().map(|(n, _, _)| n.as_str()).collect();
        let env = envelopes(seeds, &list, step, |seed| {
            run(dir, scenario, seed, &[], &pipelines, "sharing")
        })?;
        for ((name, fusion, sharing), envelope) in names.into_iter().zip(env) {
            rows.push(SharingRow {
                source,
                scenario,
                pipeline: name,
                fusion,
                sharing,
                envelope,
            });
        }
    }
    Ok(rows)
}
