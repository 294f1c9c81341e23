//! A sample message of every kind, as a sensor gateway would send it in a JSON line: for
//! documentation, and for the tests that take every kind through encoding, decoding and its
//! JSON schema. The match is exhaustive, so a new kind cannot be added without its sample.

use serde_json::{json, Value};

use super::{AnyMessage, MessageKind};

/// 2026-06-01 08:00:00 UTC.
const T: u64 = 1_780_300_800_000_000_000;

impl MessageKind {
    /// The sample message's fields as JSON.
    pub fn example_json(self) -> Value {
        self.sensor_example()
            .or_else(|| self.other_example())
            .expect("every kind has an example")
    }

    /// A raw sensor message's example.
    fn sensor_example(self) -> Option<Value> {
        Some(match self {
            MessageKind::GnssFix => json!({
                "stamp_ns": T, "fix_type": "rtk_fixed", "satellites": 21, "hdop": 0.6,
                "latitude_deg": 44.6551106, "longitude_deg": 10.9297304, "altitude_m": 79.3, "altitude_msl_m": 35.2,
                "position_covariance_enu_m2": [4e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 1e-3],
                "speed_mps": 22.5, "course_rad": 1.2
            }),
            MessageKind::Imu => json!({
                "stamp_ns": T, "sensor_id": "imu0",
                "specific_force_mps2": [0.31, -0.02, 9.81], "angular_rate_radps": [0.0, 0.001, 0.02],
                "accel_lsb_mps2": 0.01, "gyro_lsb_radps": 0.001
            }),
            MessageKind::RadarSpeed => json!({
                "stamp_ns": T, "speed_mps": 22.4, "quality": 0.93, "valid": true,
                "speed_variance_m2ps2": 0.01
            }),
            MessageKind::Odometer => json!({
                "stamp_ns": T, "sensor_id": "axle1", "pulse_count": 120_455,
                "pulses_per_revolution": 200, "wheel_diameter_m": 0.92,
                "distance_increment_m": 0.9, "speed_mps": 22.6
            }),
            MessageKind::LoopPosition => json!({
                "stamp_ns": T, "chainage_m": 1250.0, "crossing": 50, "variance_m2": 0.01
            }),
            MessageKind::BalisePassage => json!({
                "stamp_ns": T, "balise_id": "B-0012", "chainage_m": 12_004.2, "variance_m2": 0.04
            }),
            MessageKind::TimeReference => json!({
                "stamp_ns": T, "local_ns": T + 350_000_123, "source": "pps"
            }),
            MessageKind::CanFrame => json!({
                "stamp_ns": T, "receive_ns": T + 120_000, "bus": "can0", "id": 256,
                "extended": false, "remote": false, "error": false, "fd": false, "brs": false,
                "esi": false, "data": "D2049604010000F0"
            }),
            MessageKind::CanSignals => json!({
                "stamp_ns": T, "bus": "can0", "id": 256, "message": "WheelSpeed",
                "signals": [
                    {"name": "AxleSpeed1", "value": 12.02, "unit": "m/s"},
                    {"name": "Direction", "value": 1.0, "label": "forward"},
                    {"name": "Counter", "value": 15.0, "out_of_range": true}
                ]
            }),
            MessageKind::EddyCurrentBlock => json!({
                "stamp_ns": T, "sample_rate_hz": 10_000.0, "spacing_m": 0.3,
                "sensor_a": [0.1, 0.4, -0.2], "sensor_b": [0.0, 0.1, 0.4],
                "volts_per_count": 0.0005
            }),
            _ => return None,
        })
    }

