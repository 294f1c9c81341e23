//! Regression tests from real receivers' sentences: one per defect found by comparing
//! captures with gpsd and pynmeagps (issue 44), and the sentence forms of NMEA 2.x to 4.11.
//! Lines quoted whole are as the receivers sent them; the others are written from the
//! standard with [`nmea`], which adds the checksum.

use super::*;
use railfuse_catalog::messages::{FixType, GnssFix};

/// `body` with its `$` and checksum.
fn nmea(body: &str) -> String {
    format!("${body}*{:02X}", body.bytes().fold(0u8, |a, b| a ^ b))
}

/// Feeds whole lines to a fresh assembler dated `date`, then ends the stream.
fn run(lines: &[String], date: Date) -> (Vec<GnssFix>, FixAssembler) {
    let mut a = FixAssembler::with_date(Some(date));
    for line in lines {
        let s = parse(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        a.feed(&s, None).unwrap_or_else(|e| panic!("{line}: {e}"));
    }
    a.finish(None);
    let fixes = std::iter::from_fn(|| a.next_fix()).collect();
    (fixes, a)
}

fn lines(l: &[&str]) -> Vec<String> {
    l.iter().map(|s| s.to_string()).collect()
}

/// Seconds of the day of a fix stamped on `date`.
fn second_of_day(f: &GnssFix) -> f64 {
    (f.stamp_ns % 86_400_000_000_000) as f64 / 1e9
}

#[test]
fn gns_alone_is_a_fix_with_its_satellites_heights_and_mode_per_constellation() {
    // ST Teseo III sends GNS and no GGA.
    let (f, _) = run(
        &lines(&["$GNGNS,213712.000,4111.59903,N,11156.54809,W,AANN,13,0.93,01482.5,-016.5,,*52"]),
        (2019, 3, 1),
    );
    assert_eq!(f.len(), 1, "one GNS, one fix");
    let f = &f[0];
    assert_eq!(
        (f.fix_type, f.satellites, f.hdop),
        (FixType::Single, 13, Some(0.93))
    );
    assert!((f.latitude_deg.unwrap() - (41.0 + 11.59903 / 60.0)).abs() < 1e-9);
    assert!((f.longitude_deg.unwrap() + (111.0 + 56.54809 / 60.0)).abs() < 1e-9);
    assert_eq!(f.altitude_msl_m, Some(1482.5));
    assert!((f.altitude_m.unwrap() - 1466.0).abs() < 1e-9);
    assert!((second_of_day(f) - (21.0 * 3600.0 + 37.0 * 60.0 + 12.0)).abs() < 1e-9);
    // The mode of each constellation: the best of them is the fix; N, E, M, S are none.
    let gns = |mode: &str| {
        let body = format!("GNGNS,120000.00,4807.038,N,01131.000,E,{mode},10,0.9,545.4,46.9,,,S");
        run(&[nmea(&body)], (2025, 3, 1)).0[0].fix_type
    };
    for (mode, want) in [
        ("NNN", FixType::None),
        ("NAN", FixType::Single),
        ("DN", FixType::Dgps),
        ("PNN", FixType::Dgps),
        ("FAA", FixType::RtkFloat),
        ("NRN", FixType::RtkFixed),
        ("EEE", FixType::None),
        ("M", FixType::None),
        ("S", FixType::None),
    ] {
        assert_eq!(gns(mode), want, "mode {mode}");
    }
    // NMEA 4.1 navigation status U takes the position; V (no status given) does not.
    let status = |nav: &str| {
        let body = format!("GNGNS,120000.00,4807.038,N,01131.000,E,AA,10,0.9,545.4,46.9,,,{nav}");
        run(&[nmea(&body)], (2025, 3, 1)).0[0]
            .latitude_deg
            .is_some()
    };
    assert!(status("S") && status("C") && status("V") && !status("U"));
    // A mode character no standard defines is a bad field, named.
    let bad = nmea("GNGNS,120000.00,4807.038,N,01131.000,E,AX,10,0.9,545.4,46.9,,,S");
    let e = FixAssembler::default()
        .feed(&parse(&bad).unwrap(), None)
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "NMEA GNS field 6 (mode indicator) 'AX': N, A, D, P, R, F, E, M or S expected"
    );
}

