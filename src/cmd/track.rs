use std::path::PathBuf;

use anyhow::{Context, Result};
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::messages::TrackVertex;
use railfuse_catalog::run::{Run, RunOptions};
use railfuse_eval::FixQuality;
use railfuse_track::chainage::{self, Post};
use railfuse_track::fit::{self, FitOptions};
use railfuse_track::fixes::{read_fixes, RunFixes};
use railfuse_track::line::Line;
use railfuse_track::osm;
use railfuse_track::output::{self, Summary};

use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The runs over the line, each a file, a directory of its parts or a ROS 2 bag
    /// directory. The first sets chainage's origin and direction unless --origin or
    /// --chainage-at does.
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// The line: GeoJSON (a LineString with each vertex's chainage and what the fit says
    /// about itself), or CSV where the name ends in .csv.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the line as a CSV of latitude, longitude and chainage_m.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// The channel the line comes from: a GNSS channel, or a 2-D pipeline's fused states
    /// (`/fused/<pipeline>/state`, e.g. gnss_ins: positions that hold through the fixes'
    /// gaps). Default: the run's one GNSS channel, else its one fused channel with positions.
    #[arg(long)]
    pub topic: Option<String>,
    /// Which fixes count: auto (RTK fixed where a run has any, else all), all, or fix types
    /// (rtk_fixed, rtk_float, dgps, single; commas between several).
    #[arg(long, default_value = "auto")]
    pub quality: FixQuality,
    /// Chainage 0 at the place on the line nearest this point (LAT,LON in degrees).
    #[arg(long, value_name = "LAT,LON")]
    pub origin: Option<String>,
    /// The chainage (km) of the place on the line nearest a point, e.g. a kilometre post:
    /// LAT,LON=KM. Twice: the two posts also set the direction.
    #[arg(long, value_name = "LAT,LON=KM")]
    pub chainage_at: Vec<String>,
    #[command(flatten)]
    pub formats: super::run_input::FormatArgs,
    /// The line's name in the file.
    #[arg(long)]
    pub name: Option<String>,
    /// The residual across the track (RMS, m) every 500 m stretch must keep: where the fit
    /// cannot, it says where and fails.
    #[arg(long, default_value_t = 0.10)]
    pub tolerance: f64,
    /// Length the spline smooths over, m.
    #[arg(long, default_value_t = 10.0)]
    pub smoothing: f64,
    /// An OpenStreetMap extract (.osm XML, or GeoJSON as overpass-turbo exports it): the
    /// fitted line is checked against its railway=rail ways and their offset reported.
    #[arg(long, value_name = "FILE")]
    pub osm: Option<PathBuf>,
    /// Bridge the stretches without fixes with the spline alone, not with each run's own
    /// motion (its IMU's turn and its odometer's distance, tied to its fixes either side).
    #[arg(long)]
    pub no_motion: bool,
    /// Print what the fit says about itself as JSON.
    #[arg(long)]
    pub json: bool,
}

/// `LAT,LON` in degrees.
fn lat_lon(text: &str, what: &str) -> Result<(f64, f64)> {
    let parsed = text.split_once(',').and_then(|(a, b)| {
        let (lat, lon) = (a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?);
        ((-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon)).then_some((lat, lon))
    });
    parsed.with_context(|| {
        format!("{what} '{text}': a place is LAT,LON in degrees (latitude within ±90°, longitude within ±180°)")
    })
}

/// The posts given, as (latitude, longitude, chainage m, label).
fn posts(a: &Args) -> Result<Vec<(f64, f64, f64, String)>> {
    let mut out = Vec::new();
    if let Some(o) = &a.origin {
        let (lat, lon) = lat_lon(o, "--origin")?;
        out.push((lat, lon, 0.0, format!("--origin {o}")));
    }
    for p in &a.chainage_at {
        let (place, km) = p
            .rsplit_once('=')
            .with_context(|| format!("--chainage-at '{p}': LAT,LON=KM"))?;
        let (lat, lon) = lat_lon(place, "--chainage-at")?;
        let km: f64 = km
            .trim()
            .parse()
            .ok()
            .filter(|k: &f64| k.is_finite())
            .with_context(|| format!("--chainage-at '{p}': '{km}' is not a chainage in km"))?;
        out.push((lat, lon, km * 1000.0, format!("--chainage-at {p}")));
    }
    if out.len() > 2 {
        anyhow::bail!(
            "at most two chainage posts (--origin, --chainage-at); {} were given",
            out.len()
        );
    }
    Ok(out)
}

