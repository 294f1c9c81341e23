use super::*;

fn point(k: u64) -> ExportPoint {
    ExportPoint {
        stamp_ns: 1_627_274_401_250_000_000 + k * 100_000_000,
        geo: FusedGeodetic {
            latitude_deg: 55.7 + k as f64 * 1e-5,
            longitude_deg: 12.5,
            altitude_m: 10.0,
            covariance_enu_m2: [4.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            covariance_type: 3,
            heading_rad: Some(-0.5),
        },
        chainage_m: 100.0 + k as f64,
        speed_mps: 10.0,
        speed_sigma_mps: 0.1,
    }
}

fn write(format: ExportFormat, pipelines: &[&str], n: u64) -> String {
    let mut out = Vec::new();
    {
        let mut w = format.writer(Box::new(&mut out));
        for p in pipelines {
            w.begin(p).unwrap();
            for k in 0..n {
                w.point(&point(k)).unwrap();
            }
            w.end().unwrap();
        }
        w.finish().unwrap();
    }
    String::from_utf8(out).unwrap()
}

#[test]
fn uncertainty_is_the_covariances_own() {
    let p = point(0);
    assert_eq!((p.sigma_east_m(), p.sigma_north_m()), (2.0, 1.0));
    // Eigenvalues of [[4, 1], [1, 1]]: 2.5 ± √3.25.
    assert!((p.sigma_major_m() - (2.5 + 3.25f64.sqrt()).sqrt()).abs() < 1e-12);
    assert_eq!(p.time(), "2021-07-26T04:40:01.250Z");
}

#[test]
fn geojson_is_one_valid_feature_collection_even_empty() {
    let text = write(ExportFormat::GeoJson, &["kalman", "gnss \"ins\""], 3);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let features = v["features"].as_array().unwrap();
    assert_eq!(features.len(), 6);
    assert_eq!(features[4]["properties"]["pipeline"], "gnss \"ins\"");
    assert_eq!(features[0]["geometry"]["coordinates"][0], 12.5);
    let empty: serde_json::Value =
        serde_json::from_str(&write(ExportFormat::GeoJson, &[], 0)).unwrap();
    assert_eq!(empty["features"].as_array().unwrap().len(), 0);
}

#[test]
fn kml_lists_times_then_coordinates_then_arrays_per_pipeline() {
    let text = write(ExportFormat::Kml, &["a<b", "c"], 2);
    assert_eq!(text.matches("<gx:Track>").count(), 2);
    assert!(text.contains("<name>a&lt;b</name>"));
    let track = &text[text.find("<gx:Track>").unwrap()..text.find("</gx:Track>").unwrap()];
    let (last_when, first_coord) = (
        track.rfind("<when>").unwrap(),
        track.find("<gx:coord>").unwrap(),
    );
    assert!(last_when < first_coord);
    assert_eq!(track.matches("<gx:value>").count(), 2 * 5);
}

#[test]
fn gpx_reads_back_through_the_gpx_reader() {
    let text = write(ExportFormat::Gpx, &["kalman"], 4);
    let mut r = crate::formats::gpx::GpxReader::new(text.as_bytes(), Path::new("x.gpx"));
    let mut fixes = Vec::new();
    while let Some(p) = r.next_point().unwrap() {
        fixes.push(p.to_fix(&Default::default()).unwrap());
    }
    assert_eq!(fixes.len(), 4);
    assert_eq!(fixes[1].stamp_ns, point(1).stamp_ns);
    assert_eq!(fixes[0].speed_mps, Some(10.0));
    assert!((fixes[3].latitude_deg.unwrap() - point(3).geo.latitude_deg).abs() < 1e-9);
}
