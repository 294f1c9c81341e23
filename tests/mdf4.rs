//! ASAM MDF 4 bus logging read as asammdf reads it: the real car drive of
//! `../shared/data/canedge-car/` (a CSS CANedge's five files, 39 minutes, two buses) frame for
//! frame, the same drive re-written by asammdf with deflate and transposed-deflate DZ blocks,
//! a file cut off mid-block (the frames before the cut kept), and blocks that lie about their
//! size (one line, bounded). The run reader takes the files directly, as one run.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::CanFrame;
use railfuse_catalog::run::{Run, RunOptions};

/// The real drive's folder (shared/ beside the checkout, as CI lays it).
fn drive() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/canedge-car/00000164");
    assert!(
        d.is_dir(),
        "{} is missing: the real CANedge drive is shared/data/canedge-car",
        d.display()
    );
    d
}

fn drive_files() -> Vec<PathBuf> {
    let mut f: Vec<PathBuf> = std::fs::read_dir(drive())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    f.sort();
    f
}

/// Every CAN frame of a run: (stamp, bus, id, extended, data in hex).
fn frames(inputs: &[PathBuf]) -> Vec<(u64, String, u32, bool, String)> {
    let run = Run::open(inputs, &RunOptions::default()).unwrap();
    let mut reader = run.reader().unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        if let LogRecord::Message(m) = r.unwrap() {
            if m.channel.topic.ends_with("/frames") {
                let f: CanFrame = m.decode(run.name()).unwrap();
                let f = f.to_frame();
                let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
                out.push((f.stamp_ns, f.bus, f.id, f.extended, hex));
            }
        }
    }
    out
}

/// asammdf's frames of a file, in railfuse's form.
fn theirs(file: &Path, dir: &Path) -> Vec<(u64, String, u32, bool, String)> {
    let out = dir.join("theirs.json");
    python_ok("mdf4_frames.py", &["frames", s(file), s(&out)]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f[0].as_u64().unwrap(),
                f[1].as_str().unwrap().to_owned(),
                f[2].as_u64().unwrap() as u32,
                f[3].as_bool().unwrap(),
                f[4].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

/// The same frames, times within a microsecond (asammdf's are float seconds).
fn same(ours: &[(u64, String, u32, bool, String)], theirs: &[(u64, String, u32, bool, String)]) {
    assert_eq!(ours.len(), theirs.len());
    for (k, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert!(a.0.abs_diff(b.0) <= 1_000, "frame {k}: {a:?} vs {b:?}");
        assert_eq!((&a.1, a.2, a.3, &a.4), (&b.1, b.2, b.3, &b.4), "frame {k}");
    }
}

#[test]
fn the_real_canedge_drive_reads_frame_for_frame_as_asammdf_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let files = drive_files();
    assert_eq!(files.len(), 5);
    let mut all = Vec::new();
    for f in &files {
        let ours = frames(std::slice::from_ref(f));
        same(&ours, &theirs(f, dir.path()));
        all.extend(ours);
    }
    // The five files as one run (their folder), in time order: every frame once.
    let run = frames(&[drive()]);
    assert_eq!(run.len(), all.len());
    assert_eq!(run.len(), 292_097);
    assert!(run.windows(2).all(|w| w[0].0 <= w[1].0));
    // Both buses: the GNSS module's on CAN2, OBD-2 responses (0x7E8) on CAN1.
    assert!(run.iter().any(|f| f.1 == "CAN2" && f.2 == 0x3));
    assert!(run.iter().any(|f| f.1 == "CAN1" && f.2 == 0x7E8));
}

#[test]
fn deflated_and_transposed_files_asammdf_wrote_read_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let src = &drive_files()[4];
    let want = frames(std::slice::from_ref(src));
    for compression in ["1", "2"] {
        let out = dir.path().join(format!("z{compression}.mf4"));
        let py = python("mdf4_frames.py", &["save", s(src), s(&out), compression]);
        assert!(py.status.success(), "{}", stderr(&py));
        let bytes = std::fs::read(&out).unwrap();
        assert!(
            bytes.windows(4).any(|w| w == b"##DZ"),
            "asammdf wrote no DZ block"
        );
        assert_eq!(frames(&[out]), want, "compression {compression}");
    }
}

