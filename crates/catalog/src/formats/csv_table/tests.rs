use super::*;
use crate::log::{LogReader, LogRecord};
use crate::messages::{AnyMessage, FixType};

/// Converts `csv` with `mapping`: the report and each message (topic, log time, message).
fn convert_text(mapping: &str, csv: &[u8]) -> Result<(Converted, Vec<(String, u64, AnyMessage)>)> {
    let d = tempfile::tempdir().unwrap();
    let (m, c, o) = (
        d.path().join("m.toml"),
        d.path().join("t.csv"),
        d.path().join("o.mcap"),
    );
    std::fs::write(&m, mapping).unwrap();
    std::fs::write(&c, csv).unwrap();
    let report = convert(&c, &o, &MappingFile::read(&m)?, &WriterOptions::default())?;
    let mut reader = LogReader::open(&o)?;
    let mut out = Vec::new();
    while let Some(record) = reader.next() {
        if let LogRecord::Message(m) = record? {
            // (Foxglove's twins of the messages are not catalogue messages.)
            if let Some(message) = m.decode_any(&o)? {
                out.push((m.channel.topic.clone(), m.log_time_ns, message));
            }
        }
    }
    Ok((report, out))
}

/// The GNSS logger of the issue: date and time in six columns, whole seconds, 1e-7°, mm,
/// mm/s, five rows a second.
const LOGGER_MAP: &str = r#"
[time]
columns = ["Year", "Month", "Day", "Hour", "Minute", "Second"]
format = "%Y %m %d %H %M %S"
spread = "rate"
rate_hz = 5
[columns]
Lat = { scale = 1e-7 }
Lon = { scale = 1e-7 }
Alt1 = { unit = "mm" }
hAcc = { unit = "mm" }
vAcc = { unit = "mm" }
speed = { unit = "mm/s" }
[[channel]]
topic = "/gnss/fix"
fields = { latitude_deg = "Lat", longitude_deg = "Lon", altitude_m = "Alt1", satellites = "nSAT", speed_mps = "speed", horizontal_accuracy_m = "hAcc", vertical_accuracy_m = "vAcc" }
constants = { fix_type = "single" }
"#;

fn logger_row(second: u32, lat: i64) -> String {
    format!("2023,7,1,10,5,{second},12,85512345,{lat},412000,365000,1500,2500,12345,300,150\r\n")
}

#[test]
fn a_gnss_logger_s_rows_are_scaled_into_units_and_spread_over_their_second() {
    let mut csv = "\u{feff}Year,Month,Day,Hour,Minute,Second,nSAT,Lon,Lat,Alt1,Alt2,hAcc,vAcc,speed,speedAcc,PDOP\r\n".to_owned();
    for k in 0..5 {
        csv += &logger_row(3, 473_000_000 + k);
    }
    csv += &logger_row(4, 473_000_010);
    let (report, out) = convert_text(LOGGER_MAP, csv.as_bytes()).unwrap();
    assert_eq!((report.rows, report.messages), (6, 6), "{report:?}");
    let t0 = 1_688_205_903_000_000_000u64; // 2023-07-01T10:05:03Z
    let times: Vec<u64> = out.iter().map(|(_, t, _)| t - t0).collect();
    assert_eq!(
        times,
        vec![
            0,
            200_000_000,
            400_000_000,
            600_000_000,
            800_000_000,
            1_000_000_000
        ]
    );
    let AnyMessage::GnssFix(f) = &out[1].2 else {
        panic!("{:?}", out[1])
    };
    assert_eq!((f.fix_type, f.satellites), (FixType::Single, 12));
    assert!((f.latitude_deg.unwrap() - 47.300_000_1).abs() < 1e-12);
    assert!((f.longitude_deg.unwrap() - 8.551_234_5).abs() < 1e-12);
    assert_eq!(f.altitude_m, Some(412.0));
    assert!((f.speed_mps.unwrap() - 12.345).abs() < 1e-12);
    // hAcc 1.5 m and vAcc 2.5 m, each one σ by default.
    let c = f.position_covariance_enu_m2.unwrap();
    assert!((c[0] - 2.25).abs() < 1e-9 && (c[4] - 2.25).abs() < 1e-9 && (c[8] - 6.25).abs() < 1e-9);
}