#[test]
fn one_cycle_with_gga_and_gns_makes_one_fix_the_combined_talker_s() {
    // Quectel EG25-G: GPGGA (GPS satellites only) and GNGNS (all) of one epoch.
    let l = [
        nmea("GPGGA,191503.01,3645.876324,N,03124.670280,E,1,03,1.3,-6.7,M,32.0,M,,"),
        nmea("GNGNS,191503.01,3645.876324,N,03124.670280,E,AAN,08,1.3,-6.7,32.0,,,V"),
        nmea("GPVTG,300.5,T,296.9,M,1.3,N,2.3,K,A"),
        nmea("GPRMC,191503.01,A,3645.876324,N,03124.670280,E,1.3,300.5,110922,3.6,E,A,V"),
        nmea("GPGSA,A,3,13,15,17,,,,,,,,,,2.9,1.3,2.6,1"),
        nmea("GNGSA,A,3,78,69,88,87,68,,,,,,,,2.9,1.3,2.6,2"),
    ];
    let (f, _) = run(&l, (2022, 9, 11));
    assert_eq!(f.len(), 1);
    assert_eq!((f[0].fix_type, f[0].satellites), (FixType::Single, 8));
    assert!((f[0].altitude_m.unwrap() - 25.3).abs() < 1e-9);
    // VTG (2.3 km/h) then RMC (1.3 kn) of the epoch: the later sentence's speed.
    assert!((f[0].speed_mps.unwrap() - 1.3 * 1852.0 / 3600.0).abs() < 1e-12);
}

/// The Quectel EG25-G's no-fix epoch: a GNS with a time and mode NNN, everything else
/// without a time.
fn quectel_no_fix_epoch(hhmmss: &str) -> Vec<String> {
    vec![
        nmea(&format!("GNGNS,{hhmmss},,,,,NNN,,,,,,")),
        "$GPVTG,,T,,M,,N,,K,N*2C".into(),
        nmea("GPGSA,A,1,,,,,,,,,,,,,,,,"),
        nmea("GNGSA,A,1,,,,,,,,,,,,,,,,"),
        "$GPGGA,,,,,,0,,,,,,,,*66".into(),
        "$GPRMC,,V,,,,,,,,,,N*53".into(),
    ]
}

#[test]
fn the_first_fix_after_an_outage_is_not_lost_to_the_untimed_sentences_before_it() {
    let mut l = quectel_no_fix_epoch("191501.01");
    l.extend(quectel_no_fix_epoch("191502.01"));
    l.push(nmea(
        "GPGGA,191503.01,3645.876324,N,03124.670280,E,1,03,1.3,-6.7,M,32.0,M,,",
    ));
    l.push(nmea("GPGSA,A,3,13,15,17,,,,,,,,,,2.9,1.3,2.6,1"));
    let (f, _) = run(&l, (2022, 9, 11));
    let kinds: Vec<_> = f
        .iter()
        .map(|f| (second_of_day(f).round(), f.fix_type))
        .collect();
    let t = 19.0 * 3600.0 + 15.0 * 60.0;
    assert_eq!(
        kinds,
        [
            (t + 1.0, FixType::None),
            (t + 2.0, FixType::None),
            (t + 3.0, FixType::Single)
        ]
    );
    assert!(f[2].latitude_deg.is_some() && f[2].satellites == 3);

    // A receiver whose no-fix epochs carry no time at all: the fixes either side of the
    // outage both keep their positions, and the untimed epochs are counted.
    let good = |t: &str| {
        [
            nmea(&format!(
                "GPGGA,{t},3645.876324,N,03124.670280,E,1,05,1.3,-6.7,M,32.0,M,,"
            )),
            nmea(&format!(
                "GPRMC,{t},A,3645.876324,N,03124.670280,E,1.3,300.5,110922,,,A"
            )),
            nmea("GPGSA,A,3,13,15,17,19,20,,,,,,,,2.9,1.3,2.6"),
        ]
    };
    let untimed = [
        "$GPRMC,,V,,,,,,,,,,N*53".to_string(),
        "$GPGGA,,,,,,0,,,,,,,,*66".into(),
        nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
    ];
    let mut l: Vec<String> = good("191500.00").into();
    l.extend(untimed.clone());
    l.extend(untimed);
    l.extend(good("191503.00"));
    let (f, a) = run(&l, (2022, 9, 11));
    assert_eq!(f.len(), 2, "{f:?}");
    assert!(f
        .iter()
        .all(|f| f.fix_type == FixType::Single && f.latitude_deg.is_some()));
    assert_eq!(a.untimed, 2);
    // Before any timed sentence too (a capture that starts in an outage).
    let mut l = vec![
        nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
        "$GPGGA,,,,,,0,,,,,,,,*66".into(),
    ];
    l.extend(good("191503.00"));
    let (f, a) = run(&l, (2022, 9, 11));
    assert_eq!((f.len(), f[0].fix_type, a.untimed), (1, FixType::Single, 1));
}