#[test]
fn a_cut_off_file_keeps_its_frames_and_lying_blocks_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let src = &drive_files()[0];
    let bytes = std::fs::read(src).unwrap();
    let whole = frames(std::slice::from_ref(src));
    let cut = dir.path().join("cut.mf4");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let info = ok(&["info", s(&cut)]);
    let err = stderr(&info);
    assert!(
        err.contains("warning: ") && err.contains("past the file's end"),
        "{err}"
    );
    let part = frames(&[cut]);
    assert!(
        part.len() > 1000 && part.len() < whole.len(),
        "{}",
        part.len()
    );
    // The frames it keeps are the file's own, as far as they go.
    let kept = part.iter().filter(|f| whole.contains(f)).count();
    assert_eq!(kept, part.len());

    // The header block claiming a terabyte: refused before it is read, in one line.
    let mut lying = bytes.clone();
    lying[64 + 8..64 + 16].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let big = dir.path().join("big.mf4");
    std::fs::write(&big, &lying).unwrap();
    let e = fails(&["info", s(&big)]);
    assert!(
        e.contains("big.mf4: byte 64: ##HD claims 1099511627776 bytes"),
        "{e}"
    );
    // Not MDF at all.
    let other = dir.path().join("other.mf4");
    std::fs::write(&other, b"MDF     3.30    ").unwrap();
    assert!(fails(&["info", s(&other)]).contains("other.mf4"));
}

#[test]
fn import_writes_the_drives_frames_and_decodes_them_with_the_dbc() {
    let dir = tempfile::tempdir().unwrap();
    let src = &drive_files()[4];
    let out = dir.path().join("drive.mcap");
    let dbc = drive().join("../canmod-gps.dbc");
    let r = ok_json(&["import", s(src), "--dbc", s(&dbc), "-o", s(&out), "--json"]);
    assert_eq!(r["format"], "mdf4");
    assert_eq!(r["per_topic"]["/can/CAN2/frames"], 4846);
    assert!(
        r["per_topic"]["/can/CAN2/gnss_pos"].as_u64().unwrap() > 30,
        "{r}"
    );
}

/// Every message of `topic` in a log, as JSON.
fn messages(path: &Path, topic: &str) -> Vec<serde_json::Value> {
    let run = Run::open(&[path.to_owned()], &RunOptions::default()).unwrap();
    let mut reader = run.reader().unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        if let LogRecord::Message(m) = r.unwrap() {
            if m.channel.topic == topic {
                let any = m.decode_any(path).unwrap().expect("a catalogue message");
                out.push(serde_json::from_slice(&any.to_json()).unwrap());
            }
        }
    }
    out
}

