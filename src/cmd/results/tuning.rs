//! `railfuse results --tuning`: the tuning experiments (`railfuse_experiments::tuning`) and EM
//! against pykalman's, written as the page kept in `docs/tuning.md`.

use anyhow::Result;
use railfuse_experiments::tuning::{self, HeldOut, TuningResults};
use railfuse_tune::recording::Metrics;

use super::super::bench_em::{self, EmComparison};
use super::super::DEFAULT_PIPELINES;
use super::page::{with_progress, write_page, Args, Template};
use super::table::Table;

pub fn run(a: &Args) -> Result<()> {
    let results = with_progress("tuning experiments", tuning::runs(a.seeds), |step| {
        tuning::run_all(&a.dir, a.seeds, DEFAULT_PIPELINES, step)
    })?;
    let python = a.python.clone().or_else(super::super::measure::find_python);
    let em = match &python {
        Some(py) => Some(bench_em::compare(py, &a.dir, 10_000, 20, 5)?),
        None => None,
    };
    write_page(a, &markdown(&results, em.as_ref())?)
}

fn markdown(r: &TuningResults, em: Option<&EmComparison>) -> Result<String> {
    let h = &r.held_out;
    let span = |s: &[u64]| format!("{}–{}", s[0], s[s.len() - 1]);
    Template::new(include_str!("pages/tuning.md"))
        .set("n", r.seeds)
        .set("recovery_s", format!("{:.0}", tuning::RECOVERY_DURATION_S))
        .set("recovery", recovery(r).markdown())
        .set("held_out_s", format!("{:.0}", h.duration_s))
        .set("evaluations", h.evaluations)
        .set("seconds", format!("{:.1}", h.seconds))
        .set("train", span(&h.train_seeds))
        .set("test", span(&h.test_seeds))
        .set("held_out", held_out(h).markdown())
        .set("params", params(&h.params).markdown())
        .set("rtk_basis", &h.without_truth.objective_basis)
        .set("rtk_evaluations", h.without_truth.evaluations)
        .set("rtk_seconds", format!("{:.1}", h.without_truth.seconds))
        .set("without_truth", without_truth(h).markdown())
        .set("rtk_params", params(&h.without_truth.params).markdown())
        .set("rtk_claims", rtk_claims(h))
        .set("em", em_section(em)?)
        .render()
}

/// Seed000's known noise values, as each method found them.
fn recovery(r: &TuningResults) -> Table {
    let mut t = Table::text([
        "method",
        "jerk variance (0.001)",
        "loop variance (0.01)",
        "radar variance (0.01)",
        "evaluations per run",
        "seconds per run",
    ]);
    for row in &r.recovery {
        let cell = |k: usize| {
            let e = &row.relative_errors[k];
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            let worst = e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            format!("{:+.1} % ({:.1} %)", 100.0 * mean, 100.0 * worst)
        };
        t.row([
            row.method.to_string(),
            cell(0),
            cell(1),
            cell(2),
            format!("{:.0}", row.evaluations),
            format!("{:.2}", row.seconds),
        ]);
    }
    t
}

fn held_out(h: &HeldOut) -> Table {
    let mut t = Table::text([
        "runs",
        "pipeline",
        "position RMSE (m)",
        "speed RMSE (m/s)",
        "NEES in 95 %",
        "NIS in 95 %",
    ]);
    let f = |x: Option<f64>, d: usize| x.map_or("–".into(), |x| format!("{x:.d$}"));
    let p = |x: Option<f64>| x.map_or("–".into(), |x| format!("{:.1} %", 100.0 * x));
    let rows: [(&str, &str, &Metrics); 5] = [
        ("training", "untuned", &h.train_before),
        ("training", "tuned", &h.train_after),
        ("**held out**", "untuned", &h.test_before),
        ("**held out**", "tuned", &h.test_after),
        (
            "**held out**",
            "tuned against the RTK fixes",
            &h.without_truth.test_after,
        ),
    ];
    for (runs, which, m) in rows {
        t.row([
            runs.to_owned(),
            which.to_owned(),
            f(m.position_rmse_m, 3),
            f(m.speed_rmse_mps, 4),
            p(m.nees_inside_95),
            p(m.nis_inside_95),
        ]);
    }
    t
}

/// Per held-out seed: the position RMSE against the truth of each configuration.
fn without_truth(h: &HeldOut) -> Table {
    let mut t = Table::text([
        "held-out seed",
        "untuned (m)",
        "tuned against the truth (m)",
        "tuned against the RTK fixes (m)",
    ]);
    for (seed, untuned, truth, rtk) in &h.without_truth.per_seed {
        t.row([
            seed.to_string(),
            format!("{untuned:.3}"),
            format!("{truth:.3}"),
            format!("{rtk:.3}"),
        ]);
    }
    t
}

/// The two claims, as measured.
fn rtk_claims(h: &HeldOut) -> String {
    let w = &h.without_truth;
    let (beats, of) = w.beats_untuned();
    let gap = w
        .against_truth_tuned(&h.test_after)
        .map_or("–".into(), |g| format!("{:+.1} %", 100.0 * g));
    let speed = |m: &Metrics| m.speed_rmse_mps.map_or("–".into(), |v| format!("{v:.4}"));
    format!(
        "Held out, the pipeline tuned against the RTK fixes has a position RMSE {gap} of the one \
         tuned against the truth (the goal: within 10 %), and beats the untuned pipeline on \
         {beats} of {of} held-out seeds. Its speed RMSE is {} m/s against {} m/s tuned \
         against the truth: it was scored against the receiver's own speed, noisier than the \
         truth's, and the parameters that set the speed went where that noise let them.\n",
        speed(&w.test_after),
        speed(&h.test_after)
    )
}

fn params(list: &[railfuse_tune::ParamReport]) -> Table {
    let mut t = Table::text(["value", "bounds", "untuned", "tuned"]);
    for p in list {
        let bound = if p.on_bound { " (on a bound)" } else { "" };
        t.row([
            format!("`{}`", p.name),
            format!("{} … {}", p.min, p.max),
            p.before.to_string(),
            format!("{}{bound}", p.after),
        ]);
    }
    t
}

fn em_section(em: Option<&EmComparison>) -> Result<String> {
    let Some(c) = em else {
        return Ok(
            "Not run: no Python with pykalman (run `tests/run` once, or give --python).\n".into(),
        );
    };
    let show = |m: &[Vec<f64>]| {
        let rows: Vec<String> = m
            .iter()
            .map(|r| {
                let cells: Vec<String> = r.iter().map(|x| format!("{x:.4e}")).collect();
                cells.join(", ")
            })
            .collect();
        rows.join("; ")
    };
    let mut t = Table::text(["", "railfuse", "pykalman"]);
    t.row(["Q".into(), show(&c.railfuse_q), show(&c.pykalman_q)]);
    t.row(["R".into(), show(&c.railfuse_r), show(&c.pykalman_r)]);
    t.row([
        "time".into(),
        format!("{:.3} s", c.railfuse_s),
        format!("{:.1} s", c.pykalman_s),
    ]);
    Template::new(include_str!("pages/tuning_em.md"))
        .set("steps", c.steps)
        .set("iterations", c.iterations)
        .set("matrices", t.markdown())
        .set("q_difference", format!("{:.1e}", c.q_relative_difference))
        .set("r_difference", format!("{:.1e}", c.r_relative_difference))
        .set("speedup", format!("{:.0}", c.speedup))
        .render()
}
