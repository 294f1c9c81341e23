use super::*;

fn points(xml: &str) -> Result<(Vec<Point>, GpxReader<&[u8]>)> {
    let mut r = GpxReader::new(xml.as_bytes(), Path::new("t.gpx"));
    let mut out = Vec::new();
    while let Some(p) = r.next_point()? {
        out.push(p);
    }
    Ok((out, r))
}

const PHONE: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.0" creator="GPSLogger" xmlns="http://www.topografix.com/GPX/1/0">
<trk><trkseg>
<trkpt lat="47.3769" lon="8.5417"><ele>408.2</ele><time>2021-07-01T10:54:23+02:00</time><course>90.0</course><speed>0.87</speed><sat>9</sat><hdop>14.2</hdop></trkpt>
<trkpt lat="47.3770" lon="8.5418"><ele>408.5</ele><time>2021-07-01T08:54:24.5Z</time><hdop>12.0</hdop><fix>dgps</fix></trkpt>
</trkseg><trkseg>
<trkpt lat="47.3771" lon="8.5419"><time>2021-07-01T08:54:30</time></trkpt>
</trkseg></trk></gpx>"#;

#[test]
fn a_phones_gpx_1_0_track_reads_with_its_zone_speed_course_and_segments() {
    let (p, r) = points(PHONE).unwrap();
    assert_eq!(p.len(), 3);
    assert_eq!(r.version.as_deref(), Some("1.0"));
    assert_eq!(r.breaks, 1);
    assert_eq!((p[0].segment, p[2].segment), (1, 2));
    let f = p[0].to_fix(&GpxOptions::default()).unwrap();
    // 10:54:23+02:00 is 08:54:23 UTC.
    assert_eq!(f.stamp_ns, 1_625_129_663_000_000_000);
    assert_eq!(f.satellites, 9);
    assert_eq!(f.hdop, Some(14.2));
    assert_eq!(f.speed_mps, Some(0.87));
    assert!((f.course_rad.unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!((f.altitude_msl_m, f.altitude_m), (Some(408.2), None));
    assert_eq!(f.position_covariance_enu_m2, None);
    let g = p[1].to_fix(&GpxOptions::default()).unwrap();
    assert_eq!(g.stamp_ns, 1_625_129_664_500_000_000);
    assert_eq!(g.fix_type, FixType::Dgps);
    // No zone: UTC, as GPX says.
    let h = p[2].to_fix(&GpxOptions::default()).unwrap();
    assert_eq!(h.stamp_ns, 1_625_129_670_000_000_000);
}

#[test]
fn hdop_as_metres_is_a_68_percent_radius_made_a_sigma() {
    let (p, _) = points(PHONE).unwrap();
    let options = GpxOptions {
        hdop: "metres".parse().unwrap(),
        elevation: Elevation::Ellipsoid,
    };
    let f = p[0].to_fix(&options).unwrap();
    assert_eq!(f.hdop, None);
    let c = f.position_covariance_enu_m2.unwrap();
    // σ = 14.2 / √(−2 ln 0.32) = 9.406 m; vertical twice that without a vdop.
    let sigma = 14.2 / (-2.0 * 0.32f64.ln()).sqrt();
    assert!((c[0].sqrt() - sigma).abs() < 1e-9 && (sigma - 9.406).abs() < 1e-3);
    assert_eq!(c[0], c[4]);
    assert!((c[8].sqrt() - 2.0 * sigma).abs() < 1e-9);
    assert_eq!(f.altitude_m, Some(408.2));
    assert!((accuracy::normal_quantile(0.975) - 1.959964).abs() < 1e-6);
    assert!("metres:150".parse::<HdopMeaning>().is_err());
}

#[test]
fn garmins_extensions_give_speed_and_course_in_gpx_1_1() {
    let xml = r#"<gpx version="1.1" creator="Garmin" xmlns="http://www.topografix.com/GPX/1/1"
      xmlns:gpxtpx="http://www.garmin.com/xmlschemas/TrackPointExtension/v2">
      <rte><rtept lat="1" lon="2"><time>2020-01-01T00:00:00Z</time>
        <extensions><gpxtpx:TrackPointExtension><gpxtpx:speed>12.5</gpxtpx:speed>
        <gpxtpx:course>370</gpxtpx:course></gpxtpx:TrackPointExtension></extensions>
      </rtept></rte></gpx>"#;
    let (p, _) = points(xml).unwrap();
    let f = p[0].to_fix(&GpxOptions::default()).unwrap();
    assert_eq!(f.speed_mps, Some(12.5));
    assert!((f.course_rad.unwrap() - 10f64.to_radians()).abs() < 1e-12);
}

#[test]
fn an_entity_bomb_is_refused_before_anything_is_expanded() {
    let bomb = r#"<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;">]>
<gpx version="1.1"><trk><name>&lol2;</name></trk></gpx>"#;
    let e = points(bomb).err().unwrap().to_string();
    assert!(
        e.contains("t.gpx: line 2: the document type declares entities"),
        "{e}"
    );
    // An undeclared entity is named.
    let e = points(r#"<gpx><trk><name>&x;</name></trk></gpx>"#)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("entity &x; is not defined"), "{e}");
}

#[test]
fn xml_that_is_not_gpx_and_markup_free_floods_are_refused() {
    let e = points("<kml><Document/></kml>").err().unwrap().to_string();
    assert!(e.contains("the document is <kml>, not <gpx>"), "{e}");
    let flood = format!(
        "<gpx><trk><name>{}</name></trk></gpx>",
        "a".repeat(MAX_EVENT + 10)
    );
    let e = points(&flood).err().unwrap().to_string();
    assert!(e.contains("without markup"), "{e}");
}

#[test]
fn a_cut_off_document_keeps_the_points_before_the_cut() {
    let cut = &PHONE[..PHONE.find("</trkseg><trkseg>").unwrap()];
    let (p, r) = points(cut).unwrap();
    assert_eq!(p.len(), 2);
    assert!(
        r.damage.as_deref().unwrap().contains("cut off"),
        "{:?}",
        r.damage
    );
}

#[test]
fn points_without_time_or_with_a_bad_number_are_unusable_with_a_reason() {
    let xml = r#"<gpx><trk><trkseg><trkpt lat="1" lon="2"/>
      <trkpt lat="1" lon="2"><time>2020-01-01T00:00:00Z</time><hdop>x</hdop></trkpt>
      <trkpt lat="100" lon="2"><time>2020-01-01T00:00:01Z</time></trkpt>
      <trkpt lat="1" lon="2"><time>yesterday</time></trkpt></trkseg></trk></gpx>"#;
    let (p, _) = points(xml).unwrap();
    let why: Vec<&str> = p
        .iter()
        .map(|p| p.to_fix(&GpxOptions::default()).unwrap_err().reason)
        .collect();
    assert_eq!(
        why,
        [
            "a point without <time>",
            "a field that does not read",
            "lat/lon missing or off the globe",
            "a <time> that does not read"
        ]
    );
}
