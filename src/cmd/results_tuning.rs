//! `railfuse results --tuning`: the tuning experiments (`railfuse_experiments::tuning`) and EM
//! against pykalman's, written as the table kept in `docs/tuning.md`.

use std::fmt::Write as _;

use anyhow::Result;
use railfuse_experiments::tuning::{self, TuningResults, SEED000_TRUTH};
use railfuse_tune::recording::Metrics;

use super::bench_em::{self, EmComparison};
use super::results_page::{write_table, Args};
use super::DEFAULT_PIPELINES;

pub fn run(a: &Args) -> Result<()> {
    let seeds = a.seeds;
    let bar = crate::progress::Progress::steps("tuning experiments", tuning::runs(seeds));
    let results = tuning::run_all(&a.dir, seeds, DEFAULT_PIPELINES, &|done| bar.set(done))?;
    bar.finish();
    let python = a.python.clone().or_else(super::measure::find_python);
    let em = match &python {
        Some(py) => Some(bench_em::compare(py, &a.dir, 10_000, 20, 5)?),
        None => None,
    };
    let md = markdown(&results, em.as_ref())?;
    write_table(a, &md)
}

fn markdown(r: &TuningResults, em: Option<&EmComparison>) -> Result<String> {
    let n = r.seeds;
    let mut md = String::new();
    writeln!(
        md,
        "# Tuning: what `railfuse tune` recovers, and what it buys\n"
    )?;
    writeln!(
        md,
        "Regenerate with `railfuse results --tuning --seeds {n}` (this file).\n"
    )?;

    writeln!(md, "## Known noise values recovered (seed000)\n")?;
    writeln!(md, "The seed000 preset states its noise: jerk variance 0.001 m²/s⁶ (a jerk held over each 0.1 s step),")?;
    writeln!(md, "loop and radar variances 0.01. Seeds 1–{n}, {:.0} s each (ten times the source's run, so that", tuning::RECOVERY_DURATION_S)?;
    writeln!(md, "estimates are worth comparing). Every method starts 10x off (0.01, 0.1, 0.1) inside bounds")?;
    writeln!(md, "1e-5 … 1 (jerk) and 1e-4 … 1 (variances), log scale, and maximises the likelihood: EM directly,")?;
    writeln!(md, "the optimisers by minimising the innovations' negative log-likelihood (no reference). Cells:")?;
    writeln!(
        md,
        "mean of found/true − 1 over the seeds, and the largest |found/true − 1| in brackets.\n"
    )?;
    writeln!(md, "| method | jerk variance (0.001) | loop variance (0.01) | radar variance (0.01) | evaluations per run | seconds per run |")?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    for row in &r.recovery {
        let cell = |k: usize| {
            let e = &row.relative_errors[k];
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            let worst = e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            format!("{:+.1} % ({:.1} %)", 100.0 * mean, 100.0 * worst)
        };
        writeln!(
            md,
            "| {} | {} | {} | {} | {:.0} | {:.2} |",
            row.method,
            cell(0),
            cell(1),
            cell(2),
            row.evaluations,
            row.seconds
        )?;
    }
    debug_assert_eq!(SEED000_TRUTH.len(), 3);
    writeln!(md, "\nThe grid can only land on its points, nine a value about 4.2x (jerk) and 3.2x (variances) apart")?;
    writeln!(md, "over these bounds: its error is the grid's spacing, not the data's. 0.01 happens to be one of")?;
    writeln!(md, "the variances' points, hence its 0 % there; the jerk's nearest point is 7.5e-4 (−25 %). The")?;
    writeln!(
        md,
        "particle swarm had not converged within its 200 evaluations, nor had Bayesian optimisation"
    )?;
    writeln!(md, "within its 60 (its row is there in a build with `--features bayesian`); EM and Nelder–Mead")?;
    writeln!(md, "reach the same maximum of the likelihood.\n")?;

    let h = &r.held_out;
    writeln!(
        md,
        "## The default pipeline tuned on some runs, scored on others\n"
    )?;
    writeln!(md, "`samples/kalman.toml` on the default scenario, {:.0} s runs. Tuned against the truth (position", h.duration_s)?;
    writeln!(
        md,
        "RMSE + speed RMSE, Nelder–Mead, {} evaluations in {:.1} s) on seeds {}–{}, then both the",
        h.evaluations,
        h.seconds,
        h.train_seeds[0],
        h.train_seeds[h.train_seeds.len() - 1]
    )?;
    writeln!(md, "untuned and the tuned pipeline replayed on seeds {}–{}, which tuning never saw. Errors pooled", h.test_seeds[0], h.test_seeds[h.test_seeds.len() - 1])?;
    writeln!(
        md,
        "over the runs. These runs come from the simulator the pipeline is scored against; the"
    )?;
    writeln!(
        md,
        "simulator's sensor errors are not white (scale errors, slip, quantisation), so the tuned"
    )?;
    writeln!(md, "values are not the simulator's parameters copied.\n")?;
    writeln!(
        md,
        "| runs | pipeline | position RMSE (m) | speed RMSE (m/s) | NEES in 95 % | NIS in 95 % |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    let row = |md: &mut String, runs: &str, which: &str, m: &Metrics| {
        let f = |x: Option<f64>, d: usize| x.map_or("–".into(), |x| format!("{x:.d$}"));
        let p = |x: Option<f64>| x.map_or("–".into(), |x| format!("{:.1} %", 100.0 * x));
        writeln!(
            md,
            "| {runs} | {which} | {} | {} | {} | {} |",
            f(m.position_rmse_m, 3),
            f(m.speed_rmse_mps, 4),
            p(m.nees_inside_95),
            p(m.nis_inside_95)
        )
    };
    row(&mut md, "training", "untuned", &h.train_before)?;
    row(&mut md, "training", "tuned", &h.train_after)?;
    row(&mut md, "**held out**", "untuned", &h.test_before)?;
    row(&mut md, "**held out**", "tuned", &h.test_after)?;
    writeln!(md, "\n| value | bounds | untuned | tuned |")?;
    writeln!(md, "|---|---|---|---|")?;
    for p in &h.params {
        let bound = if p.on_bound { " (on a bound)" } else { "" };
        writeln!(
            md,
            "| `{}` | {} … {} | {} | {}{bound} |",
            p.name, p.min, p.max, p.before, p.after
        )?;
    }

    writeln!(md, "\n## EM against pykalman\n")?;
    match em {
        None => writeln!(
            md,
            "Not run: no Python with pykalman (run `tests/run` once, or give --python)."
        )?,
        Some(c) => {
            writeln!(md, "The same linear-Gaussian data (a constant-acceleration run at 10 Hz, white jerk PSD 0.2,")?;
            writeln!(md, "position and speed measured with variance 0.01), {} steps, {} iterations from the same start", c.steps, c.iterations)?;
            writeln!(
                md,
                "(Q and R 10x off), Q (3x3) and R (2x2) estimated in full, as pykalman's `em` does"
            )?;
            writeln!(md, "(pykalman 0.11.2). Times are EM alone: railfuse's the median of 5 runs, pykalman's one run.\n")?;
            writeln!(md, "| | railfuse | pykalman |")?;
            writeln!(md, "|---|---|---|")?;
            let show = |m: &[Vec<f64>]| {
                m.iter()
                    .map(|r| {
                        r.iter()
                            .map(|x| format!("{x:.4e}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    })
                    .collect::<Vec<_>>()
                    .join("; ")
            };
            writeln!(
                md,
                "| Q | {} | {} |",
                show(&c.railfuse_q),
                show(&c.pykalman_q)
            )?;
            writeln!(
                md,
                "| R | {} | {} |",
                show(&c.railfuse_r),
                show(&c.pykalman_r)
            )?;
            writeln!(
                md,
                "| time | {:.3} s | {:.1} s |",
                c.railfuse_s, c.pykalman_s
            )?;
            writeln!(
                md,
                "\nRelative difference (Frobenius norm): Q {:.1e}, R {:.1e} (goal: under 1e-6).",
                c.q_relative_difference, c.r_relative_difference
            )?;
            writeln!(
                md,
                "railfuse is {:.0}x faster (goal: at least 150x).",
                c.speedup
            )?;
        }
    }
    Ok(md)
}