#[test]
fn the_drives_gnss_imu_and_wheel_speed_come_off_its_two_buses_as_asammdf_decodes_them() {
    let dir = tempfile::tempdir().unwrap();
    let src = &drive_files()[4];
    let fused = dir.path().join("car.fused.mcap");
    let out = ok(&[
        "refuse",
        s(src),
        "-c",
        s(&sample("canedge-car.toml")),
        "-o",
        s(&fused),
    ]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("made from the CAN bus: /gnss/fix"), "{said}");
    // asammdf's extract_bus_logging with the module's DBC on bus 2, signal for signal.
    let sig = dir.path().join("signals.json");
    let dbc = sample("canedge-car/canmod-gps.dbc");
    python_ok(
        "mdf4_frames.py",
        &["signals", s(src), s(&dbc), "2", s(&sig)],
    );
    let theirs: serde_json::Value = serde_json::from_slice(&std::fs::read(&sig).unwrap()).unwrap();
    let series = |name: &str| -> Vec<(u64, f64)> {
        theirs[name]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p[0].as_u64().unwrap(), p[1].as_f64().unwrap()))
            .collect()
    };
    let at = |s: &[(u64, f64)], t: u64| s.iter().find(|p| p.0.abs_diff(t) <= 1_000).map(|p| p.1);
    let (lat, lon) = (series("Latitude"), series("Longitude"));
    let fixes = messages(&fused, "/gnss/fix");
    assert_eq!(fixes.len(), lat.len());
    let placed: Vec<&serde_json::Value> = fixes
        .iter()
        .filter(|f| !f["latitude_deg"].is_null())
        .collect();
    assert!(placed.len() > 30, "{}", placed.len());
    for f in &placed {
        let t = f["stamp_ns"].as_u64().unwrap();
        assert!((f["latitude_deg"].as_f64().unwrap() - at(&lat, t).unwrap()).abs() < 1e-9);
        assert!((f["longitude_deg"].as_f64().unwrap() - at(&lon, t).unwrap()).abs() < 1e-9);
        // The module's accuracy is each fix's σ.
        let sigma = f["position_covariance_enu_m2"][0].as_f64().unwrap().sqrt();
        assert_eq!(
            Some(sigma),
            at(&series("PositionAccuracy"), t)
                .map(|a| a.max(0.0))
                .filter(|a| *a > 0.0)
        );
    }
    let imu = messages(&fused, "/imu");
    let ax = series("AccelerationX");
    let wz = series("AngularRateZ");
    assert!(
        imu.len() as f64 > 0.95 * ax.len() as f64,
        "{} of {}",
        imu.len(),
        ax.len()
    );
    for m in imu.iter().step_by(97) {
        let t = m["stamp_ns"].as_u64().unwrap();
        assert!((m["specific_force_mps2"][0].as_f64().unwrap() - at(&ax, t).unwrap()).abs() < 1e-9);
        let rate = at(&wz, t).unwrap().to_radians();
        assert!((m["angular_rate_radps"][2].as_f64().unwrap() - rate).abs() < 1e-9);
    }
    // The wheel speed from the OBD-2 responses on bus 1, km/h into m/s.
    let odo = messages(&fused, "/odometer/1");
    assert!(odo.len() > 60, "{}", odo.len()); // about 2 Hz over the last file's 45 s
    assert!(odo
        .iter()
        .all(|o| (0.0..70.0).contains(&o["speed_mps"].as_f64().unwrap())));
}

/// A measurement system's MDF 4 (physical values, two groups at 10 and 100 Hz) that asammdf
/// wrote: read through samples/loggers/mdf4-measured.toml, every sample as asammdf reads it back, in
/// railfuse's units (the MDF channels' own units: mm, km/h through a linear conversion, g,
/// deg/s), uncompressed and in transposed deflate.
#[test]
fn measured_signals_read_through_a_mapping_as_asammdf_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let map = sample("loggers/mdf4-measured.toml");
    for compression in ["0", "2"] {
        let file = dir.path().join(format!("measured-{compression}.mf4"));
        let theirs = python_ok("mdf4_frames.py", &["measured", s(&file), compression]);
        let e = fails(&["info", s(&file)]);
        assert!(e.contains("--map") && e.contains("Latitude"), "{e}");
        let out = dir.path().join(format!("measured-{compression}.mcap"));
        ok(&["import", s(&file), "--map", s(&map), "-o", s(&out)]);
        let col = |name: &str| theirs[name].as_array().unwrap().clone();
        let fixes = messages(&out, "/gnss/fix");
        assert_eq!(fixes.len(), col("Latitude").len());
        for (k, f) in fixes.iter().enumerate() {
            let at = |name: &str| col(name)[k][1].as_f64().unwrap();
            assert_eq!(f["stamp_ns"], col("Latitude")[k][0]);
            assert_eq!(f["latitude_deg"].as_f64(), Some(at("Latitude")));
            assert_eq!(f["longitude_deg"].as_f64(), Some(at("Longitude")));
            assert!((f["altitude_m"].as_f64().unwrap() - at("Height") / 1000.0).abs() < 1e-9);
            assert!((f["speed_mps"].as_f64().unwrap() - at("Speed") / 3.6).abs() < 1e-9);
        }
        let imu = messages(&out, "/imu");
        assert_eq!(imu.len(), col("AccX").len());
        for (k, m) in imu.iter().enumerate() {
            let at = |name: &str| col(name)[k][1].as_f64().unwrap();
            assert_eq!(m["stamp_ns"], col("AccZ")[k][0]);
            let f = m["specific_force_mps2"][2].as_f64().unwrap();
            assert!((f - at("AccZ") * 9.806_65).abs() < 1e-9);
            let w = m["angular_rate_radps"][0].as_f64().unwrap();
            assert!((w - at("GyroX").to_radians()).abs() < 1e-12);
        }
    }
}
