//! `railfuse import`: the ETH-PBL railway samples and a CSV log through its column mapping.

use super::*;

/// The three real ETH-PBL samples import; their NAV-PVT values are those SOURCE.md decodes,
/// a NAV-PVT without a fix arrives as a fix that says so (no position), and the IMU is in SI
/// units (a node lying on the cab floor of a standing train feels 1 g up).
#[test]
fn the_eth_railway_samples_import_with_the_documented_values() {
    use railfuse_catalog::log::{LogReader, LogRecord};
    use railfuse_catalog::messages::{FixType, GnssFix, Imu};
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/eth-pbl-railway");
    let d = tempfile::tempdir().unwrap();
    let read = |name: &str| -> (Vec<GnssFix>, Vec<Imu>, serde_json::Value) {
        let out = d.path().join(format!("{name}.mcap"));
        let report = ok(&[
            "import",
            s(&data.join(format!("{name}.csv"))),
            "-o",
            s(&out),
            "--json",
        ]);
        let report: serde_json::Value = serde_json::from_slice(&report.stdout).unwrap();
        let (mut fixes, mut imu) = (Vec::new(), Vec::new());
        let mut r = LogReader::open(&out).unwrap();
        while let Some(rec) = r.next() {
            if let LogRecord::Message(m) = rec.unwrap() {
                match m.channel.topic.as_str() {
                    "/gnss/fix" => fixes.push(m.decode(&out).unwrap()),
                    "/imu" => imu.push(m.decode(&out).unwrap()),
                    _ => {}
                }
            }
        }
        (fixes, imu, report)
    };
    let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 5e-8);

    let (fixes, imu, report) = read("20221020_1030_R90117_Modena_SN1_sample");
    assert_eq!(fixes.len(), 2, "{report}");
    for f in &fixes {
        assert_eq!(
            (f.fix_type, f.satellites, f.latitude_deg, f.longitude_deg),
            (FixType::None, 0, None, None)
        );
    }
    assert_eq!(imu.len(), 1997);
    let (fixes, _, report) = read("20221020_1030_R90117_Modena_SN2_sample");
    assert_eq!(fixes.len(), 1, "{report}");
    assert!(fixes[0].fix_type.has_position() && fixes[0].satellites == 29);
    assert!(
        close(fixes[0].latitude_deg, 44.6551106) && close(fixes[0].longitude_deg, 10.9297304),
        "{:?}",
        fixes[0]
    );
    let h = fixes[0].position_covariance_enu_m2.unwrap();
    assert!((h[0] + h[4]).sqrt() < 1.5, "NAV-COV horizontal σ {h:?}");
    assert_eq!(
        report["skipped"]
            ["NMEA sentence beside UBX NAV-PVT (the same receiver's solutions; NAV-PVT used)"],
        4
    );
    let (fixes, imu, _) = read("20221019_1252_R90120_Formigine_SN1_sample");
    assert!(
        fixes[0].satellites == 28
            && close(fixes[0].latitude_deg, 44.5775211)
            && close(fixes[0].longitude_deg, 10.8457549),
        "{:?}",
        fixes[0]
    );
    // UTC from the receiver: 2022-10-19, the run's date.
    assert_eq!(fixes[0].stamp_ns / 86_400_000_000_000, 19_284);
    let g = imu.iter().map(|m| m.specific_force_mps2[2]).sum::<f64>() / imu.len() as f64;
    assert!((g - 9.81).abs() < 0.3, "mean z specific force {g} m/s²");
    let rate = imu
        .iter()
        .map(|m| m.angular_rate_radps[2].abs())
        .fold(0.0, f64::max);
    assert!(rate < 0.1, "a standing train does not turn: {rate} rad/s");
    // IMU about 1.6 kHz on the node clock.
    let span = (imu.last().unwrap().stamp_ns - imu[0].stamp_ns) as f64 / 1e9;
    assert!(
        (1300.0..2000.0).contains(&(imu.len() as f64 / span)),
        "{} Hz",
        imu.len() as f64 / span
    );
}

