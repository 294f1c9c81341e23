//! The fitted line as the files `track =` and `--track` read: a GeoJSON `LineString` with
//! each vertex's chainage, or a CSV of latitude, longitude and chainage; with what the fit
//! says about itself in the GeoJSON feature's `railfuse_track` property.

use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::messages::TrackVertex;
use serde::Serialize;
use serde_json::json;

use crate::chainage::Placement;
use crate::fit::FitOptions;
use crate::multipath::SetAside;
use crate::osm::OsmOffset;
use crate::report::{Centreline, Disagreement, Excursion, Gap, RunReport, StretchResidual};

/// What a fit says about itself, chainage placed.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub runs: Vec<RunSummary>,
    pub fix_quality: String,
    pub fixes_used: usize,
    pub length_m: f64,
    pub vertices: usize,
    pub lateral_residual_rms_m: f64,
    pub lateral_residual_p95_m: f64,
    /// Stretches with no fix, crossed by runs' motion or bridged by the spline alone.
    pub gaps: Vec<Gap>,
    /// Stretches whose fixes the runs' motion contradicted (a steady multipath pull), set
    /// aside and crossed by that motion.
    pub set_aside: Vec<SetAside>,
    /// The residual across the track over each stretch with fixes.
    pub stretches: Vec<StretchResidual>,
    /// Stretches where runs' mean offsets differ by more than `disagreement_m`.
    pub runs_disagree: Vec<Disagreement>,
    pub placement: Placement,
    /// The height profile: fitted from the fixes' heights, or why the line is flat.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub profile: Option<crate::profile::Profile>,
    /// The cant: fitted from the runs' IMU roll, or why the line has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cant: Option<crate::cant::Cant>,
    /// The line against OpenStreetMap's rail ways, where an extract was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub osm: Option<OsmOffset>,
    pub knot_spacing_m: f64,
    pub smoothing_m: f64,
    pub tolerance_m: f64,
    pub disagreement_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    pub name: String,
    pub fixes: usize,
    pub used: usize,
    pub set_aside: usize,
    pub off_line: usize,
    /// Which way it travels along the placed chainage.
    pub direction: &'static str,
    pub lateral_rms_m: f64,
    pub leaves_line: Vec<Excursion>,
    /// What taking its antenna's lean in canted curves out of its fixes did.
    pub antenna_lean: Option<crate::motion::Lean>,
    /// The antenna's height above the rail when the run had no IMU to take its lean out
    /// with, m (its fixes keep the lean).
    pub antenna_lean_kept_m: Option<f64>,
}

impl Summary {
    pub fn new(
        c: &Centreline,
        p: &Placement,
        vertices: &[TrackVertex],
        quality: String,
        opts: &FitOptions,
        tolerance_m: f64,
    ) -> Self {
        Self {
            runs: c.runs.iter().map(|r| RunSummary::new(r, p)).collect(),
            fix_quality: quality,
            fixes_used: c.fixes_used,
            length_m: c.line.end_m() - c.line.start_m(),
            vertices: vertices.len(),
            lateral_residual_rms_m: c.lateral_rms_m,
            lateral_residual_p95_m: c.lateral_p95_m,
            gaps: c
                .gaps
                .iter()
                .map(|g| {
                    let (from_m, to_m) = p.span(g.from_m, g.to_m);
                    Gap { from_m, to_m, ..*g }
                })
                .collect(),
            set_aside: c
                .set_aside
                .iter()
                .map(|a| {
                    let (from_m, to_m) = p.span(a.from_m, a.to_m);
                    SetAside { from_m, to_m, ..*a }
                })
                .collect(),
            stretches: c
                .stretches
                .iter()
                .map(|r| {
                    let (from_m, to_m) = p.span(r.from_m, r.to_m);
                    StretchResidual { from_m, to_m, ..*r }
                })
                .collect(),
            runs_disagree: c
                .disagreements
                .iter()
                .map(|d| {
                    let (from_m, to_m) = p.span(d.from_m, d.to_m);
                    Disagreement {
                        from_m,
                        to_m,
                        spread_m: d.spread_m,
                    }
                })
                .collect(),
            placement: *p,
            osm: None,
            profile: c.profile.clone().map(|q| q.placed(|s| p.chainage(s))),
            cant: c.cant.clone().map(|q| q.placed(|s| p.chainage(s))),
            knot_spacing_m: opts.knot_spacing_m,
            smoothing_m: opts.smoothing_m,
            tolerance_m,
            disagreement_m: opts.disagreement_m,
        }
    }
}

