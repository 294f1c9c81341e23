//! Sources 000 and 001: their scenarios, fault cases, pipelines (`samples/seed000.toml`,
//! `samples/seed001.toml`) and claims, and the rows of their results tables.

use std::path::{Path, PathBuf};

use railfuse_record::simulator::FaultSpec;
use railfuse_record::Scenario;
use railfuse_refuse::config::embedded_path;
use railfuse_refuse::spec::Pipelines;
use serde::Serialize;

use crate::long_runs::{long_runs, LongRunRow, LONG_RUN_S};
use crate::sharing::SharingRow;
use crate::{envelopes, run, run_scenario, Envelope, Result};

/// Source 000's experiment: `samples/seed000.toml`.
pub const SEED000_PIPELINES: &str = include_str!("../../../samples/seed000.toml");

/// Source 001's experiment: `samples/seed001.toml`.
pub const SEED001_PIPELINES: &str = include_str!("../../../samples/seed001.toml");

/// One case of source 001's experiment: faults, and the sensor noise relative to the preset.
#[derive(Debug, Clone, Copy)]
pub struct Case {
    pub label: &'static str,
    pub faults: &'static [&'static str],
    /// Every sensor's noise σ times this, in the simulator and in the filters' variances.
    pub noise: f64,
}

const fn case(label: &'static str, faults: &'static [&'static str]) -> Case {
    Case {
        label,
        faults,
        noise: 1.0,
    }
}

/// Source 001's cases. The profile: accelerating 5–160 s (across 50 km/h at about 19 s and
/// 150 km/h at about 47 s, where β changes), cruising at 432 km/h 160–365 s, braking 365–500 s
/// (across 150 km/h at about 450 s and 50 km/h at about 480 s).
pub const SOURCE_001_CASES: &[Case] = &[
    case("no fault", &[]),
    Case {
        label: "no fault, noise ×0.5",
        faults: &[],
        noise: 0.5,
    },
    Case {
        label: "no fault, noise ×2",
        faults: &[],
        noise: 2.0,
    },
    case("radar dead 200–300 s (cruise)", &["radar:dropout:200:300"]),
    case("INS dead 200–300 s (cruise)", &["imu:dropout:200:300"]),
    case("GNSS dead 200–300 s (cruise)", &["gnss:dropout:200:300"]),
    case(
        "radar dead 30–80 s (accelerating, across 150 km/h)",
        &["radar:dropout:30:80"],
    ),
    case(
        "INS dead 30–80 s (accelerating, across 150 km/h)",
        &["imu:dropout:30:80"],
    ),
    case(
        "GNSS dead 30–80 s (accelerating, across 150 km/h)",
        &["gnss:dropout:30:80"],
    ),
    case(
        "radar dead 420–490 s (braking, across 150 and 50 km/h)",
        &["radar:dropout:420:490"],
    ),
    case(
        "INS dead 420–490 s (braking, across 150 and 50 km/h)",
        &["imu:dropout:420:490"],
    ),
    case(
        "GNSS dead 420–490 s (braking, across 150 and 50 km/h)",
        &["gnss:dropout:420:490"],
    ),
    case("radar stuck 200–300 s", &["radar:stuck:200:300"]),
    case("INS stuck 200–300 s", &["imu:stuck:200:300"]),
    case("GNSS stuck 200–300 s", &["gnss:stuck:200:300"]),
    case("INS biased +0.5 m/s² 200–300 s", &["imu:bias=0.5:200:300"]),
    case("GNSS biased +20 m 200–300 s", &["gnss:bias=20:200:300"]),
];

/// Simulated GNSS receivers whose bias differs from what `fkf_cal`/`kf_cal` assume (σ 2 m,
/// τ 60 s, the preset's own): (label, bias time constant s, bias σ over the preset's).
pub const SOURCE_001_MISMATCHES: &[(&str, f64, f64)] = &[
    ("as modelled: τ 60 s, σ 2 m", 60.0, 1.0),
    ("τ 20 s", 20.0, 1.0),
    ("τ 300 s", 300.0, 1.0),
    ("σ 1 m (×0.5)", 60.0, 0.5),
    ("σ 4 m (×2)", 60.0, 2.0),
];

/// The pipelines scored in the mismatch table: the sensor-state filters and, for scale, the
/// source's.
pub const SOURCE_001_MISMATCH_PIPELINES: &[&str] = &["fkf_cal", "kf_cal", "fkf"];

/// The pipelines scored in source 001's table (`kf/smoothed`: the RTS-smoothed states).
pub const SOURCE_001_PIPELINES: &[&str] = &["fkf", "fkf_cal", "kf", "kf_cal", "kf/smoothed"];

/// Source 001's targets: output rate, position error, speed error.
pub const SOURCE_001_MIN_RATE_HZ: f64 = 50.0;
pub const SOURCE_001_MAX_POSITION_M: f64 = 10.0;
pub const SOURCE_001_MAX_SPEED_MPS: f64 = 1.0 / 3.6;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Beats,
    /// Inside the source's bound (a bound says nothing of how far inside the source was).
    Matches,
    FallsShort,
    /// The figures are of different experiments.
    NotComparable {
        because: &'static str,
    },
}

