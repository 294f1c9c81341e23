use anyhow::Result;
use railfuse_catalog::inspect::{summarise, LogSummary};
use railfuse_catalog::run::{Alignment, Run};

use super::run_input::RunArgs;
use crate::table::Table;

#[derive(clap::Args)]
pub struct Args {
    /// The log: a file, or every file of a run.
    #[command(flatten)]
    pub run: RunArgs,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let run = a.run.open()?;
    let s = summarise(&run)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(());
    }
    println!(
        "{}: {} messages over {:.1} s, {:.1} MiB",
        s.file,
        s.messages,
        s.duration_s,
        s.file_bytes as f64 / (1 << 20) as f64
    );
    let t0 = s.first_log_time_ns.unwrap_or(0);
    let rel = |t: Option<u64>| {
        t.map_or("-".into(), |t| {
            format!("{:.3}", t.saturating_sub(t0) as f64 / 1e9)
        })
    };
    if s.files.len() > 1 || !run.missing().is_empty() {
        print_files(&s, &run, &rel);
    }
    if let Some(clocks) = &s.clocks {
        print_clocks(clocks, run.alignment().is_some());
    }
    let mut t = Table::new(&[
        "topic",
        "schema",
        "messages",
        "rate Hz",
        "first s",
        "last s",
        "largest gap s",
    ]);
    for c in &s.channels {
        t.row(vec![
            c.topic.clone(),
            c.schema.clone(),
            c.messages.to_string(),
            c.mean_rate_hz.map_or("-".into(), |r| format!("{r:.2}")),
            rel(c.first_log_time_ns),
            rel(c.last_log_time_ns),
            c.largest_gap_s.map_or("-".into(), |g| format!("{g:.3}")),
        ]);
    }
    print!("{t}");
    for (name, m) in &s.metadata {
        println!("metadata {name}:");
        for (k, v) in m {
            let v = if v.len() > 100 {
                format!("{}… ({} bytes)", &v[..v.floor_char_boundary(100)], v.len())
            } else {
                v.clone()
            };
            println!("  {k} = {}", v.replace('\n', " "));
        }
    }
    for at in &s.attachments {
        println!(
            "attachment {} ({}, {} bytes)",
            at.name, at.media_type, at.bytes
        );
    }
    if let Some(v) = &s.vehicle {
        print_vehicle(v);
    }
    for note in &s.vehicle_notes {
        println!("  vehicle: {note}");
    }
    if s.fused_pipelines.is_empty() {
        println!("fused pipelines: none");
    } else {
        println!("fused pipelines: {}", s.fused_pipelines.join(", "));
    }
    Ok(())
}

/// The train of `/vehicle`: its length, and each sensor's lever arm and mounting.
fn print_vehicle(v: &railfuse_catalog::messages::Vehicle) {
    let lean = match v.roll_per_lateral_mps2 {
        0.0 => String::new(),
        k => format!(", leaning {k} rad per m/s² unbalanced"),
    };
    println!(
        "vehicle '{}': {} m from front end to rear end{lean}",
        v.name, v.length_m
    );
    let mut t = Table::new(&[
        "sensor",
        "frame",
        "lever arm x y z m",
        "mounting roll pitch yaw °",
    ]);
    for m in &v.sensors {
        let [x, y, z] = m.lever_arm_m;
        let [r, p, w] = m.mounting_deg;
        t.row(vec![
            m.topic.clone(),
            m.frame_id.clone().unwrap_or_else(|| "-".into()),
            format!("{x:+.3} {y:+.3} {z:+.3}"),
            format!("{r:+.2} {p:+.2} {w:+.2}"),
        ]);
    }
    print!("{t}");
}

/// One line per file of the run (its span on the run's clock, messages, clock), then the
/// gaps between files.
fn print_files(s: &LogSummary, run: &Run, rel: &dyn Fn(Option<u64>) -> String) {
    let mut t = Table::new(&[
        "file",
        "messages",
        "MiB",
        "first s",
        "last s",
        "clock offset s",
        "drift ppm",
    ]);
    for f in &s.files {
        t.row(vec![
            f.path.clone(),
            f.messages.to_string(),
            format!("{:.1}", f.bytes as f64 / (1 << 20) as f64),
            rel(f.first_log_time_ns),
            rel(f.last_log_time_ns),
            format!("{:+.3}", f.clock.offset_s()),
            format!("{:+.1}", f.clock.drift_ppm),
        ]);
    }
    for m in run.missing() {
        t.row(vec![
            format!("{} (missing)", m.path.display()),
            m.messages.map_or("-".into(), |n| n.to_string()),
            "-".into(),
            rel(m.start_ns),
            rel(m.start_ns.zip(m.duration_ns).map(|(a, d)| a + d)),
            "-".into(),
            "-".into(),
        ]);
    }
    print!("{t}");
    for g in &s.gaps_between_files {
        println!(
            "gap between files: {:.3} s from {} s (end of {}) to {} s (start of {}){}",
            (g.end_ns - g.start_ns) as f64 / 1e9,
            rel(Some(g.start_ns)),
            g.after,
            rel(Some(g.end_ns)),
            g.before,
            match &g.missing {
                Some(m) => format!(": the missing part {m}"),
                None => String::new(),
            }
        );
    }
}

/// Each input's clock against GNSS time, and whether `--align gnss` applied it.
fn print_clocks(a: &Alignment, applied: bool) {
    let mut t = Table::new(&[
        "input",
        "GNSS time from",
        "pairs",
        "offset s",
        "drift ppm",
        "residual rms ms",
        "span s",
    ]);
    for e in &a.estimates {
        match e {
            Ok(e) => t.row(vec![
                e.input.display().to_string(),
                format!("{} ({})", e.source.label(), e.topics.join(", ")),
                e.pairs.to_string(),
                format!("{:+.6}", e.clock.offset_s()),
                format!("{:+.2}", e.clock.drift_ppm),
                format!("{:.3}", e.residual_rms_ns / 1e6),
                format!("{:.1}", e.span_s),
            ]),
            Err(n) => t.row(vec![
                n.input.display().to_string(),
                n.cause.clone(),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
            ]),
        }
    }
    println!("clocks against GNSS time (local − GNSS at each input's first pair):");
    print!("{t}");
    match (applied, a.reference) {
        (true, Some(r)) => println!(
            "--align gnss: every input on the clock of {} (the file table's clock columns)",
            a.estimates[r]
                .as_ref()
                .map_or(String::new(), |e| e.input.display().to_string())
        ),
        (false, Some(_)) => println!("--align gnss puts every input on the first one's clock"),
        _ => {}
    }
}