#[test]
fn a_gsa_sent_before_its_gga_does_not_take_the_fix_of_the_epoch_before() {
    // Receivers that send GSA first: the GSA of the epoch that lost the fix arrives while
    // the last good epoch's cycle is open (gpsd places it there too). That cycle's own GSA
    // says there is a fix, so its fix stands; the next epoch has none.
    let epoch = |t: &str, mode: u8, quality: u8| {
        [
            nmea(&format!(
                "GPGSA,A,{mode},01,02,03,04,05,06,,,,,,,1.5,0.9,1.2"
            )),
            nmea(&format!(
                "GPGGA,{t},4807.038,N,01131.000,E,{quality},06,0.9,545.4,M,46.9,M,,"
            )),
        ]
    };
    let mut l: Vec<String> = epoch("120000.00", 3, 1).into();
    l.extend(epoch("120001.00", 1, 0));
    let (f, _) = run(&l, (2025, 3, 1));
    let types: Vec<FixType> = f.iter().map(|f| f.fix_type).collect();
    assert_eq!(types, [FixType::Single, FixType::None]);
    // Where every GSA of the cycle says no fix, the GGA's position is not used (gpsd).
    let l = [
        nmea("GPGGA,120000.00,4807.038,N,01131.000,E,1,06,0.9,545.4,M,46.9,M,,"),
        nmea("GPGSA,A,1,,,,,,,,,,,,,,,"),
    ];
    assert_eq!(run(&l, (2025, 3, 1)).0[0].fix_type, FixType::None);
}

#[test]
fn junk_before_the_last_dollar_is_skipped_and_the_sentence_decoded() {
    // ST Teseo LIV4F: every line starts `$$`.
    let rmc = nmea("GNRMC,135806.000,A,4723.00484,N,00045.88150,E,0.5,120.9,210325,,,A,C");
    let gga = nmea("GNGGA,135806.000,4723.00484,N,00045.88150,E,1,13,1.7,063.64,M,48.3,M,,");
    let teseo = format!("${rmc}");
    let s = parse(&teseo).unwrap();
    assert_eq!((s.kind, s.junk), ("RMC", 1));
    // Half a sentence before the next, as a serial link that reconnects leaves it.
    let cut = format!("4807.038,N,01131.0{gga}\r\n");
    let s = parse(&cut).unwrap();
    assert_eq!((s.kind, s.junk), ("GGA", 18));
    assert_eq!(parse("no sentence here"), Err(NmeaError::NotASentence));
    let (f, _) = run(&[format!("${rmc}"), format!("${gga}")], (2025, 3, 21));
    assert_eq!((f.len(), f[0].satellites), (1, 13));
    assert!(f[0].speed_mps.is_some() && f[0].latitude_deg.is_some());
}

#[test]
fn several_talkers_in_one_cycle_count_every_constellation() {
    // SiRFstarV: GPGGA counts GPS satellites, GLGGA GLONASS; GNGSA lists both.
    let sirf = [
        nmea("GPGGA,020935.000,4404.1351,N,12118.8556,W,1,08,0.9,1123.9,M,-19.6,M,,0000"),
        nmea("GLGGA,020935.000,4404.1351,N,12118.8556,W,1,02,0.9,1123.9,M,-19.6,M,,0000"),
        nmea("GNGSA,A,3,15,17,30,28,01,19,24,11,,,,,1.8,0.9,1.5"),
        nmea("GNGSA,A,3,73,82,,,,,,,,,,,1.8,0.9,1.5"),
        nmea("GNRMC,020935.000,A,4404.1351,N,12118.8556,W,0.04,359.11,050219,,,A"),
    ];
    let (f, _) = run(&sirf, (2019, 2, 5));
    assert_eq!(
        (f.len(), f[0].satellites, f[0].fix_type),
        (1, 10, FixType::Single)
    );
    // Without GSA, the talkers' counts are added.
    let (f, _) = run(&sirf[..2], (2019, 2, 5));
    assert_eq!(f[0].satellites, 10);
    // Telit PLS83-W: GPGGA 5, GAGGA 1, and a GNGNS with the 14 of every constellation.
    let telit = [
        nmea("GPGGA,043539.00,4333.190206,N,00127.618380,E,1,05,1.3,250.8,M,50.0,M,,"),
        nmea("GAGGA,043539.00,4333.190206,N,00127.618380,E,1,01,1.3,250.8,M,50.0,M,,"),
        nmea("GNGNS,043539.00,4333.190206,N,00127.618380,E,AAAAN,14,1.3,250.8,50.0,,,V"),
        nmea("GPRMC,043539.00,A,4333.190206,N,00127.618380,E,0.0,,040925,1.7,W,A,V"),
        nmea("GARMC,043539.00,A,4333.190206,N,00127.618380,E,0.0,,040925,1.7,W,A,V"),
        nmea("GNGSA,A,2,02,08,10,23,27,,,,,,,,1.6,1.3,0.9,1"),
        nmea("GNGSA,A,2,65,66,73,81,82,,,,,,,,1.6,1.3,0.9,2"),
        nmea("GNGSA,A,2,33,,,,,,,,,,,,1.6,1.3,0.9,3"),
        nmea("GNGSA,A,2,208,211,213,,,,,,,,,,1.6,1.3,0.9,4"),
    ];
    let (f, _) = run(&telit, (2025, 9, 4));
    assert_eq!((f.len(), f[0].satellites), (1, 14));
    // Without the GNS, the GSAs' distinct satellites (system id and PRN): 5 + 5 + 1 + 3.
    let no_gns: Vec<String> = telit
        .iter()
        .filter(|l| !l.contains("GNS"))
        .cloned()
        .collect();
    assert_eq!(run(&no_gns, (2025, 9, 4)).0[0].satellites, 14);
    // The best talker's position: a GP RTK fix beats a GL single one.
    let best = [
        nmea("GLGGA,120000.00,4807.000,N,01131.000,E,1,04,0.9,545.4,M,46.9,M,,"),
        nmea("GPGGA,120000.00,4807.038,N,01131.000,E,4,09,0.9,545.4,M,46.9,M,,"),
    ];
    let (f, _) = run(&best, (2025, 3, 1));
    assert_eq!((f[0].fix_type, f[0].satellites), (FixType::RtkFixed, 13));
    assert!((f[0].latitude_deg.unwrap() - (48.0 + 7.038 / 60.0)).abs() < 1e-9);
}

