use super::*;
use railfuse_catalog::messages::{FixType, GnssFix};

/// Feeds whole lines, then ends the stream; returns the fixes.
fn fixes(a: &mut FixAssembler, lines: &[&str], clock: Option<u64>) -> Vec<GnssFix> {
    for line in lines {
        let s = parse(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        a.feed(&s, clock).unwrap_or_else(|e| panic!("{line}: {e}"));
    }
    a.finish(clock);
    std::iter::from_fn(|| a.next_fix()).collect()
}

/// `body` with its `$` and checksum.
fn nmea(body: &str) -> String {
    format!("${body}*{:02X}", body.bytes().fold(0u8, |a, b| a ^ b))
}

#[test]
fn a_fix_is_assembled_from_rmc_gst_and_gga() {
    let f = fixes(
        &mut FixAssembler::default(),
        &[
            "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F",
            "$GNGST,083559.00,0.45,0.020,0.015,77.4,0.018,0.017,0.031*45",
            GGA,
        ],
        None,
    );
    let f = &f[0];
    assert_eq!(f.fix_type, FixType::RtkFixed);
    assert_eq!(f.stamp_ns, STAMP);
    assert!((f.latitude_deg.unwrap() - 44.655110666).abs() < 1e-8);
    assert!((f.longitude_deg.unwrap() - 10.929730333).abs() < 1e-8);
    assert!((f.altitude_m.unwrap() - 79.3).abs() < 1e-9);
    assert_eq!(f.altitude_msl_m, Some(35.2));
    assert!((f.position_covariance_enu_m2.unwrap()[4] - 0.018f64.powi(2)).abs() < 1e-12);
}

#[test]
fn bad_checksums_and_junk_are_errors_not_panics() {
    assert!(matches!(
        parse("$GNGGA,1*00"),
        Err(NmeaError::Checksum { .. })
    ));
    assert_eq!(parse("hello"), Err(NmeaError::NotASentence));
    assert_eq!(
        parse(&format!("${}*00", "A".repeat(300))),
        Err(NmeaError::TooLong(304))
    );
    let s =
        parse("$GBGSV,2,1,07,06,25,044,42,09,38,057,44,12,49,295,46,16,19,038,37,B*04").unwrap();
    assert_eq!((s.talker, s.kind), ("GB", "GSV"));
    assert_eq!(
        FixAssembler::default().feed(&s, None).unwrap(),
        Decoded::Skipped
    );
    let bad_field =
        parse("$GNGGA,08x559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*10");
    assert!(FixAssembler::default()
        .feed(&bad_field.unwrap(), None)
        .is_err());
    // Proprietary sentences are sentences, skipped.
    let line = nmea("PUBX,00,081350.00");
    let pubx = parse(&line).unwrap();
    assert_eq!((pubx.talker, pubx.kind), ("P", "UBX"));
}

#[test]
fn a_non_ascii_byte_with_a_good_checksum_is_refused_not_a_panic() {
    let line = "$GPGGA,2é5959.00,4807.038,S,01131.000,W,1,08,0.9,545.4,M,46.9,M,,*33";
    assert_eq!(parse(line), Err(NmeaError::NotAscii));
    // Past the sentence check, no field is ever sliced off a character boundary either.
    let s = Sentence {
        talker: "GP",
        kind: "GGA",
        fields: vec!["2é5959.00", "4é07.038", "S", "é1131.000", "W", "1"],
        junk: 0,
    };
    assert!(FixAssembler::default().feed(&s, None).is_err());
}

#[test]
fn nan_inf_exponents_and_impossible_values_are_refused_naming_the_field() {
    let reason = |body: &str| {
        let line = nmea(body);
        match FixAssembler::default().feed(&parse(&line).unwrap(), None) {
            Err(NmeaError::BadField { name, why, .. }) => format!("{name}: {why}"),
            other => panic!("{line}: {other:?}"),
        }
    };
    let gga = |lat: &str, ns: &str| {
        format!("GPGGA,120000.00,{lat},{ns},01131.000,E,1,08,0.9,545.4,M,46.9,M,,")
    };
    let gst = |sigma: &str| format!("GPGST,120000.00,0.45,0.020,0.015,77.4,{sigma},0.017,0.031");
    for (body, why) in [
        (
            gga("48nan", "N"),
            "latitude: degrees and minutes (d…dmm.mmmm) expected",
        ),
        (
            gga("4807.0e1", "N"),
            "latitude: degrees and minutes (d…dmm.mmmm) expected",
        ),
        (gga("4860.000", "N"), "latitude: minutes of 60 or more"),
        (
            gga("9100.000", "N"),
            "latitude: beyond the pole or the antimeridian",
        ),
        (gga("4807.038", "X"), "N/S: hemisphere expected"),
        (gst("NaN"), "σ latitude: not a number"),
        (gst("-0.5"), "σ latitude: negative"),
        (gst("inf"), "σ latitude: not a number"),
    ] {
        assert_eq!(reason(&body), why, "{body}");
    }
    for date in ["311322", "000124", "310224", "2902x3"] {
        let rmc = format!("GPRMC,120000.00,A,4807.038,N,01131.000,E,0.1,,{date},,,A");
        assert!(reason(&rmc).starts_with("date: "), "{date}");
    }
    assert_eq!(
        reason(&gga("4807.038", "N").replace("120000.00", "120060.00")),
        "time: not a time of day"
    );
    // 23:59:60 is a leap second: the same Unix instant as the next midnight.
    let mut a = FixAssembler::with_date(Some((2016, 12, 31)));
    let leap = nmea(&gga("4807.038", "N").replace("120000.00", "235960.00"));
    let f = fixes(&mut a, &[&leap], None);
    assert_eq!(f[0].stamp_ns, 1_483_228_800 * 1_000_000_000);
}

const GGA: &str = "$GNGGA,083559.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*5B";
const STAMP: u64 = 1_666_254_959 * 1_000_000_000; // 2022-10-20 08:35:59 UTC

#[test]
fn a_fix_before_the_date_waits_for_it_and_is_never_stamped_1970() {
    let rmc = "$GNRMC,083559.00,A,4439.30664,N,01055.78382,E,0.074,,201022,,,R,V*0F";
    let f = fixes(&mut FixAssembler::default(), &[GGA, rmc], None);
    assert_eq!(f[0].stamp_ns, STAMP);
    // ZDA gives the date too.
    let zda = "$GNZDA,083559.00,20,10,2022,00,00*7B";
    let f = fixes(&mut FixAssembler::default(), &[GGA, zda], None);
    assert_eq!(f[0].stamp_ns, STAMP);
    // Never dated: dropped and counted at the end, not stamped 1970.
    let mut n = FixAssembler::default();
    assert!(fixes(&mut n, &[GGA], None).is_empty());
    assert_eq!(n.undated, 1);
    // A date given up front, or a live clock near the fix (just after midnight UTC).
    let f = fixes(
        &mut FixAssembler::with_date(Some((2022, 10, 20))),
        &[GGA],
        None,
    );
    assert_eq!(f[0].stamp_ns, STAMP);
    let f = fixes(
        &mut FixAssembler::default(),
        &[GGA],
        Some(STAMP + 3_000_000_000),
    );
    assert_eq!(f[0].stamp_ns, STAMP);
    let late = "$GNGGA,235959.00,4439.30664,N,01055.78382,E,4,12,0.58,35.2,M,44.1,M,1.0,0000*58";
    let after_midnight = 1_666_310_400 * 1_000_000_000 + 2_000_000_000; // 2022-10-21 00:00:02
    let f = fixes(&mut FixAssembler::default(), &[late], Some(after_midnight));
    assert_eq!(f[0].stamp_ns, after_midnight - 3_000_000_000);
}

/// A GGA at `hhmmss` and an RMC of the same epoch dated `ddmmyy`.
fn epoch(hhmmss: &str, ddmmyy: &str) -> [String; 2] {
    [
        nmea(&format!(
            "GPGGA,{hhmmss}.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
        )),
        nmea(&format!(
            "GPRMC,{hhmmss}.00,A,4807.038,N,01131.000,E,0.1,,{ddmmyy},,,A"
        )),
    ]
}

#[test]
fn each_fix_takes_its_own_epochs_date_across_midnight_and_the_new_year() {
    let new_year = 1_735_689_600 * 1_000_000_000u64; // 2025-01-01 00:00:00
                                                     // RMC after the GGA (the date comes last in each epoch).
    let mut lines: Vec<String> = epoch("235958", "311224").into();
    lines.extend(epoch("235959", "311224"));
    lines.extend(epoch("000000", "010125"));
    lines.extend(epoch("000001", "010125"));
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    let stamps: Vec<u64> = fixes(&mut FixAssembler::default(), &refs, None)
        .iter()
        .map(|f| f.stamp_ns)
        .collect();
    let s = 1_000_000_000;
    assert_eq!(
        stamps,
        [new_year - 2 * s, new_year - s, new_year, new_year + s]
    );
    // Held before the first date, released by a date after midnight: the day before.
    let first = nmea("GPGGA,235959.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
    let mut lines = vec![first];
    lines.extend(epoch("000000", "010125"));
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    let stamps: Vec<u64> = fixes(&mut FixAssembler::default(), &refs, None)
        .iter()
        .map(|f| f.stamp_ns)
        .collect();
    assert_eq!(stamps, [new_year - s, new_year]);
    // GGA only after one dated epoch: the day rolls over with the time of day.
    let mut lines: Vec<String> = epoch("235959", "311224").into();
    lines.push(nmea(
        "GPGGA,000000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    ));
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    let f = fixes(&mut FixAssembler::default(), &refs, None);
    assert_eq!(f[1].stamp_ns, new_year);
}

#[test]
fn gsa_and_gst_after_the_gga_belong_to_its_epoch_and_empty_fields_carry_nothing_over() {
    let gga = |t: &str, q: u8| {
        nmea(&format!(
            "GPGGA,{t},4807.038,N,01131.000,E,{q},08,0.9,545.4,M,,M,,"
        ))
    };
    let lines = [
        // Epoch 1: no fix, GSA mode 1, no GST.
        gga("120000.00", 0),
        nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
        // Epoch 2: a fix, its GSA and GST after the GGA.
        gga("120001.00", 1),
        nmea("GPGSA,A,3,01,02,03,04,,,,,,,,,1.5,0.9,1.2"),
        nmea("GPGST,120001.00,0.45,0.020,0.015,77.4,1.5,2.5,3.5"),
        nmea("GPVTG,45.0,T,,M,10.0,N,18.52,K,A"),
        // Epoch 3: empty GST and VTG course: nothing from epoch 2.
        gga("120002.00", 1),
        nmea("GPGST,120002.00,,,,,,,"),
        nmea("GPVTG,,T,,M,10.0,N,18.52,K,A"),
    ];
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    let f = fixes(
        &mut FixAssembler::with_date(Some((2025, 3, 1))),
        &refs,
        None,
    );
    assert_eq!(f.len(), 3);
    assert_eq!(f[0].fix_type, FixType::None);
    assert_eq!(f[1].fix_type, FixType::Single);
    assert_eq!(f[1].position_covariance_enu_m2.map(|c| c[0]), Some(6.25));
    assert!((f[1].course_rad.unwrap() - 45f64.to_radians()).abs() < 1e-12);
    assert_eq!(f[2].position_covariance_enu_m2, None);
    assert_eq!(f[2].course_rad, None);
    assert!((f[2].speed_mps.unwrap() - 18.52 / 3.6).abs() < 1e-12);
    // An empty geoid separation: the MSL height, and no ellipsoidal height.
    assert_eq!((f[1].altitude_m, f[1].altitude_msl_m), (None, Some(545.4)));
}