impl RunSummary {
    /// A run's report with its chainages placed.
    fn new(r: &RunReport, p: &Placement) -> Self {
        let at = |x: Option<f64>| x.map(|s| p.chainage(s));
        Self {
            name: r.name.clone(),
            fixes: r.fixes,
            used: r.used,
            set_aside: r.set_aside,
            off_line: r.off_line,
            direction: match r.increasing == (p.direction > 0.0) {
                true => "increasing",
                false => "decreasing",
            },
            lateral_rms_m: r.lateral_rms_m,
            leaves_line: r
                .leaves_line
                .iter()
                .map(|e| Excursion {
                    from_m: at(e.from_m),
                    to_m: at(e.to_m),
                    ..e.clone()
                })
                .collect(),
            antenna_lean: r.antenna_lean,
            antenna_lean_kept_m: r.antenna_lean_kept_m,
        }
    }
}

/// Longitude, latitude (degrees) and, where the vertex has a height, its ellipsoidal
/// height (m) of each vertex.
fn lon_lat(vertices: &[TrackVertex], origin: &GeodeticOrigin) -> Vec<(f64, f64, Option<f64>)> {
    vertices
        .iter()
        .map(|v| {
            let up = v.height_m.unwrap_or(0.0);
            let (lat, lon, alt) = origin.to_geodetic(v.east_m, v.north_m, up);
            (lon, lat, v.height_m.map(|_| round_mm(alt)))
        })
        .collect()
}

/// The line as a GeoJSON feature collection of one main line.
pub fn geojson(
    name: &str,
    vertices: &[TrackVertex],
    origin: &GeodeticOrigin,
    summary: &Summary,
) -> String {
    // A profile's heights are the coordinates' third value, on every vertex.
    let coordinates: Vec<Vec<f64>> = lon_lat(vertices, origin)
        .into_iter()
        .map(|(lon, lat, alt)| [lon, lat].into_iter().chain(alt).collect())
        .collect();
    let chainage: Vec<f64> = vertices.iter().map(|v| round_mm(v.chainage_m)).collect();
    let mut properties = json!({
        "name": name,
        "role": "main",
        "chainage_m": chainage,
        "railfuse_track": summary,
    });
    if let Some(cant) = cant_mm(vertices) {
        properties["cant_mm"] = cant.into();
    }
    let collection = json!({
        "type": "FeatureCollection",
        "features": [{
            "type": "Feature",
            "properties": properties,
            "geometry": { "type": "LineString", "coordinates": coordinates },
        }],
    });
    serde_json::to_string_pretty(&collection).expect("a summary serialises")
}

/// Every vertex's cant in mm, where every vertex has one.
fn cant_mm(vertices: &[TrackVertex]) -> Option<Vec<f64>> {
    let cant: Option<Vec<f64>> = vertices
        .iter()
        .map(|v| v.cant_m.map(|c| (c * 1e3).round()))
        .collect();
    cant.filter(|c| !c.is_empty())
}

/// The line as a CSV of latitude, longitude and chainage (and altitude and cant where the
/// line has them), one vertex a row.
pub fn csv(vertices: &[TrackVertex], origin: &GeodeticOrigin) -> String {
    let heights = vertices.iter().all(|v| v.height_m.is_some()) && !vertices.is_empty();
    let cant = cant_mm(vertices);
    let mut out = String::from("latitude,longitude,chainage_m");
    if heights {
        out.push_str(",altitude_m");
    }
    if cant.is_some() {
        out.push_str(",cant_mm");
    }
    out.push('\n');
    for (k, (v, (lon, lat, alt))) in vertices.iter().zip(lon_lat(vertices, origin)).enumerate() {
        out.push_str(&format!("{lat:.10},{lon:.10},{:.3}", v.chainage_m));
        if let (true, Some(alt)) = (heights, alt) {
            out.push_str(&format!(",{alt:.3}"));
        }
        if let Some(c) = &cant {
            out.push_str(&format!(",{:.0}", c[k]));
        }
        out.push('\n');
    }
    out
}

fn round_mm(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}
