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
use railfuse_refuse::filter::particle::{ParticleSettings, Resampling};
use railfuse_refuse::filter::{LocalFilter, ParticleFilter, StateAndCovariance};
use railfuse_refuse::measurement::{Measurement, SensorContext, SensorModel};
use railfuse_refuse::model::{ConstantAcceleration, ProcessNoise};
use railfuse_refuse::pipeline::{AnyPipeline, Fused};
use railfuse_refuse::spec::Pipelines;

/// One message's measurements, as the replay hands them to a pipeline.
struct Replayed {
    /// Index into [`Stream::topics`].
    topic: usize,
    log_time_ns: u64,
    measurements: Vec<Measurement>,
}

/// The measurements of a simulated log, and its sensor channels with their schemas.
struct Stream {
    replayed: Vec<Replayed>,
    topics: Vec<(String, String)>,
}

/// Simulates `scenario` and decodes every message of a channel a pipeline of `spec` reads.
fn stream(scenario: &str, duration: Option<f64>, spec: &Pipelines) -> Stream {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let preset = railfuse_record::Scenario::preset(scenario).unwrap();
    railfuse_record::simulate(&preset, 1, duration, &[], &path).unwrap();
    let mut topics: Vec<(String, String)> = Vec::new();
    let mut ctx = SensorContext::default();
    let mut replayed = Vec::new();
    let mut reader = LogReader::open(&path).unwrap();
    while let Some(r) = reader.next() {
        let LogRecord::Message(m) = r.unwrap() else {
            continue;
        };
        let schema = m.channel.schema_name();
        if schema == TrackMap::SCHEMA_NAME {
            ctx.track = Some(m.decode(Path::new("bench")).unwrap());
            continue;
        }
        let read = spec
            .pipeline
            .iter()
            .any(|p| p.sensor_for(&m.channel.topic).is_some());
        let (true, Some(model)) = (read, SensorModel::for_schema(schema)) else {
            continue;
        };
        let topic = match topics.iter().position(|(t, _)| *t == m.channel.topic) {
            Some(i) => i,
            None => {
                topics.push((m.channel.topic.clone(), schema.to_owned()));
                topics.len() - 1
            }
        };
        let mut measurements = Vec::new();
        model
            .decode(&m, Path::new("bench"), &ctx, &mut measurements)
            .unwrap();
        replayed.push(Replayed {
            topic,
            log_time_ns: m.log_time_ns,
            measurements,
        });
    }
    Stream { replayed, topics }
}

impl Stream {
    /// Messages of the channels the first pipeline of `spec` reads.
    fn read_by(&self, spec: &Pipelines) -> u64 {
        let p = &spec.pipeline[0];
        let read: Vec<bool> = self
            .topics
            .iter()
            .map(|(t, _)| p.sensor_for(t).is_some())
            .collect();
        self.replayed.iter().filter(|r| read[r.topic]).count() as u64
    }
}

/// The pipelines of `spec`, each sensor bound to its channel of `stream`, with the sensor
/// index of each stream topic.
fn pipelines(spec: &Pipelines, stream: &Stream) -> Vec<(AnyPipeline, Vec<Option<usize>>)> {
    spec.pipeline
        .iter()
        .map(|ps| {
            let mut p = AnyPipeline::new(ps.clone()).unwrap();
            let sensors = stream
                .topics
                .iter()
                .map(|(topic, schema)| {
                    let si = ps.sensor_for(topic)?;
                    p.bind(si, &ps.bind(Path::new("bench"), si, schema).unwrap());
                    Some(si)
                })
                .collect();
            (p, sensors)
        })
        .collect()
}

fn replay(spec: &Pipelines, stream: &Stream, out: &mut Vec<Fused>) -> usize {
    let mut pipelines = pipelines(spec, stream);
    let mut states = 0;
    for r in &stream.replayed {
        for (p, sensors) in pipelines.iter_mut() {
            if let Some(si) = sensors[r.topic] {
                p.push(si, &r.measurements, r.log_time_ns, out);
                states += out.len();
                out.clear();
            }
        }
    }
    states
}

/// The first pipeline of a config file, `copies` times under different names.
fn config(text: &str, copies: usize) -> Pipelines {
    let mut c = Pipelines::parse(text, Path::new("bench.toml")).unwrap();
    let first = c.pipeline[0].clone();
    c.pipeline = (0..copies)
        .map(|i| first.renamed(&format!("p{i}")))
        .collect();
    c
}

fn kalman(c: &mut Criterion) {
    let kalman_toml = include_str!("../../../samples/kalman.toml");
    let stream = stream("default", Some(600.0), &config(kalman_toml, 1));
    let mut out = Vec::new();
    let mut g = c.benchmark_group("kalman_replay");
    let one = config(kalman_toml, 1);
    g.throughput(Throughput::Elements(stream.read_by(&one)));
    g.bench_function("default_run_600s", |b| {
        b.iter(|| replay(&one, &stream, &mut out))
    });
    g.finish();

    let mut g = c.benchmark_group("side_by_side");
    g.throughput(Throughput::Elements(stream.read_by(&one)));
    for n in [1usize, 2, 4, 8] {
        let copies = config(kalman_toml, n);
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| replay(&copies, &stream, &mut out))
        });
    }
    g.finish();
}

/// Pipeline `name` of a config file, alone.
fn named(text: &str, name: &str) -> Pipelines {
    let mut c = Pipelines::parse(text, Path::new("bench.toml")).unwrap();
    c.pipeline.retain(|p| p.name == name);
    c
}

/// Source 001's federated filter (3 states), and federated and centralised filters with three
/// sensor states (6 states, one of them an EKF row).
fn federated(c: &mut Criterion) {
    let toml = include_str!("../../../samples/seed001.toml");
    let stream = stream(
        "seed001",
        None,
        &Pipelines::parse(toml, Path::new("bench.toml")).unwrap(),
    );
    let mut out = Vec::new();
    let mut g = c.benchmark_group("seed001_replay");
    g.sample_size(10);
    for name in ["fkf", "fkf_cal", "kf_cal"] {
        let spec = named(toml, name);
        g.throughput(Throughput::Elements(stream.read_by(&spec)));
        g.bench_function(name, |b| b.iter(|| replay(&spec, &stream, &mut out)));
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
                reseed_nis: 25.0,
                reseed_ess: 0.01,
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