pub fn run(a: Args) -> Result<()> {
    check_args(&a)?;
    let given = posts(&a)?;
    let rails = a.osm.as_deref().map(osm::read_rail).transpose()?;
    let (runs, origin) = read_runs(&a, &given)?;
    let opts = FitOptions {
        smoothing_m: a.smoothing,
        disagreement_m: a.tolerance,
        cross_gaps: !a.no_motion,
        ..FitOptions::default()
    };
    let centreline = fit::fit(&runs, &opts)?;
    let posts: Vec<Post> = given
        .iter()
        .map(|(lat, lon, chainage_m, label)| {
            let (east_m, north_m, _) = origin.to_enu(*lat, *lon, 0.0);
            Post {
                east_m,
                north_m,
                chainage_m: *chainage_m,
                label: label.clone(),
            }
        })
        .collect();
    let placement = chainage::place(&centreline, &posts)?;
    centreline.check(a.tolerance, |s| placement.chainage(s))?;
    let vertices = chainage::placed(&centreline.line.thinned(0.002), &placement);
    let mut summary = Summary::new(
        &centreline,
        &placement,
        &vertices,
        match runs.iter().all(|r| r.fused) {
            true => "fused states".to_owned(),
            false => a.quality.label(),
        },
        &opts,
        a.tolerance,
    );
    summary.osm = rails.map(|ways| osm_offset(&centreline.line, &ways, &origin));
    write_outputs(&a, runs.len(), &vertices, &origin, &summary)?;
    if a.json {
        let mut v = serde_json::to_value(&summary)?;
        v["peak_rss_kib"] = super::measure::peak_rss_kib().into();
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_summary(&summary, &a.output);
    }
    Ok(())
}

/// The outputs can be written and the lengths are lengths: said before any work.
fn check_args(a: &Args) -> Result<()> {
    super::check_writable(&a.output)?;
    if let Some(csv) = &a.csv {
        super::check_writable(csv)?;
    }
    for (what, v) in [("--tolerance", a.tolerance), ("--smoothing", a.smoothing)] {
        if !(v.is_finite() && v > 0.0) {
            anyhow::bail!("{what} {v}: a length in metres above 0");
        }
    }
    Ok(())
}

/// Each run's fixes, in one plane: around the first post where one is given, else the first
/// fix read.
fn read_runs(
    a: &Args,
    given: &[(f64, f64, f64, String)],
) -> Result<(Vec<RunFixes>, GeodeticOrigin)> {
    let mut origin = given.first().map(|&(lat, lon, _, _)| GeodeticOrigin {
        latitude_deg: lat,
        longitude_deg: lon,
        altitude_m: 0.0,
    });
    let mut runs: Vec<RunFixes> = Vec::with_capacity(a.runs.len());
    let options = RunOptions {
        formats: a.formats.options()?,
        ..RunOptions::default()
    };
    for path in &a.runs {
        let run = Run::open(std::slice::from_ref(path), &options)?;
        let mut fixes = read_fixes(&run, a.topic.as_deref(), &a.quality, &mut origin)?;
        railfuse_track::lean::take_out(&mut fixes);
        runs.push(fixes);
    }
    Ok((runs, origin.expect("a run with fixes set the plane")))
}

/// The fitted line against OpenStreetMap's rail `ways` (latitude, longitude).
fn osm_offset(line: &Line, ways: &[osm::Way], origin: &GeodeticOrigin) -> osm::OsmOffset {
    let plane: Vec<Vec<(f64, f64)>> = ways
        .iter()
        .map(|w| {
            w.iter()
                .map(|&(lat, lon)| {
                    let (e, n, _) = origin.to_enu(lat, lon, 0.0);
                    (e, n)
                })
                .collect()
        })
        .collect();
    osm::offset(line, &plane)
}

/// The line as GeoJSON (or CSV, by the name) at `-o`, and as CSV at `--csv`.
fn write_outputs(
    a: &Args,
    runs: usize,
    vertices: &[TrackVertex],
    origin: &GeodeticOrigin,
    summary: &Summary,
) -> Result<()> {
    let name = a
        .name
        .clone()
        .unwrap_or_else(|| format!("fitted by railfuse track from {runs} runs"));
    let csv_out = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let text = match csv_out {
        true => output::csv(vertices, origin),
        false => output::geojson(&name, vertices, origin, summary),
    };
    std::fs::write(&a.output, text)
        .with_context(|| format!("{}: cannot write", a.output.display()))?;
    if let Some(csv) = &a.csv {
        std::fs::write(csv, output::csv(vertices, origin))
            .with_context(|| format!("{}: cannot write", csv.display()))?;
    }
    Ok(())
}