/// Why source 000's figures and the `seed000` preset's cannot be set side by side.
pub const SOURCE_000_NOT_COMPARABLE: &str = "the loop's error in the stated parameters is white \
     noise of 0.01 m², while the source's grows with distance (its ±10 m without balises comes \
     from that growth); `seed000_loop_drift` is the comparable run";

impl Verdict {
    /// Against a target (a requirement): inside it matches, outside falls short; nothing
    /// beats a target.
    pub fn within_target(ok: bool) -> Self {
        match ok {
            true => Verdict::Matches,
            false => Verdict::FallsShort,
        }
    }
}

/// Source 000's two runs: its parameters as stated, and with the loop's error growing.
pub const SOURCE_000_SCENARIOS: &[&str] = &["seed000", "seed000_loop_drift"];

/// Source 000's reported figures: both observed envelopes of one run.
pub const SOURCE_000_NO_BALISE: &str =
    "observed envelope: position ±10 m, growing; speed −0.3…+0.4 m/s";
pub const SOURCE_000_BALISE: &str = "observed bound: position within 1 m after each balise";

#[derive(Debug, Clone, Serialize)]
pub struct Source000Row {
    pub scenario: &'static str,
    pub pipeline: String,
    /// What the source reports for this configuration, and what kind of figure it is.
    pub claim: &'static str,
    pub envelope: Envelope,
    pub verdict: Verdict,
}

impl Source000Row {
    /// Whether the pipeline reads balises (by the sample's naming: `*_balise`, not `*_no_balise`).
    pub fn balise(&self) -> bool {
        uses_balises(&self.pipeline)
    }
}

fn uses_balises(pipeline: &str) -> bool {
    pipeline.contains("balise") && !pipeline.contains("no_balise")
}

/// The verdict on one source 000 row. On the stated parameters, not comparable. On the drifting
/// loop: without balises the source's figure is an envelope ("±10 m"), so railfuse's envelope
/// inside it half as wide or less beats it, inside it matches; with balises it is a bound
/// ("within 1 m"), which railfuse's largest error after the first balise matches or not.
fn verdict_000(scenario: &str, pipeline: &str, e: &Envelope) -> Verdict {
    if scenario == "seed000" {
        return Verdict::NotComparable {
            because: SOURCE_000_NOT_COMPARABLE,
        };
    }
    if uses_balises(pipeline) {
        match e.after_first_balise_abs_m {
            Some(a) if a < 1.0 => Verdict::Matches,
            _ => Verdict::FallsShort,
        }
    } else {
        let speed_ok = e.speed_min_mps > -0.3 && e.speed_max_mps < 0.4;
        match (e.position_abs_m(), speed_ok) {
            (p, true) if p <= 5.0 => Verdict::Beats,
            (p, true) if p <= 10.0 => Verdict::Matches,
            _ => Verdict::FallsShort,
        }
    }
}

/// One pipeline on a receiver whose bias is not what the pipeline models.
#[derive(Debug, Clone, Serialize)]
pub struct MismatchRow {
    pub receiver: &'static str,
    pub pipeline: String,
    pub envelope: Envelope,
    pub verdict: Verdict,
}

/// Source 001's targets met or not: output rate (not for smoothed states, which are offline),
/// position and speed error.
fn verdict_001(pipeline: &str, e: &Envelope) -> Verdict {
    let rate_ok = pipeline.ends_with("smoothed") || e.min_rate_hz >= SOURCE_001_MIN_RATE_HZ - 0.1;
    Verdict::within_target(
        rate_ok
            && e.position_abs_m() < SOURCE_001_MAX_POSITION_M
            && e.speed_abs_mps() < SOURCE_001_MAX_SPEED_MPS,
    )
}

#[derive(Debug, Clone, Serialize)]
pub struct Source001Row {
    pub case: &'static str,
    pub pipeline: String,
    pub envelope: Envelope,
    pub verdict: Verdict,
}

/// Both tables, over seeds `0 … seeds − 1`.
#[derive(Debug, Clone, Serialize)]
pub struct Results {
    pub seeds: u64,
    pub source_000: Vec<Source000Row>,
    pub source_001: Vec<Source001Row>,
    /// Source 001 without faults, on receivers whose bias the sensor-state models get wrong.
    pub source_001_mismatch: Vec<MismatchRow>,
    /// The default pipelines over one-hour default runs.
    pub long_runs: Vec<LongRunRow>,
    /// What α and β change.
    pub sharing: Vec<SharingRow>,
}

