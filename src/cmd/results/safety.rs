//! `railfuse results --safety`: source 002's experiment (`railfuse_experiments::safety`),
//! written as the page kept in `docs/safety.md`.

use anyhow::Result;
use railfuse_experiments::safety::{self, CaseResult, SafetyResults};

use super::page::{with_progress, write_page, Args, Template};
use super::table::Table;

pub fn run(a: &Args) -> Result<()> {
    let results = with_progress("safety experiments", safety::runs(a.seeds), |step| {
        safety::run_all(&a.dir, a.seeds, step)
    })?;
    write_page(a, &markdown(&results)?)
}

fn markdown(r: &SafetyResults) -> Result<String> {
    let mut cases = Table::new(
        [
            "scenario",
            "case",
            "pipeline",
            "usable epochs",
            "availability (lowest run)",
            "of them degraded",
            "containment (lowest run)",
            "goal met",
            "faults flagged",
            "slowest flag (s)",
            "flagged first by",
            "pos RMSE (m)",
        ],
        "lllrrrrlrrlr",
    );
    for c in &r.cases {
        cases.row(case_row(c));
    }
    Template::new(include_str!("pages/safety.md"))
        .set("n", r.seeds)
        .set("cases", cases.markdown())
        .render()
}

fn case_row(c: &CaseResult) -> Vec<String> {
    let availability = c.usable_epochs as f64 / c.epochs.max(1) as f64;
    let containment = c.intervals_contained as f64 / c.intervals_checked.max(1) as f64;
    let fault_free = c.faults == 0;
    // The aims: containment ≥ 99.99 %; availability ≥ 99 % fault-free, ≥ 97 % with a fault.
    let aim = if fault_free { 0.99 } else { 0.97 };
    let goal = match (containment >= 0.9999, availability >= aim) {
        (true, true) => "yes",
        (true, false) => "containment yes; availability falls short",
        (false, _) => "**falls short** (containment)",
    };
    let by: Vec<String> = c
        .flagged_by
        .iter()
        .map(|(k, n)| format!("{k} ×{n}"))
        .collect();
    let dash = |s: String| if s.is_empty() { "–".to_owned() } else { s };
    vec![
        c.scenario.to_string(),
        c.label.to_string(),
        format!("`{}`", c.pipeline),
        format!("{} of {}", c.usable_epochs, c.epochs),
        format!(
            "{:.2} % ({:.2} %)",
            100.0 * availability,
            100.0 * c.availability_min
        ),
        format!(
            "{:.2} %",
            100.0 * c.degraded_epochs as f64 / c.epochs.max(1) as f64
        ),
        format!(
            "{:.4} % ({:.4} %)",
            100.0 * containment,
            100.0 * c.containment_min
        ),
        goal.to_owned(),
        match fault_free {
            true => "–".to_owned(),
            // A map fault's own check: how often S4 flagged it, whatever came first.
            false if c.label.starts_with("map") => {
                let s4 = c.flagged_at_all_by.iter().find(|(k, _)| k == "s4_map");
                format!(
                    "{} of {} (S4 in {})",
                    c.faults_flagged,
                    c.faults,
                    s4.map_or(0, |(_, n)| *n)
                )
            }
            false => format!("{} of {}", c.faults_flagged, c.faults),
        },
        c.delay_max_s.map_or("–".to_owned(), |d| format!("{d:.2}")),
        dash(by.join(", ")),
        format!("{:.3}", c.position_rmse_m),
    ]
}