fn km(m: f64) -> String {
    format!("{:.3}", m / 1000.0)
}

/// The height profile's line: what it was fitted from, or why the line is flat.
fn print_profile(s: &Summary) {
    let Some(p) = &s.profile else { return };
    // A stretch without fixes has no heights of its own: the spline bridges it.
    let bridged = match (p, s.gaps.len()) {
        (railfuse_track::profile::Profile::Fitted { .. }, n) if n > 0 => format!(
            "; across the {n} stretch(es) without fixes below, heights are the spline's \
             bridge between their ends"
        ),
        _ => String::new(),
    };
    println!("{}{bridged}", p.describe());
    if let Some(c) = &s.cant {
        let bridged = match (c, s.gaps.len()) {
            (railfuse_track::cant::Cant::Fitted { .. }, n) if n > 0 => {
                format!("; across the {n} stretch(es) without fixes, the spline's bridge")
            }
            _ => String::new(),
        };
        println!("{}{bridged}", c.describe());
    }
}

/// Each run: its table row, how far its fixes moved for the antenna's lean, where it leaves
/// the line.
fn print_runs(s: &Summary) {
    let mut t = Table::new(&[
        "run",
        "fixes",
        "used",
        "off the line",
        "direction",
        "residual RMS m",
    ]);
    for r in &s.runs {
        t.row(vec![
            r.name.clone(),
            r.fixes.to_string(),
            r.used.to_string(),
            r.off_line.to_string(),
            r.direction.to_owned(),
            format!("{:.3}", r.lateral_rms_m),
        ]);
    }
    print!("{t}");
    for r in &s.runs {
        if let Some(l) = r.antenna_lean.filter(|l| l.moved > 0) {
            println!(
                "{}: the antenna's lean taken out of {} fixes with the IMU's roll, up to {:.2} m \
                 ({:+.2}° of roll on the straights taken as the rest of the IMU's mounting)",
                r.name,
                l.moved,
                l.max_m,
                l.straight_roll_rad.to_degrees()
            );
        }
        if let Some(z) = r.antenna_lean_kept_m {
            println!(
                "{}: the antenna's lean left in its fixes: {z:.2} m above the rail and no IMU \
                 in the run to take it out ({:.2} m towards the inside of a curve per 100 mm \
                 of cant)",
                r.name,
                z * 0.1 / railfuse_catalog::track_profile::STANDARD_CANT_BASE_M
            );
        }
        for e in &r.leaves_line {
            let at = |x: Option<f64>| x.map_or("-".to_owned(), km);
            println!(
                "{}: leaves the line after km {} ({} fixes off it, up to {:.1} m away), back at km {}",
                r.name,
                at(e.from_m),
                e.fixes,
                e.largest_offset_m,
                at(e.to_m)
            );
        }
    }
}

fn print_summary(s: &Summary, out: &std::path::Path) {
    println!(
        "fitted {} km of line from {} runs ({} fixes, {}): across the track the fixes lie {:.3} m RMS, {:.3} m p95 from it -> {}",
        km(s.length_m),
        s.runs.len(),
        s.fixes_used,
        s.fix_quality,
        s.lateral_residual_rms_m,
        s.lateral_residual_p95_m,
        out.display()
    );
    print_profile(s);
    print_runs(s);
    for a in &s.set_aside {
        println!(
            "fixes set aside from km {} to {}: the runs' motion says they bend up to {:.2} m off (a steady multipath pull)",
            km(a.from_m),
            km(a.to_m),
            a.peak_m
        );
    }
    for g in &s.gaps {
        let how = match g.crossed_by_runs {
            0 => "bridged by the spline alone".to_owned(),
            n => format!("crossed by the motion (IMU turn, odometer distance) of {n} runs"),
        };
        println!("no fix from km {} to {}: {how}", km(g.from_m), km(g.to_m));
    }
    if let Some(o) = &s.osm {
        println!(
            "against OpenStreetMap ({} railway=rail ways): {:.0} % of the line has one within {} m, {:.2} m RMS, {:.2} m p95, {:.2} m at most from the nearest",
            o.ways,
            100.0 * o.share_near,
            osm::NEAR_M,
            o.rms_m,
            o.p95_m,
            o.max_m
        );
    }
    for d in &s.runs_disagree {
        println!(
            "runs disagree from km {} to {}: their mean offsets differ by up to {:.3} m",
            km(d.from_m),
            km(d.to_m),
            d.spread_m
        );
    }
}
