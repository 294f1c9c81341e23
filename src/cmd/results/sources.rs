//! `railfuse results`: the experiments of sources 000 and 001 re-run on their simulated
//! scenarios over several seeds, each source's reported figure beside railfuse's, the
//! default pipelines over one-hour runs and what α and β change: the page kept in
//! `docs/results.md`.

use anyhow::Result;
use railfuse_experiments::long_runs;
use railfuse_experiments::sources::{self, Results, Verdict};

use super::page::{with_progress, write_page, Args, Template};
use super::table::Table;

pub fn run(a: &Args) -> Result<()> {
    let results = with_progress("results", sources::runs(a.seeds), |step| {
        sources::run_all(&a.dir, a.seeds, step)
    })?;
    write_page(a, &markdown(&results)?)
}

fn verdict(v: Verdict) -> String {
    match v {
        Verdict::Beats => "**beats**".into(),
        Verdict::Matches => "**matches**".into(),
        Verdict::FallsShort => "**falls short**".into(),
        Verdict::NotComparable { because } => format!("not comparable because {because}"),
    }
}

fn markdown(r: &Results) -> Result<String> {
    let (source_000, reasons) = source_000(r);
    Template::new(include_str!("pages/results.md"))
        .set("n", r.seeds)
        .set("last", r.seeds - 1)
        .set(
            "nees_target",
            format!("{:.0}", long_runs::TARGET_NEES_INSIDE * 100.0),
        )
        .set(
            "rmse_target",
            format!("{:.2}", long_runs::TARGET_POSITION_RMSE_M),
        )
        .set("source_000", source_000.markdown())
        .set("reasons", reasons)
        .set("source_001", source_001(r).markdown())
        .set("mismatch", mismatch(r).markdown())
        .set("long_runs", long_runs(r).markdown())
        .set("sharing", sharing(r).markdown())
        .render()
}

/// Source 000's rows, and the reasons of its "not comparable" verdicts, said once each below.
fn source_000(r: &Results) -> (Table, String) {
    let mut t = Table::text([
        "run",
        "pipeline",
        "source reports",
        "position envelope (m)",
        "max \\|pos error\\| after the first balise (m)",
        "pos RMSE (m)",
        "speed envelope (m/s)",
        "NEES in 95 %",
        "verdict",
    ]);
    let mut reasons = Vec::new();
    for row in &r.source_000 {
        let e = &row.envelope;
        let cell = match row.verdict {
            Verdict::NotComparable { because } => {
                if !reasons.contains(&because) {
                    reasons.push(because);
                }
                "not comparable (below)".to_owned()
            }
            v => verdict(v),
        };
        let after = e.after_first_balise_abs_m.filter(|_| row.balise());
        t.row([
            format!("`{}`", row.scenario),
            format!("`{}`", row.pipeline),
            row.claim.to_string(),
            format!("{:+.2} … {:+.2}", e.position_min_m, e.position_max_m),
            after.map_or("–".to_owned(), |a| format!("{a:.2}")),
            format!("{:.2}", e.position_rmse_m()),
            format!("{:+.3} … {:+.3}", e.speed_min_mps, e.speed_max_mps),
            format!("{:.0} %", e.nees_inside_95() * 100.0),
            cell,
        ]);
    }
    let said = reasons
        .iter()
        .map(|b| format!("\nNot comparable because {b}.\n"))
        .collect();
    (t, said)
}

fn source_001(r: &Results) -> Table {
    let mut t = Table::text([
        "case",
        "pipeline",
        "output Hz (min)",
        "max \\|position error\\| (m)",
        "pos RMSE (m)",
        "max \\|speed error\\| (km/h)",
        "speed RMSE (km/h)",
        "NEES in 95 %",
        "verdict",
    ]);
    for row in &r.source_001 {
        let e = &row.envelope;
        t.row([
            row.case.to_string(),
            format!("`{}`", row.pipeline),
            format!("{:.1}", e.min_rate_hz),
            format!("{:.2}", e.position_abs_m()),
            format!("{:.2}", e.position_rmse_m()),
            format!("{:.3}", e.speed_abs_mps() * 3.6),
            format!("{:.3}", e.speed_rmse_mps() * 3.6),
            format!("{:.0} %", e.nees_inside_95() * 100.0),
            verdict(row.verdict),
        ]);
    }
    t
}

/// Source 001 with a simulated receiver the sensor-state model gets wrong.
fn mismatch(r: &Results) -> Table {
    let mut t = Table::text([
        "simulated GNSS bias",
        "pipeline",
        "max \\|position error\\| (m)",
        "pos RMSE (m)",
        "change in pos RMSE",
        "max \\|speed error\\| (km/h)",
        "NEES in 95 %",
        "verdict on the source's targets",
    ]);
    for row in &r.source_001_mismatch {
        let e = &row.envelope;
        // The first row of the pipeline is the receiver it models.
        let base = r
            .source_001_mismatch
            .iter()
            .find(|b| b.pipeline == row.pipeline)
            .map_or(f64::NAN, |b| b.envelope.position_rmse_m());
        t.row([
            row.receiver.to_string(),
            format!("`{}`", row.pipeline),
            format!("{:.2}", e.position_abs_m()),
            format!("{:.2}", e.position_rmse_m()),
            format!("{:+.0} %", (e.position_rmse_m() / base - 1.0) * 100.0),
            format!("{:.3}", e.speed_abs_mps() * 3.6),
            format!("{:.0} %", e.nees_inside_95() * 100.0),
            verdict(row.verdict),
        ]);
    }
    t
}

fn long_runs(r: &Results) -> Table {
    let mut t = Table::text([
        "pipeline",
        "runs on target",
        "NEES in 95 % (lowest run)",
        "NEES in 95 % (mean)",
        "pos RMSE (worst run, m)",
        "pos RMSE (mean, m)",
        "max \\|position error\\| (m)",
    ]);
    for row in &r.long_runs {
        let e = &row.envelope;
        t.row([
            format!("`{}`", row.pipeline),
            format!("{} of {}", row.runs_on_target, e.runs),
            format!("{:.1} %", e.nees_inside_min * 100.0),
            format!("{:.1} %", e.nees_inside_95() * 100.0),
            format!("{:.3}", e.position_rmse_max_m),
            format!("{:.3}", e.position_rmse_m()),
            format!("{:.2}", e.position_abs_m()),
        ]);
    }
    t
}

/// Each source's federated pipeline with its sharing table and with even shares.
fn sharing(r: &Results) -> Table {
    let mut t = Table::text([
        "source",
        "run",
        "pipeline",
        "fusion",
        "sharing",
        "max \\|position error\\| (m)",
        "pos RMSE (m)",
        "max \\|speed error\\| (m/s)",
        "speed RMSE (m/s)",
        "NEES in 95 %",
    ]);
    for row in &r.sharing {
        let e = &row.envelope;
        t.row([
            row.source.to_string(),
            format!("`{}`", row.scenario),
            format!("`{}`", row.pipeline),
            row.fusion.to_string(),
            row.sharing.to_string(),
            format!("{:.2}", e.position_abs_m()),
            format!("{:.3}", e.position_rmse_m()),
            format!("{:.3}", e.speed_abs_mps()),
            format!("{:.3}", e.speed_rmse_mps()),
            format!("{:.0} %", e.nees_inside_95() * 100.0),
        ]);
    }
    t
}