    /// The example of a map, truth, event, fused or recorder message.
    fn other_example(self) -> Option<Value> {
        Some(match self {
            MessageKind::TrackMap => json!({
                "stamp_ns": T, "name": "test line",
                "origin": {"latitude_deg": 44.6, "longitude_deg": 10.9, "altitude_m": 40.0},
                "vertices": [
                    {"chainage_m": 0.0, "east_m": 0.0, "north_m": 0.0},
                    {"chainage_m": 100.0, "east_m": 100.0, "north_m": 0.0}
                ],
                "balises": [{"balise_id": "B-1", "chainage_m": 50.0}],
                "tunnels": [{"name": "T1", "start_chainage_m": 60.0, "end_chainage_m": 80.0}],
                "stations": [{"name": "A", "chainage_m": 0.0}],
                "sleeper_spacing_m": 0.6, "loop_crossing_spacing_m": 25.0
            }),
            MessageKind::Vehicle => vehicle_example(),
            MessageKind::TrainPosition => train_position_example(),
            MessageKind::GroundTruth => json!({
                "stamp_ns": T, "chainage_m": 1250.2, "speed_mps": 22.5, "acceleration_mps2": 0.1,
                "east_m": 1200.0, "north_m": 310.0, "latitude_deg": 44.61,
                "longitude_deg": 10.92, "heading_rad": 0.3
            }),
            MessageKind::TuneEvaluation => json!({
                "stamp_ns": T, "evaluation": 3, "objective": 0.31, "best": 0.29,
                "values": [{"name": "motion.jerk_psd", "value": 0.05}]
            }),
            MessageKind::Event => json!({
                "stamp_ns": T, "kind": "tunnel_entry", "text": "T1"
            }),
            MessageKind::FusedState => json!({
                "stamp_ns": T, "chainage_m": 1250.1, "speed_mps": 22.5, "acceleration_mps2": 0.1,
                "covariance": [0.04, 0.001, 0.0, 0.001, 0.01, 0.0, 0.0, 0.0, 0.02],
                "source": "/loop/position",
                "sensor_states": [
                    {"topic": "/radar/speed", "kind": "scale_factor", "value": 0.003, "std": 2e-4}
                ]
            }),
            MessageKind::FusedDiagnostics => json!({
                "stamp_ns": T, "source": "/radar/speed", "measurement": 22.4,
                "measurement_variance": 0.1, "innovation": -0.1, "innovation_variance": 0.11,
                "nis": 0.09, "decision": "accepted", "device": "radar", "axis": "east",
                "reason": "fix type none, below single",
                "effective_sample_size": 812.5, "resampled": true,
                "sharing": [{"device": "radar", "beta": 0.5, "fault": "silent for 1.2 s"}]
            }),
            MessageKind::SafetyStatus => json!({
                "stamp_ns": T, "usable": false,
                "checks": [
                    {"check": "s1_gnss", "passed": true},
                    {"check": "s4_map", "passed": false, "value": 3.1, "limit": 2.4,
                     "reason": "fix 3.10 m beside the track, limit 2.40 m"}
                ],
                "first_failure": "s4_map", "reason": "fix 3.10 m beside the track, limit 2.40 m",
                "safe_interval": {"chainage_m": 1250.0, "chainage_std_m": 0.4, "low_m": 1247.9,
                                  "high_m": 1252.1}
            }),
            MessageKind::ImuErrorModel => json!({
                "stamp_ns": T, "accel_bias_mps2": 0.0021, "gyro_bias_radps": 1.1e-4,
                "standstill_samples": 9600, "standstill_s": 6.0,
                "speed_residual_mps2": 0.012, "speed_residual_std_mps2": 0.08,
                "heading_residual_radps": -2e-5, "heading_residual_std_radps": 4e-4,
                "learnt_s": 240.0, "applied": false
            }),
            MessageKind::RecorderDiagnostics => json!({
                "stamp_ns": T, "bytes_written": 1_048_576,
                "sources": [{
                    "name": "udp:5600", "received": 100, "written": 99, "malformed": 1,
                    "checksum_failures": 0, "oversized": 0, "dropped": 0, "kernel_dropped": 2,
                    "reconnects": 0, "connected": true, "last_error": "not a JSON object",
                    "skipped": {"JSON line that does not decode": 1},
                    "first_problems": ["line 7: not a JSON object: expected value at line 1 column 1"]
                }]
            }),
            _ => return None,
        })
    }

    /// The sample message.
    pub fn example(self) -> AnyMessage {
        self.from_value(self.example_json())
            .expect("every sample fits its type")
    }
}

/// The example of a train: its length and two sensors' places.
fn train_position_example() -> Value {
    let end = |east: f64, north: f64| {
        json!({"east_m": east, "north_m": north, "up_m": 12.3, "latitude_deg": 44.61,
               "longitude_deg": 10.92, "altitude_m": 47.3})
    };
    json!({
        "stamp_ns": T, "length_m": 104.0, "confidence": 0.9999,
        "front_chainage_m": 1250.2, "front_std_m": 0.3,
        "min_safe_front_m": 1249.03, "max_safe_front_m": 1251.37,
        "rear_chainage_m": 1146.2, "min_safe_rear_m": 1145.03, "max_safe_rear_m": 1147.37,
        "speed_mps": 22.5, "speed_std_mps": 0.05,
        "front": end(1200.0, 310.0), "rear": end(1110.0, 262.0)
    })
}

fn vehicle_example() -> Value {
    json!({
        "stamp_ns": T, "name": "test train", "length_m": 75.0,
        "roll_per_lateral_mps2": 0.015,
        "installation_std_m": 0.03,
        "sensors": [
            {"topic": "/gnss/fix", "frame_id": "gnss", "lever_arm_m": [-12.0, 0.0, 4.1],
             "mounting_deg": [0.0, 0.0, 0.0]},
            {"topic": "/imu", "lever_arm_m": [-10.5, 0.3, 1.1],
             "mounting_deg": [0.8, -1.2, 1.5]}
        ]
    })
}