/// Runs in all for `seeds` seeds: source 000's, every source 001 case's, the mismatched
/// receivers', the long runs, the sharing variants.
pub fn runs(seeds: u64) -> u64 {
    let long_runs = 1;
    let experiments = SOURCE_000_SCENARIOS.len()
        + SOURCE_001_CASES.len()
        + SOURCE_001_MISMATCHES.len()
        + long_runs
        + crate::sharing::EXPERIMENTS.len();
    seeds * experiments as u64
}

/// Runs both experiments over `seeds` seeds in `dir`; `progress` is told the runs done.
pub fn run_all(dir: &Path, seeds: u64, progress: &dyn Fn(u64)) -> Result<Results> {
    let seeds = seeds.max(1);
    let c000 = Pipelines::parse(SEED000_PIPELINES, &embedded("seed000"))?;
    let c001 = Pipelines::parse(SEED001_PIPELINES, &embedded("seed001"))?;
    let mut done = 0;
    let mut step = || {
        done += 1;
        progress(done);
    };

    let source_000 = source_000_rows(dir, seeds, &c000, &mut step)?;
    let source_001 = source_001_rows(dir, seeds, &mut step)?;
    let source_001_mismatch = mismatch_rows(dir, seeds, &c001, &mut step)?;
    let long_runs = long_runs(dir, seeds, LONG_RUN_S, &mut step)?;
    let sharing = crate::sharing::run_all(dir, seeds, &c000, &c001, &mut step)?;
    Ok(Results {
        sharing,
        seeds,
        source_000,
        source_001,
        source_001_mismatch,
        long_runs,
    })
}

/// Source 000: every pipeline of samples/seed000.toml on both runs, no faults.
fn source_000_rows(
    dir: &Path,
    seeds: u64,
    c000: &Pipelines,
    step: &mut dyn FnMut(),
) -> Result<Vec<Source000Row>> {
    let names000: Vec<&str> = c000.names().collect();
    let mut source_000 = Vec::new();
    for scenario in SOURCE_000_SCENARIOS {
        let env = envelopes(seeds, &names000, step, |seed| {
            run(dir, scenario, seed, &[], c000, "clean")
        })?;
        for (name, e) in names000.iter().zip(env) {
            source_000.push(Source000Row {
                scenario,
                pipeline: (*name).to_owned(),
                claim: match uses_balises(name) {
                    true => SOURCE_000_BALISE,
                    false => SOURCE_000_NO_BALISE,
                },
                verdict: verdict_000(scenario, name, &e),
                envelope: e,
            });
        }
    }
    Ok(source_000)
}

/// Source 001: the federated filter (and the centralised one), clean and with faults.
fn source_001_rows(dir: &Path, seeds: u64, step: &mut dyn FnMut()) -> Result<Vec<Source001Row>> {
    let mut source_001 = Vec::new();
    for (ci, case) in SOURCE_001_CASES.iter().enumerate() {
        let faults = case
            .faults
            .iter()
            .map(|f| f.parse())
            .collect::<Result<Vec<FaultSpec>, _>>()
            .expect("the built-in fault cases parse");
        let scenario = seed001_noise(case.noise);
        let pipelines = seed001_pipelines_for_noise(case.noise)?;
        let env = envelopes(seeds, SOURCE_001_PIPELINES, step, |seed| {
            run_scenario(
                dir,
                &scenario,
                seed,
                None,
                &faults,
                &pipelines,
                &format!("case{ci}"),
            )
        })?;
        for (name, e) in SOURCE_001_PIPELINES.iter().zip(env) {
            if e.runs == 0 {
                continue;
            }
            source_001.push(Source001Row {
                case: case.label,
                pipeline: (*name).to_owned(),
                verdict: verdict_001(name, &e),
                envelope: e,
            });
        }
    }
    Ok(source_001)
}

/// Source 001 with the simulated receiver's bias unlike the filters' model of it.
fn mismatch_rows(
    dir: &Path,
    seeds: u64,
    c001: &Pipelines,
    step: &mut dyn FnMut(),
) -> Result<Vec<MismatchRow>> {
    let mut source_001_mismatch = Vec::new();
    for (mi, &(receiver, tau_s, scale)) in SOURCE_001_MISMATCHES.iter().enumerate() {
        let scenario = gnss_bias_variant(tau_s, scale);
        let env = envelopes(seeds, SOURCE_001_MISMATCH_PIPELINES, step, |seed| {
            run_scenario(dir, &scenario, seed, None, &[], c001, &format!("bias{mi}"))
        })?;
        for (name, e) in SOURCE_001_MISMATCH_PIPELINES.iter().zip(env) {
            source_001_mismatch.push(MismatchRow {
                receiver,
                pipeline: (*name).to_owned(),
                verdict: verdict_001(name, &e),
                envelope: e,
            });
        }
    }
    Ok(source_001_mismatch)
}

