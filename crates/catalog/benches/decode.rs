//! Decoding speed of the sensor messages a pipeline reads, per encoding: a ROS 2 bag's CDR
//! (`NavSatFix`, `Imu`, read through the translators into catalogue messages) against
//! railfuse's own JSON of the same content. Messages per second on one core.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use railfuse_catalog::foreign::ros2::{
    self, Header, ImuMsg, NavSatFix, NavSatStatus, Quaternion, Time, Vector3,
};
use railfuse_catalog::foreign::Translator;
use railfuse_catalog::messages::MessageKind;

const N: usize = 1000;

fn header(k: usize) -> Header {
    Header {
        stamp: Time {
            sec: 1_780_300_800 + k as i32,
            nanosec: 5_000_000,
        },
        frame_id: "gnss".into(),
    }
}

fn payloads() -> [(&'static str, MessageKind, Vec<Vec<u8>>, Vec<Vec<u8>>); 2] {
    let fixes = (0..N).map(|k| NavSatFix {
        header: header(k),
        status: NavSatStatus {
            status: 2,
            service: 1,
        },
        latitude: 44.6 + k as f64 * 1e-6,
        longitude: 10.9,
        altitude: 79.3,
        position_covariance: [4e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 1e-3],
        position_covariance_type: 3,
    });
    let imus = (0..N).map(|k| ImuMsg {
        header: header(k),
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        },
        orientation_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        angular_velocity: Vector3 {
            x: 0.001,
            y: 0.002,
            z: 0.003 * k as f64,
        },
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: Vector3 {
            x: 0.1,
            y: 0.02,
            z: 9.81,
        },
        linear_acceleration_covariance: [0.0; 9],
    });
    let fix_cdr: Vec<Vec<u8>> = fixes.map(|m| ros2::to_cdr(&m)).collect();
    let imu_cdr: Vec<Vec<u8>> = imus.map(|m| ros2::to_cdr(&m)).collect();
    // The same messages as railfuse writes them.
    let json = |schema: &str, cdr: &[Vec<u8>]| -> Vec<Vec<u8>> {
        let t = Translator::for_schema("cdr", schema, b"", None)
            .unwrap()
            .unwrap();
        cdr.iter()
            .map(|p| match t.translate(p, 0).unwrap() {
                railfuse_catalog::foreign::Translated::Message { message, .. } => message.to_json(),
                other => panic!("{other:?}"),
            })
            .collect()
    };
    [
        (
            ros2::NAV_SAT_FIX,
            MessageKind::GnssFix,
            json(ros2::NAV_SAT_FIX, &fix_cdr),
            fix_cdr,
        ),
        (
            ros2::IMU,
            MessageKind::Imu,
            json(ros2::IMU, &imu_cdr),
            imu_cdr,
        ),
    ]
}

fn decode(c: &mut Criterion) {
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(N as u64));
    for (schema, kind, json, cdr) in payloads() {
        let t = Translator::for_schema("cdr", schema, b"", None)
            .unwrap()
            .unwrap();
        g.bench_function(format!("{schema} cdr"), |b| {
            b.iter(|| {
                cdr.iter()
                    .map(|p| t.translate(p, 0).is_ok() as usize)
                    .sum::<usize>()
            })
        });
        g.bench_function(format!("{} json", kind.schema_name()), |b| {
            b.iter(|| {
                json.iter()
                    .map(|p| kind.decode(p).is_ok() as usize)
                    .sum::<usize>()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