#[test]
fn rmc_and_gll_alone_make_fixes_and_vtg_reads_every_form() {
    // RMC with the NMEA 2.3 mode and the 4.1 navigation status; a receiver sending RMC only.
    let rmc = |mode_status: &str| {
        let body =
            format!("GPRMC,120000.00,A,4807.038,N,01131.000,E,10.0,45.0,010325,,,{mode_status}");
        run(&[nmea(&body)], (2025, 3, 1)).0[0].clone()
    };
    assert_eq!(rmc("D,S").fix_type, FixType::Dgps);
    assert_eq!(rmc("R,V").fix_type, FixType::RtkFixed);
    assert!(
        rmc("A,U").latitude_deg.is_none(),
        "navigation status U: unsafe"
    );
    assert!(rmc("N,V").speed_mps.is_none());
    assert!((rmc("A").speed_mps.unwrap() - 10.0 * 1852.0 / 3600.0).abs() < 1e-12);
    // GLL: position, time, status and mode.
    let (f, _) = run(
        &[nmea("GPGLL,4916.45,N,12311.12,W,225444.00,A,A")],
        (2025, 3, 1),
    );
    assert_eq!((f[0].fix_type, f[0].satellites), (FixType::Single, 0));
    assert!((f[0].latitude_deg.unwrap() - (49.0 + 16.45 / 60.0)).abs() < 1e-9);
    let (f, _) = run(
        &[nmea("GPGLL,4916.45,N,12311.12,W,225444.00,V,N")],
        (2025, 3, 1),
    );
    assert_eq!((f[0].fix_type, f[0].latitude_deg), (FixType::None, None));
    // Beside a GGA, RMC and GLL give no position of their own: the GGA's quality decides.
    let (f, _) = run(
        &[
            nmea("GPRMC,120000.00,A,4807.038,N,01131.000,E,10.0,45.0,010325,,,A"),
            nmea("GPGGA,120000.00,4807.038,N,01131.000,E,6,08,0.9,545.4,M,46.9,M,,"),
        ],
        (2025, 3, 1),
    );
    assert_eq!((f.len(), f[0].fix_type), (1, FixType::None));
    // VTG: NMEA 2.3 with its mode, 2.0 without, and before 2.0 with no unit letters.
    let vtg = |body: &str| {
        let gga = nmea("GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        let f = run(&[gga, nmea(body)], (2025, 3, 1)).0;
        (
            f[0].speed_mps.map(|v| (v * 3.6 * 1e6).round() / 1e6),
            f[0].course_rad.map(f64::to_degrees),
        )
    };
    assert_eq!(vtg("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A").0, Some(10.2));
    assert_eq!(vtg("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K").0, Some(10.2));
    assert_eq!(vtg("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,N"), (None, None));
    let old = vtg("GPVTG,054.7,034.4,005.5,010.2");
    assert_eq!(old.0, Some(10.2));
    assert!((old.1.unwrap() - 54.7).abs() < 1e-9);
}
