//! Converting other tools' files into a run: one hour of a 10 Hz GPX track (36 000 points, as
//! a Garmin or phone app writes them: time, elevation, hdop, satellites, speed and course in
//! extensions), and one hour of a 10 Hz GNSS logger's CSV (date and time in six columns,
//! whole seconds spread at the receiver's rate, 1e-7°, mm, mm/s) into MCAP `/gnss/fix`. The
//! goal: each under a second. And a ROS 1 bag, `samples/short-run.bag` (90 s, 25 207
//! messages in bz2 chunks), into MCAP `ros1msg` channels.

use std::io::Write;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use railfuse_catalog::formats::csv_table::mapping::MappingFile;
use railfuse_catalog::formats::{self, FormatOptions, Storage};

const POINTS: usize = 36_000;

fn hour_of_gpx(path: &std::path::Path) {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(
        f,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.1" creator="bench" xmlns="http://www.topografix.com/GPX/1/1" xmlns:gpxtpx="http://www.garmin.com/xmlschemas/TrackPointExtension/v2">
<trk><name>an hour at 10 Hz</name><trkseg>"#
    )
    .unwrap();
    for k in 0..POINTS {
        let (s, tenth) = (k / 10, k % 10);
        writeln!(
            f,
            "<trkpt lat=\"{:.7}\" lon=\"{:.7}\"><ele>{:.1}</ele><time>2021-07-26T{:02}:{:02}:{:02}.{tenth}00Z</time>\
             <sat>9</sat><hdop>0.9</hdop><extensions><gpxtpx:TrackPointExtension><gpxtpx:speed>{:.2}</gpxtpx:speed>\
             <gpxtpx:course>{:.1}</gpxtpx:course></gpxtpx:TrackPointExtension></extensions></trkpt>",
            55.6 + k as f64 * 2e-6,
            12.5 + k as f64 * 1e-6,
            20.0 + (k % 100) as f64 * 0.1,
            4 + s / 3600,
            (s / 60) % 60,
            s % 60,
            20.0 + (k % 50) as f64 * 0.1,
            (k % 360) as f64,
        )
        .unwrap();
    }
    writeln!(f, "</trkseg></trk></gpx>").unwrap();
}

/// The GNSS logger's table of `samples/loggers/gnss-logger.csv`, at 10 Hz for an hour, and its
/// mapping at that rate.
fn hour_of_csv(path: &std::path::Path, mapping: &std::path::Path) {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(
        f,
        "Year,Month,Day,Hour,Minute,Second,nSAT,Lon,Lat,Alt1,Alt2,hAcc,vAcc,speed,speedAcc,PDOP"
    )
    .unwrap();
    for k in 0..POINTS {
        let s = k / 10;
        writeln!(
            f,
            "2021,7,26,{},{},{},17,{},{},{},{},20,40,{},120,196",
            4 + s / 3600,
            (s / 60) % 60,
            s % 60,
            125_000_000 + k * 10,
            556_000_000 + k * 20,
            20_000 + k % 100,
            -27_000 + (k % 100) as i64,
            20_000 + k % 500,
        )
        .unwrap();
    }
    let sample = include_str!("../../../samples/loggers/gnss-logger.toml");
    std::fs::write(mapping, sample.replace("rate_hz = 5", "rate_hz = 10")).unwrap();
}

fn convert(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let gpx = dir.path().join("hour.gpx");
    hour_of_gpx(&gpx);
    let out = dir.path().join("hour.mcap");
    let mut group = c.benchmark_group("convert");
    group.sample_size(10);
    group.throughput(Throughput::Elements(POINTS as u64));
    group.bench_function("gpx_hour_10hz", |b| {
        b.iter(|| {
            let r = formats::convert(
                Storage::Gpx,
                &gpx,
                &out,
                &FormatOptions::default(),
                &Default::default(),
            )
            .unwrap();
            assert_eq!(r.messages, POINTS as u64);
        })
    });
    let (csv, mapping) = (dir.path().join("hour.csv"), dir.path().join("logger.toml"));
    hour_of_csv(&csv, &mapping);
    let options = FormatOptions {
        csv: Some(std::sync::Arc::new(MappingFile::read(&mapping).unwrap())),
        ..Default::default()
    };
    group.bench_function("csv_logger_hour_10hz", |b| {
        b.iter(|| {
            let r =
                formats::convert(Storage::Csv, &csv, &out, &options, &Default::default()).unwrap();
            assert_eq!(r.messages, POINTS as u64);
        })
    });
    let bag = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../samples/short-run.bag");
    group.throughput(Throughput::Elements(25_207));
    group.bench_function("ros1_bag_bz2_25k_messages", |b| {
        b.iter(|| {
            let r = formats::convert(Storage::Rosbag1, &bag, &out, &options, &Default::default())
                .unwrap();
            assert_eq!(r.messages, 25_207);
        })
    });
    group.finish();
}

criterion_group!(benches, convert);
criterion_main!(benches);
