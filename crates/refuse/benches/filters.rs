//! Filter throughput, without file I/O: measurements are decoded from a simulated log once,
//! then replayed through the pipelines (the `railfuse bench` subcommand measures the whole
//! file-to-file path).
//!
//! - `kalman_replay`: the default Kalman pipeline over a 10-minute line run (every loop,
//!   radar, odometer and balise message): messages per second on one core;
//! - `side_by_side`: N copies of that pipeline fed the same stream (the cost of N pipelines
//!   against one);
//! - `federated_kalman_replay`: source 001's federated filter over its 500 s run;
//! - `particle_update`: one predict + update of a particle filter: particle updates per
//!   second.

use std::path::Path;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::{Matrix3, RowVector3, Vector3};
use railfuse_catalog::log::{LogReader, LogRecord};
use railfuse_catalog::messages::{ChannelMessage, TrackMap};
use railfuse_refuse::config::PipelinesConfig;
use railfuse_refuse::filter::particle::{ParticleSettings, Resampling};
use railfuse_refuse::filter::{LocalFilter, ParticleFilter, StateAndCovariance};
use railfuse_refuse::measurement::{Measurement, SensorContext, SensorModel};
use railfuse_refuse::model::{ConstantAcceleration, ProcessNoise};
use railfuse_refuse::pipeline::{AnyPipeline, Fused};

/// One message's measurements, as the replay hands them to a pipeline.
struct Replayed {
    topic: usize,
    log_time_ns: u64,
    measurements: Vec<Measurement>,
}

/// Simulates `scenario` and decodes every message a pipeline of `config` reads.
fn stream(
    scenario: &str,
    duration: Option<f64>,
    config: &PipelinesConfig,
) -> (Vec<Replayed>, Vec<String>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let preset = railfuse_record::Scenario::preset(scenario).unwrap();
    railfuse_record::simulate(&preset, 1, duration, &[], &path).unwrap();
    let topics: Vec<String> = config.pipeline[0]
        .sensor
        .iter()
        .map(|s| s.topic.clone())
        .collect();
    let mut ctx = SensorContext::default();
    let mut out = Vec::new();
    let mut reader = LogReader::open(&path).unwrap();
    while let Some(r) = reader.next() {
        let LogRecord::Message(m) = r.unwrap() else {
            continue;
        };
        if m.channel.schema_name() == TrackMap::SCHEMA_NAME {
            ctx.track = Some(m.decode(Path::new("bench")).unwrap());
            continue;
        }
        let Some(topic) = topics.iter().position(|t| *t == m.channel.topic) else {
            continue;
        };
        let model = SensorModel::for_schema(m.channel.schema_name()).unwrap();
        let mut measurements = Vec::new();
        model
            .decode(&m, Path::new("bench"), &ctx, &mut measurements)
            .unwrap();
        out.push(Replayed {
            topic,
            log_time_ns: m.log_time_ns,
            measurements,
        });
    }
    (out, topics)
}

fn replay(pipelines: &mut [AnyPipeline], stream: &[Replayed], out: &mut Vec<Fused>) -> usize {
    let mut states = 0;
    for r in stream {
        for p in pipelines.iter_mut() {
            p.push(r.topic, &r.measurements, r.log_time_ns, out);
            states += out.len();
            out.clear();
        }
    }
    states
}

fn config(text: &str, copies: usize) -> PipelinesConfig {
    let mut c = PipelinesConfig::parse(text, Path::new("bench.toml")).unwrap();
    let first = c.pipeline[0].clone();
    c.pipeline = (0..copies)
        .map(|i| railfuse_refuse::config::PipelineConfig {
            name: format!("p{i}"),
            ..first.clone()
        })
        .collect();
    c
}

fn kalman(c: &mut Criterion) {
    let kalman_toml = include_str!("../../../samples/kalman.toml");
    let (stream, _) = stream("default", Some(600.0), &config(kalman_toml, 1));
    let mut out = Vec::new();
    let mut g = c.benchmark_group("kalman_replay");
    g.throughput(Throughput::Elements(stream.len() as u64));
    g.bench_function("default_run_600s", |b| {
        b.iter(|| {
            let mut p: Vec<AnyPipeline> = config(kalman_toml, 1)
                .pipeline
                .into_iter()
                .map(|c| AnyPipeline::new(c).unwrap())
                .collect();
            replay(&mut p, &stream, &mut out)
        })
    });
    g.finish();

    let mut g = c.benchmark_group("side_by_side");
    g.throughput(Throughput::Elements(stream.len() as u64));
    for n in [1usize, 2, 4, 8] {
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, &n| {
            b.iter(|| {
                let mut p: Vec<AnyPipeline> = config(kalman_toml, n)
                    .pipeline
                    .into_iter()
                    .map(|c| AnyPipeline::new(c).unwrap())
                    .collect();
                replay(&mut p, &stream, &mut out)
            })
        });
    }
    g.finish();
}

/// Pipeline `name` of a config file, alone.
fn named(text: &str, name: &str) -> PipelinesConfig {
    let mut c = PipelinesConfig::parse(text, Path::new("bench.toml")).unwrap();
    c.pipeline.retain(|p| p.name == name);
    c
}

/// Source 001's federated filter (3 states), and federated and centralised filters with three
/// sensor states (6 states, one of them an EKF row).
fn federated(c: &mut Criterion) {
    let toml = include_str!("../../../samples/seed001.toml");
    let (stream, _) = stream("seed001", None, &config(toml, 1));
    let mut out = Vec::new();
    let mut g = c.benchmark_group("seed001_replay");
    g.sample_size(10);
    g.throughput(Throughput::Elements(stream.len() as u64));
    for name in ["fkf", "fkf_cal", "kf_cal"] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut p: Vec<AnyPipeline> = named(toml, name)
                    .pipeline
                    .into_iter()
                    .map(|c| AnyPipeline::new(c).unwrap())
                    .collect();
                replay(&mut p, &stream, &mut out)
            })
        });
    }
    g.finish();
}

fn particle(c: &mut Criterion) {
    let model = ConstantAcceleration {
        noise: ProcessNoise::WhiteJerkPsd(0.05),
    };
    let init = StateAndCovariance {
        state: Vector3::new(0.0, 20.0, 0.0),
        covariance: Matrix3::from_diagonal(&Vector3::new(1.0, 0.25, 0.1)),
    };
    let mut g = c.benchmark_group("particle_update");
    for n in [1_000usize, 10_000] {
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, &n| {
            let settings = ParticleSettings {
                particles: n,
                resampling: Resampling::Systematic,
                ess_threshold: 0.5,
                roughening: 0.1,
                seed: 1,
            };
            let mut pf = ParticleFilter::new(settings, &init);
            let mut k = 0u64;
            b.iter(|| {
                k += 1;
                pf.predict(&model, 0.05, 1.0);
                let h = if k.is_multiple_of(2) {
                    RowVector3::new(1.0, 0.0, 0.0)
                } else {
                    RowVector3::new(0.0, 1.0, 0.0)
                };
                let z = if k.is_multiple_of(2) {
                    20.0 * 0.05 * k as f64
                } else {
                    20.0
                };
                pf.update(&h, 0.04, z)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, kalman, federated, particle);
criterion_main!(benches);
