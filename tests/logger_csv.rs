//! Loggers' CSV tables through a column mapping, checked against pandas reading the same
//! files: a u-blox logger's table (date and time in six columns, whole seconds, 1e-7°, mm,
//! mm/s), the same table as a European spreadsheet saves it (`;`, decimal comma, BOM, CRLF),
//! and a phone sensor-logger export (a local time with its offset, g with iOS's sign, a fix
//! repeated on every row); each as a run input and as an import.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use common::*;
use railfuse_catalog::formats::csv_table::mapping::MappingFile;
use railfuse_catalog::formats::FormatOptions;
use railfuse_catalog::log::LogRecord;
use railfuse_catalog::messages::{ChannelMessage, GnssFix, Imu};
use railfuse_catalog::run::{Run, RunOptions};

/// Every message on `topic` of a CSV run read with `mapping`, and the conversion's warnings.
fn of_run<M: ChannelMessage>(csv: &Path, mapping: &Path, topic: &str) -> Vec<M> {
    let options = RunOptions {
        formats: FormatOptions {
            csv: Some(Arc::new(MappingFile::read(mapping).unwrap())),
            ..Default::default()
        },
        ..Default::default()
    };
    let run = Run::open(&[csv.to_owned()], &options).unwrap();
    let mut reader = run.reader().unwrap();
    let mut out = Vec::new();
    while let Some(r) = reader.next() {
        if let LogRecord::Message(m) = r.unwrap() {
            if m.channel.topic == topic && m.channel.schema_name().starts_with("railfuse.") {
                out.push(m.decode(csv).unwrap());
            }
        }
    }
    out
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// Fixes match pandas' reading of the logger's table, field for field.
fn same_fixes(ours: &[GnssFix], theirs: &serde_json::Value) {
    let theirs = theirs["fixes"].as_array().unwrap();
    assert_eq!(ours.len(), theirs.len());
    for (f, p) in ours.iter().zip(theirs) {
        assert_eq!(f.stamp_ns as i64, p["stamp_ns"].as_i64().unwrap(), "{p}");
        let fields = [
            (f.latitude_deg, "latitude_deg", 1e-12),
            (f.longitude_deg, "longitude_deg", 1e-12),
            (f.altitude_m, "altitude_m", 1e-9),
            (f.speed_mps, "speed_mps", 1e-12),
        ];
        for (ours, name, tol) in fields {
            assert!(
                close(ours.unwrap(), p[name].as_f64().unwrap(), tol),
                "{name}: {p}"
            );
        }
        assert_eq!(f.satellites as u64, p["satellites"].as_u64().unwrap());
        let sigma = p["sigma_h_m"].as_f64().unwrap();
        let c = f.position_covariance_enu_m2.unwrap();
        assert!(close(c[0].sqrt(), sigma, 1e-12) && close(c[4].sqrt(), sigma, 1e-12));
    }
}

#[test]
fn a_gnss_logger_s_table_reads_fix_for_fix_as_pandas_reads_it() {
    let (csv, map) = (
        sample("loggers/gnss-logger.csv"),
        sample("loggers/gnss-logger.toml"),
    );
    let theirs = python_ok("logger_csv.py", &["read-logger", s(&csv)]);
    same_fixes(&of_run(&csv, &map, "/gnss/fix"), &theirs);
    assert_eq!(theirs["fixes"].as_array().unwrap().len(), 451);

    // As a European spreadsheet saves it: ';', decimal comma, BOM, CRLF.
    let dir = tempfile::tempdir().unwrap();
    let eu = dir.path().join("logger-eu.csv");
    python_ok("logger_csv.py", &["european", s(&csv), s(&eu)]);
    let text = std::fs::read(&eu).unwrap();
    assert!(text.starts_with(b"\xef\xbb\xbfYear;") && text.windows(2).any(|w| w == b"\r\n"));
    let eu_map = dir.path().join("eu.toml");
    let mapping = std::fs::read_to_string(&map).unwrap();
    std::fs::write(
        &eu_map,
        format!("delimiter = \";\"\ndecimal = \",\"\n{mapping}"),
    )
    .unwrap();
    let theirs = python_ok("logger_csv.py", &["read-logger", s(&eu), "--european"]);
    same_fixes(&of_run(&eu, &eu_map, "/gnss/fix"), &theirs);
}

#[test]
fn a_phone_export_reads_sample_for_sample_and_its_repeated_fix_once() {
    let (csv, map) = (
        sample("loggers/phone-sensorlog.csv"),
        sample("loggers/phone-sensorlog.toml"),
    );
    let theirs = python_ok("logger_csv.py", &["read-phone", s(&csv)]);
    let imu: Vec<Imu> = of_run(&csv, &map, "/imu");
    let want = theirs["imu"].as_array().unwrap();
    assert_eq!(imu.len(), want.len());
    for (m, p) in imu.iter().zip(want) {
        assert_eq!(m.stamp_ns as i64, p["stamp_ns"].as_i64().unwrap());
        for a in 0..3 {
            let f = p["specific_force_mps2"][a].as_f64().unwrap();
            assert!(
                close(m.specific_force_mps2[a], f, 1e-9),
                "{} {f}",
                m.specific_force_mps2[a]
            );
            let w = p["angular_rate_radps"][a].as_f64().unwrap();
            assert!(close(m.angular_rate_radps[a], w, 1e-12));
        }
    }
    // At rest a phone's z reads about -1 g; railfuse's specific force is +g up.
    assert!(imu.iter().map(|m| m.specific_force_mps2[2]).sum::<f64>() / imu.len() as f64 > 9.0);
    let fixes: Vec<GnssFix> = of_run(&csv, &map, "/gnss/fix");
    let want = theirs["fixes"].as_array().unwrap();
    assert_eq!(fixes.len(), want.len());
    for (f, p) in fixes.iter().zip(want) {
        assert_eq!(f.stamp_ns as i64, p["stamp_ns"].as_i64().unwrap());
        assert!(close(
            f.latitude_deg.unwrap(),
            p["latitude_deg"].as_f64().unwrap(),
            1e-12
        ));
        assert!(close(
            f.course_rad.unwrap(),
            p["course_rad"].as_f64().unwrap(),
            1e-12
        ));
        let c = f.position_covariance_enu_m2.unwrap();
        assert!(close(c[0].sqrt(), p["sigma_h_m"].as_f64().unwrap(), 1e-9));
    }
    // The fix repeated on every motion row is counted, once per repeat.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("phone.mcap");
    let r = ok_json(&["import", s(&csv), "--map", s(&map), "-o", s(&out), "--json"]);
    let repeats = r["skipped"]["a row at the time of the one before"]
        .as_u64()
        .unwrap();
    assert_eq!(repeats as usize, imu.len() - fixes.len(), "{r}");
}

#[test]
fn a_table_is_a_run_for_every_command_with_its_mapping_and_refused_without() {
    let (csv, map) = (
        sample("loggers/gnss-logger.csv"),
        sample("loggers/gnss-logger.toml"),
    );
    let info = ok_json(&["info", s(&csv), "--map", s(&map), "--json"]);
    let fix = info["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["topic"] == "/gnss/fix")
        .unwrap()
        .clone();
    assert_eq!(fix["messages"], 451, "{fix}");
    let e = fails(&["info", s(&csv)]);
    assert!(e.contains("gnss-logger.csv") && e.contains("--map"), "{e}");
}

#[test]
fn bad_tables_say_what_in_one_line_and_keep_what_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| -> PathBuf { dir.path().join(n) };
    std::fs::write(d("m.toml"), "time_column = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"pos\" }\n").unwrap();
    std::fs::write(d("t.csv"), "t,x\n1,1\n").unwrap();
    let e = fails(&[
        "import",
        s(&d("t.csv")),
        "--map",
        s(&d("m.toml")),
        "-o",
        s(&d("o.mcap")),
    ]);
    assert!(
        e.contains("m.toml") && e.contains("no column 'pos'") && e.lines().count() == 1,
        "{e}"
    );
    // Times going backwards: the rows in order are kept, the rest counted, one warning names
    // the first line that went back.
    std::fs::write(d("m.toml"), "time_column = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"x\" }\n").unwrap();
    std::fs::write(d("t.csv"), "t,x\n1,1\n2,2\n3,3\n2.5,4\n4,5\n").unwrap();
    let out = railfuse(&[
        "import",
        s(&d("t.csv")),
        "--map",
        s(&d("m.toml")),
        "-o",
        s(&d("o.mcap")),
    ]);
    assert!(out.status.success());
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert!(
        text.contains("time goes backwards on /loop/position at line 5"),
        "{text}"
    );
    assert_eq!(ok_json(&["info", s(&d("o.mcap")), "--json"])["messages"], 4);
}