/// The seed001 preset with every sensor's noise σ times `k` (GNSS position and speed, the
/// accelerometer's white noise, the radar's).
fn seed001_noise(k: f64) -> Scenario {
    let mut scenario = Scenario::preset("seed001").expect("a built-in preset");
    if let Scenario::Seed001(line) = &mut scenario {
        line.gnss.sigma_single_m *= k;
        line.gnss.speed_sigma_mps *= k;
        line.imu.accel_noise_mps2 *= k;
        line.radar.sigma_base_mps *= k;
        line.radar.sigma_per_mps *= k;
    }
    scenario
}

/// `samples/seed001.toml` with its fixed variances (the accelerometer's, the GNSS speed's)
/// times `k²`, as the source tuned its filters to each noise level; the GNSS position and the
/// radar take the variance each message reports, which the simulator scales itself.
fn seed001_pipelines_for_noise(k: f64) -> Result<Pipelines> {
    let mut text = SEED001_PIPELINES.to_owned();
    if k != 1.0 {
        for (fixed, v) in [("variance = 0.0009", 0.0009), ("speed = 0.01 }", 0.01)] {
            assert_eq!(
                text.matches(fixed).count(),
                4,
                "samples/seed001.toml: {fixed}"
            );
            let scaled = fixed.replace(&v.to_string(), &format!("{:e}", v * k * k));
            text = text.replace(fixed, &scaled);
        }
    }
    Ok(Pipelines::parse(&text, &embedded("seed001"))?)
}

/// The seed001 preset with its GNSS bias's time constant and σ changed.
fn gnss_bias_variant(tau_s: f64, scale: f64) -> Scenario {
    let mut scenario = Scenario::preset("seed001").expect("a built-in preset");
    if let Scenario::Seed001(line) = &mut scenario {
        line.gnss.bias_tau_s = tau_s;
        line.gnss.bias_scale = scale;
    }
    scenario
}

fn embedded(name: &str) -> PathBuf {
    embedded_path(&format!("samples/{name}.toml"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_cases_and_pipelines_are_valid() {
        for case in SOURCE_001_CASES {
            seed001_pipelines_for_noise(case.noise).unwrap();
            for f in case.faults {
                f.parse::<FaultSpec>().unwrap();
            }
        }
        let c001 = Pipelines::parse(SEED001_PIPELINES, &embedded("seed001")).unwrap();
        for name in SOURCE_001_PIPELINES {
            let base = name.trim_end_matches("/smoothed");
            assert!(c001.names().any(|n| n == base), "{name}");
        }
        Pipelines::parse(SEED000_PIPELINES, &embedded("seed000")).unwrap();
    }

    /// Source 000's central finding, on the run with the loop's error growing with distance:
    /// without balises the position error spreads to metres, and balises, once the filter
    /// models the loop's drift, keep it within 1 m (better than the drift model alone); with the stated white-noise loop the same
    /// filter stays within centimetres, so the spread is the drift's doing.
    #[test]
    fn on_the_drifting_loop_balises_bound_the_error_the_loop_alone_lets_grow() {
        let dir = tempfile::tempdir().unwrap();
        let c000 = Pipelines::parse(SEED000_PIPELINES, &embedded("seed000")).unwrap();
        let [mut alone, mut drift_alone, mut bounded, mut white] = [Envelope::default(); 4];
        for seed in 0..3 {
            let r = run(dir.path(), "seed000_loop_drift", seed, &[], &c000, "t").unwrap();
            alone.add_named(&r, "kf_no_balise");
            drift_alone.add_named(&r, "kf_drift_no_balise");
            bounded.add_named(&r, "kf_drift_balise");
            let r = run(dir.path(), "seed000", seed, &[], &c000, "t").unwrap();
            white.add_named(&r, "kf_no_balise");
        }
        assert_eq!((alone.runs, bounded.runs, white.runs), (3, 3, 3));
        let after = bounded.after_first_balise_abs_m.unwrap();
        eprintln!(
            "drifting loop, no balise: ±{:.2} m (drift modelled: ±{:.2} m); with balises after \
             the first: {after:.2} m; white-noise loop: ±{:.2} m",
            alone.position_abs_m(),
            drift_alone.position_abs_m(),
            white.position_abs_m()
        );
        assert!(alone.position_abs_m() > 3.0, "{alone:?}");
        assert!(after < 1.0, "{bounded:?}");
        // The drift state alone leans on the radar's dead reckoning; the balises do better.
        assert!(after < drift_alone.position_abs_m(), "{drift_alone:?}");
        assert!(white.position_abs_m() < 0.5, "{white:?}");
    }
}
