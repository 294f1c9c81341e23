//! The plan view's static furniture: the track with a chainage mark every kilometre, balises,
//! stations, tunnels, and a legend drawn into the map's top-left corner (a 2-D view has no
//! legend of its own).

use railfuse_catalog::messages::TrackMap;
use rerun::{Color, LineStrips2D, Points2D, Radius, RecordingStream};

use crate::{entities as ent, palette, Error};

/// Plan-view point: Rerun's 2-D view grows y downwards, so north is negated to show it up.
pub fn plan(east: f64, north: f64) -> [f32; 2] {
    [east as f32, -north as f32]
}

/// The plan-view point at a chainage.
pub fn at(map: &TrackMap, chainage_m: f64) -> Option<[f32; 2]> {
    map.locate(chainage_m).map(|(e, n, _)| plan(e, n))
}

/// The track between two chainages as a polyline (its vertices in between included).
pub fn stretch(map: &TrackMap, from_m: f64, to_m: f64) -> Vec<[f32; 2]> {
    let inner = map
        .vertices
        .iter()
        .filter(|v| v.chainage_m > from_m && v.chainage_m < to_m)
        .map(|v| plan(v.east_m, v.north_m));
    at(map, from_m)
        .into_iter()
        .chain(inner)
        .chain(at(map, to_m))
        .collect()
}

fn log_static(
    rec: &RecordingStream,
    entity: &str,
    data: &dyn rerun::AsComponents,
) -> Result<(), Error> {
    rec.log_static(entity, data)
        .map_err(|e| Error::Rerun(e.to_string()))
}

/// Logs the track and its furniture (static: they hold at every time).
pub fn log_track_map(rec: &RecordingStream, map: &TrackMap) -> Result<Vec<&'static str>, Error> {
    let strip: Vec<[f32; 2]> = map
        .vertices
        .iter()
        .map(|v| plan(v.east_m, v.north_m))
        .collect();
    log_static(
        rec,
        ent::TRACK,
        &LineStrips2D::new([strip])
            .with_colors([palette::track()])
            .with_radii([Radius::new_ui_points(1.5)]),
    )?;
    let mut logged = vec![ent::TRACK];
    if let Some(marks) = km_marks(map) {
        log_static(rec, ent::KM_MARKS, &marks)?;
        logged.push(ent::KM_MARKS);
    }
    if let Some(tunnels) = tunnel_strips(map) {
        log_static(rec, ent::TUNNELS, &tunnels)?;
        logged.push(ent::TUNNELS);
    }
    // Balise ids would crowd the plan view: they show on hover.
    let (balises, ids): (Vec<_>, Vec<_>) = map
        .balises
        .iter()
        .filter_map(|b| at(map, b.chainage_m).map(|p| (p, b.balise_id.clone())))
        .unzip();
    log_static(
        rec,
        ent::BALISES,
        &Points2D::new(balises)
            .with_colors([palette::balise()])
            .with_radii([Radius::new_ui_points(3.0)])
            .with_show_labels(false)
            .with_labels(ids),
    )?;
    let (stations, names): (Vec<_>, Vec<_>) = map
        .stations
        .iter()
        .filter_map(|s| at(map, s.chainage_m).map(|p| (p, s.name.clone())))
        .unzip();
    log_static(
        rec,
        ent::STATIONS,
        &Points2D::new(stations)
            .with_labels(names)
            .with_colors([palette::station()])
            .with_radii([Radius::new_ui_points(6.0)]),
    )?;
    logged.extend([ent::BALISES, ent::STATIONS]);
    Ok(logged)
}

/// A mark every km along the line; labels on a round step that leaves about a dozen, so they
/// do not overlap when the whole line is in view.
fn km_marks(map: &TrackMap) -> Option<Points2D> {
    let (first, last) = (map.vertices.first()?, map.vertices.last()?);
    let km = (first.chainage_m / 1000.0).ceil() as i64..=(last.chainage_m / 1000.0).floor() as i64;
    let length_km = (last.chainage_m - first.chainage_m) / 1000.0;
    let every = [1, 2, 5, 10, 20, 50, 100]
        .into_iter()
        .find(|&k| length_km / k as f64 <= 12.0)
        .unwrap_or(200);
    let (marks, labels): (Vec<_>, Vec<_>) = km
        .filter_map(|k| {
            let label = if k % every == 0 {
                format!("km {k}")
            } else {
                String::new()
            };
            at(map, k as f64 * 1000.0).map(|p| (p, label))
        })
        .unzip();
    Some(
        Points2D::new(marks)
            .with_labels(labels)
            .with_colors([palette::km_mark()])
            .with_radii([Radius::new_ui_points(2.5)]),
    )
}

/// Each tunnel as a wide stretch of track, named.
fn tunnel_strips(map: &TrackMap) -> Option<LineStrips2D> {
    if map.tunnels.is_empty() {
        return None;
    }
    let strips = map
        .tunnels
        .iter()
        .map(|t| stretch(map, t.start_chainage_m, t.end_chainage_m));
    let names = map.tunnels.iter().map(|t| format!("tunnel {}", t.name));
    Some(
        LineStrips2D::new(strips)
            .with_labels(names)
            .with_colors([palette::tunnel()])
            .with_radii([Radius::new_ui_points(5.0)]),
    )
}

/// The legend: a labelled dot per entry, stacked above the top-left corner of `bounds` (min
/// and max plan-view corners), clear of the track.
pub fn log_legend(
    rec: &RecordingStream,
    bounds: ([f32; 2], [f32; 2]),
    entries: &[(String, Color)],
) -> Result<(), Error> {
    let ([x0, y0], [x1, y1]) = bounds;
    let step = ((x1 - x0).max(y1 - y0) * 0.035).max(1.0);
    let (points, (labels, colors)): (Vec<_>, (Vec<_>, Vec<_>)) = entries
        .iter()
        .enumerate()
        .map(|(i, (label, color))| {
            let row = (entries.len() - i) as f32 + 0.5;
            ([x0, y0 - step * row], (label.clone(), *color))
        })
        .unzip();
    log_static(
        rec,
        ent::LEGEND,
        &Points2D::new(points)
            .with_labels(labels)
            .with_colors(colors)
            .with_radii([Radius::new_ui_points(5.0)]),
    )
}

/// The plan-view bounding box of the track.
pub fn bounds(map: &TrackMap) -> Option<([f32; 2], [f32; 2])> {
    let mut pts = map.vertices.iter().map(|v| plan(v.east_m, v.north_m));
    let first = pts.next()?;
    Some(pts.fold((first, first), |(lo, hi), p| {
        (
            [lo[0].min(p[0]), lo[1].min(p[1])],
            [hi[0].max(p[0]), hi[1].max(p[1])],
        )
    }))
}