#[test]
fn a_csv_log_imports_through_its_column_mapping_and_bad_rows_are_named() {
    let d = tempfile::tempdir().unwrap();
    let (csv, map, out) = (
        d.path().join("logger.csv"),
        d.path().join("map.toml"),
        d.path().join("logger.mcap"),
    );
    let mut text = String::from("t;v_radar;pos;note\n");
    for k in 0..100 {
        let pos = if k % 10 == 0 {
            format!("{}", k as f64 * 2.5)
        } else {
            String::new()
        };
        text += &format!("{};{};{pos};ok\n", k as f64 * 0.1, 25.0 + k as f64 * 0.01);
    }
    text += "oops;1;2;x\n7.0;fast;;x\n";
    std::fs::write(&csv, text).unwrap();
    std::fs::write(
        &map,
        "time_column = \"t\"\ntime_unit = \"s\"\ntime_offset_ns = 1780300800000000000\ndelimiter = \";\"\n\
         [[channel]]\ntopic = \"/radar/speed\"\nfields = { speed_mps = \"v_radar\" }\nconstants = { quality = 1.0, valid = true }\n\
         [[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"pos\" }\n",
    )
    .unwrap();
    let r: serde_json::Value = ok_json(&[
        "import",
        "--format",
        "csv",
        "--map",
        s(&map),
        s(&csv),
        "-o",
        s(&out),
        "--json",
    ]);
    assert_eq!(
        (
            r["per_topic"]["/radar/speed"].as_u64(),
            r["per_topic"]["/loop/position"].as_u64()
        ),
        (Some(100), Some(10)),
        "{r}"
    );
    let problems = r["first_problems"].to_string();
    assert!(
        problems.contains("bad time: line 102")
            && problems.contains("row does not make a valid message: line 103"),
        "{problems}"
    );
    let info: serde_json::Value = ok_json(&["info", s(&out), "--json"]);
    assert_eq!(info["channels"].as_array().unwrap().len(), 2);
    // A mapping naming a column the file does not have is refused, naming both.
    std::fs::write(&map, "time_column = \"t\"\ndelimiter = \";\"\n[[channel]]\ntopic = \"/radar/speed\"\nfields = { speed_mps = \"v\" }\n").unwrap();
    let bad = railfuse(&[
        "import",
        "--format",
        "csv",
        "--map",
        s(&map),
        s(&csv),
        "-o",
        s(&out),
    ]);
    assert!(
        !bad.status.success()
            && stderr(&bad).contains("channel /radar/speed: no column 'v' in the header"),
        "{}",
        stderr(&bad)
    );
}

/// Receiver captures as they come off a real device: a comment header and `$$` before every
/// sentence (ST Teseo LIV4F) are told as NMEA without `--format` and import, the junk counted;
/// a capture with unreadable lines imports the rest and says how much was skipped; one that
/// is not NMEA at all is one line naming the file, and nothing is left behind.
#[test]
fn receiver_captures_are_told_imported_and_their_junk_counted() {
    let d = tempfile::tempdir().unwrap();
    let nmea = |body: &str| format!("${body}*{:02X}", body.bytes().fold(0u8, |a, b| a ^ b));
    let mut text = String::from("# Name: ST Teseo-liv4f\n# Date: 2025-03-26\n");
    for k in 0..12 {
        for body in [
            format!("GNRMC,1358{k:02}.000,A,4723.00484,N,00045.88150,E,0.5,120.9,210325,,,A,C"),
            format!("GNGGA,1358{k:02}.000,4723.00484,N,00045.88150,E,1,13,1.7,063.64,M,48.3,M,,"),
        ] {
            text.push_str(&format!("${}\r\n", nmea(&body)));
        }
    }
    text.push_str("$$GPGSV,3,1,09,16,71,196,27*00\r\n"); // a bad checksum, as the capture has
    let capture = d.path().join("teseo.log");
    std::fs::write(&capture, &text).unwrap();
    let out = d.path().join("teseo.mcap");
    let r = ok(&["import", s(&capture), "-o", s(&out)]);
    let said = String::from_utf8_lossy(&r.stdout);
    assert!(said.contains("as 12 messages"), "{said}");
    assert!(
        said.contains("not used: 24 × NMEA line with bytes before its last `$`"),
        "{said}"
    );
    assert!(
        said.contains("not used: 1 × NMEA checksum failure"),
        "{said}"
    );
    assert!(
        said.contains("not used: 2 × not an NMEA sentence"),
        "{said}"
    );
    assert!(said.contains("line 27: NMEA checksum"), "{said}");

    let junk = d.path().join("notes.nmea");
    std::fs::write(
        &junk,
        "these are a field engineer's notes,\nnot a receiver's capture\n",
    )
    .unwrap();
    let bad = d.path().join("bad.mcap");
    assert_one_clear_line(
        &railfuse(&["import", "--format", "nmea", s(&junk), "-o", s(&bad)]),
        &[
            s(&junk),
            "no nmea message in it",
            "2 × not an NMEA sentence",
        ],
    );
    assert!(!bad.exists());
}
