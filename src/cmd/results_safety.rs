//! `railfuse results --safety`: source 002's experiment (`railfuse_experiments::safety`),
//! written as the table kept in `docs/safety.md`.

use std::fmt::Write as _;

use anyhow::Result;
use railfuse_experiments::safety::{self, SafetyResults};

use super::results_page::{write_table, Args};

pub fn run(a: &Args) -> Result<()> {
    let seeds = a.seeds;
    let bar = crate::progress::Progress::steps("safety experiments", safety::runs(seeds));
    let results = safety::run_all(&a.dir, seeds, &|done| bar.set(done))?;
    bar.finish();
    let md = markdown(&results)?;
    write_table(a, &md)
}

fn markdown(r: &SafetyResults) -> Result<String> {
    let n = r.seeds;
    let mut md = String::new();
    writeln!(md, "# Source 002: safety checks and the safe interval\n")?;
    writeln!(md, "Regenerate with `railfuse results --safety --seeds {n}` (this file). Every case runs seeds 1–{n}, re-fused")?;
    writeln!(md, "with `samples/seed002.toml`: `ekf_safety` is the source as stated (white-noise sensors), `ekf_safety_cal`")?;
    writeln!(md, "the same filter with the receiver's bias and axle 1's speed error as states on each axis. An epoch is a")?;
    writeln!(md, "GNSS fix or an axle-1 sample; it is usable when every check passes (S1 sensor diagnosis, S3 divergence,")?;
    writeln!(md, "S4 map, S5 odometry). Containment: the share of usable epochs whose U_safe (η = 3.89, m = 1.5 σ_map)")?;
    writeln!(md, "holds the truth's chainage, pooled over the seeds, with the lowest single run in brackets. The issue's")?;
    writeln!(md, "goals: containment at least 99.99 % over all seeds, fault-free and faulted; availability above 99 %")?;
    writeln!(md, "fault-free. A faulted run at 100 % containment flagged its fault before it moved the position outside")?;
    writeln!(
        md,
        "U_safe. The source reports no figures: these are railfuse's, against the issue's goals.\n"
    )?;
    writeln!(md, "| scenario | case | pipeline | usable epochs | availability (lowest run) | containment (lowest run) | goal met | faults flagged | slowest flag (s) | flagged first by | pos RMSE (m) |")?;
    writeln!(md, "|---|---|---|---:|---:|---:|---|---:|---:|---|---:|")?;
    for c in &r.cases {
        let availability = c.usable_epochs as f64 / c.epochs.max(1) as f64;
        let containment = c.intervals_contained as f64 / c.intervals_checked.max(1) as f64;
        let fault_free = c.faults == 0;
        let met_containment = containment >= 0.9999;
        let goal = match (met_containment, fault_free, availability > 0.99) {
            (true, true, true) => "yes".to_owned(),
            (true, true, false) => "containment yes; availability falls short".to_owned(),
            (true, false, _) => "yes".to_owned(),
            (false, _, _) => "**falls short** (containment)".to_owned(),
        };
        let by = c
            .flagged_by
            .iter()
            .map(|(k, n)| format!("{k} ×{n}"))
            .collect::<Vec<_>>()
            .join(", ");
        writeln!(
            md,
            "| {} | {} | `{}` | {} of {} | {:.2} % ({:.2} %) | {:.4} % ({:.4} %) | {goal} | {} | {} | {} | {:.3} |",
            c.scenario,
            c.label,
            c.pipeline,
            c.usable_epochs,
            c.epochs,
            100.0 * availability,
            100.0 * c.availability_min,
            100.0 * containment,
            100.0 * c.containment_min,
            if fault_free { "–".to_owned() } else { format!("{} of {}", c.faults_flagged, c.faults) },
            c.delay_max_s.map_or("–".to_owned(), |d| format!("{d:.2}")),
            if by.is_empty() { "–".to_owned() } else { by },
            c.position_rmse_m,
        )?;
    }
    writeln!(md)?;
    writeln!(md, "Thresholds (each default's reason is in `crates/refuse/src/safety/settings.rs`): S3a r = 3 over 10")?;
    writeln!(md, "updates (a consistent filter exceeds it with probability 7e-6), S3b 15 m and 2 m/s, S3c σ ≤ 2 m, S4")?;
    writeln!(
        md,
        "λ = 4 with σ_map = 0.1 m, S5 ΔT = 5 s at 4 σ, GNSS stale after 60 s, an axle after 0.5 s."
    )?;
    Ok(md)
}