#[test]
fn without_a_spread_the_rows_of_one_second_are_repeats_and_counted() {
    let map = LOGGER_MAP.replace("spread = \"rate\"\nrate_hz = 5\n", "");
    let mut csv =
        "Year,Month,Day,Hour,Minute,Second,nSAT,Lon,Lat,Alt1,Alt2,hAcc,vAcc,speed,speedAcc,PDOP\n"
            .to_owned();
    for k in 0..5 {
        csv += &logger_row(3, 473_000_000 + k);
    }
    let (report, out) = convert_text(&map, csv.as_bytes()).unwrap();
    assert_eq!(out.len(), 1);
    assert_eq!(
        report.skipped["a row at the time of the one before"], 4,
        "{report:?}"
    );
}

#[test]
fn a_decimal_comma_semicolons_and_a_zone_with_daylight_saving() {
    let map = r#"
delimiter = ";"
decimal = ","
[time]
column = "Zeit"
format = "%d.%m.%Y %H:%M:%S%.f"
zone = "Europe/Berlin"
[columns]
v = { unit = "km/h" }
[[channel]]
topic = "/radar/speed"
fields = { speed_mps = "v" }
constants = { quality = 1.0, valid = true }
"#;
    let csv = "Zeit;v\n01.07.2023 10:05:03,5;36,0\n01.01.2023 10:05:03,5;72\n";
    let (_, out) = convert_text(map, csv.as_bytes()).unwrap();
    // Summer is UTC+2 (10:05 is 08:05 UTC); the second row is six months earlier: not written.
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].1, 1_688_198_703_500_000_000);
    let AnyMessage::RadarSpeed(r) = &out[0].2 else {
        panic!()
    };
    assert!((r.speed_mps - 10.0).abs() < 1e-12);
}

#[test]
fn rows_out_of_order_are_counted_and_a_warning_names_the_first() {
    let map = "time_column = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"x\" }\n";
    let csv = "t,x\n1,10\n2,20\n1.5,15\n3,30\n3,31\n";
    let (report, out) = convert_text(map, csv.as_bytes()).unwrap();
    assert_eq!(out.len(), 3);
    assert_eq!(report.skipped["a row earlier than the one before"], 1);
    assert_eq!(report.skipped["a row at the time of the one before"], 1);
    assert!(
        report.warnings[0].contains("line 4"),
        "{:?}",
        report.warnings
    );
}

#[test]
fn bad_mappings_name_the_column_or_key_in_one_line() {
    let csv = b"t,x\n1,10\n";
    let e = |map: &str| convert_text(map, csv).unwrap_err().to_string();
    let missing = e("time_column = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"pos\" }\n");
    assert!(
        missing.contains("no column 'pos' in the header (t, x)") && !missing.contains('\n'),
        "{missing}"
    );
    let unit = e("time_column = \"t\"\n[columns]\nx = { unit = \"furlong\" }\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"x\" }\n");
    assert!(unit.contains("'furlong'") && unit.contains("mm"), "{unit}");
    let zone = e("[time]\ncolumn = \"t\"\nformat = \"%s\"\nzone = \"Mars/Base\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"x\" }\n");
    assert!(zone.contains("Mars/Base"), "{zone}");
    let both = e("time_column = \"t\"\n[time]\ncolumn = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { chainage_m = \"x\" }\n");
    assert!(both.contains("not both"), "{both}");
    let accuracy = e("time_column = \"t\"\n[[channel]]\ntopic = \"/loop/position\"\nfields = { horizontal_accuracy_m = \"x\" }\n");
    assert!(accuracy.contains("GNSS fix"), "{accuracy}");
}

#[test]
fn a_channel_reads_its_own_time_and_the_example_mapping_reads_its_example() {
    let map = r#"
time_column = "t"
[[channel]]
topic = "/loop/position"
fields = { chainage_m = "x" }
[[channel]]
topic = "/radar/speed"
fields = { speed_mps = "v" }
constants = { quality = 1.0, valid = true }
time = { column = "tv", unit = "ms" }
"#;
    let csv = "t,x,tv,v\n1,10,900,5\n2,20,900,5\n3,30,2950,6\n";
    let (_, out) = convert_text(map, csv.as_bytes()).unwrap();
    let radar: Vec<u64> = out
        .iter()
        .filter(|m| m.0 == "/radar/speed")
        .map(|m| m.1)
        .collect();
    assert_eq!(radar, vec![900_000_000, 2_950_000_000]);
    let (mapping, table) = example::example();
    let (report, _) = convert_text(&mapping, table.as_bytes()).unwrap();
    assert_eq!(
        report.messages as usize,
        example::EXAMPLE_KINDS.len(),
        "{report:?}"
    );
}
