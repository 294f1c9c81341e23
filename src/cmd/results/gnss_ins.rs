//! `railfuse results --gnss-ins`: source 003's experiment (`railfuse_experiments::gnss_ins`),
//! written as the page kept in `docs/gnss_ins.md`.

use anyhow::Result;
use railfuse_experiments::gnss_ins::{
    self, Consistency, GnssInsResults, PlaneErrors, SourceFigures, Spread, SOURCE, TRAIN_PIPELINES,
};

use super::page::{with_progress, write_page, Args, Template};
use super::table::Table;

pub fn run(a: &Args) -> Result<()> {
    let results = with_progress("gnss_ins experiments", gnss_ins::runs(a.seeds), |step| {
        gnss_ins::run_all(&a.dir, a.seeds, step)
    })?;
    write_page(a, &markdown(&results)?)
}

/// `kf`'s figure over `x`'s: how many times smaller the error got (> 1 is better).
fn ratio(kf: f64, x: f64) -> String {
    match x > 0.0 && kf.is_finite() {
        true => format!("{:.2}", kf / x),
        false => "–".into(),
    }
}

fn f(x: f64) -> String {
    match x.is_finite() {
        true => format!("{x:.3}"),
        false => "–".into(),
    }
}

/// The verdict on an improvement ratio against the source's.
fn against(ours: f64, source: Option<f64>) -> String {
    match source {
        None => "source gives none".into(),
        Some(s) if ours >= s => format!("at least the source's ({s:.2})"),
        Some(s) => format!("**falls short** of the source's {s:.2}"),
    }
}

fn markdown(r: &GnssInsResults) -> Result<String> {
    let kf = r
        .rows
        .iter()
        .find(|x| x.scenario == "seed003" && x.pipeline == "kf");
    let baseline = kf.map_or(String::new(), |kf| {
        format!(
            "- The baseline. railfuse's plain `kf` is already an IMU-aided error-state filter \
             with bias states and\n  the receiver's own covariance: its velocity-error std on \
             seed003 is {} / {} m/s east/north, the\n  source's plain KF 0.5146 / 0.9949 m/s. \
             The source's baseline left far more noise for a pre-filter to\n  remove.\n",
            f(kf.velocity_east.std()),
            f(kf.velocity_north.std())
        )
    });
    Template::new(include_str!("pages/gnss_ins.md"))
        .set("n", r.seeds)
        .set("errors", errors(r).markdown())
        .set("improvement", improvement(r).markdown())
        .set("constraints", constraints(r).markdown())
        .set("baseline", baseline)
        .render()
}

fn errors(r: &GnssInsResults) -> Table {
    let mut t = Table::new(
        [
            "scenario",
            "pipeline",
            "vel std E",
            "vel std N",
            "vel max E",
            "vel max N",
            "mean abs E",
            "mean abs N",
            "loss std E",
            "loss std N",
            "loss std along",
            "NEES in 95 %",
            "loss NEES in 95 %",
        ],
        "llrrrrrrrrrrr",
    );
    for row in &r.rows {
        t.row([
            row.scenario.clone(),
            format!("`{}`", row.pipeline),
            f(row.velocity_east.std()),
            f(row.velocity_north.std()),
            f(row.velocity_east.max_abs),
            f(row.velocity_north.max_abs),
            f(row.position_east.mean_abs()),
            f(row.position_north.mean_abs()),
            loss(&row.outage_east),
            loss(&row.outage_north),
            loss(&row.outage_along),
            share(&row.nees),
            share(&row.outage_nees),
        ]);
    }
    t
}

/// A spread's std, or a dash where it has no samples (no loss in the scenario).
fn loss(s: &Spread) -> String {
    match s.n {
        0 => "–".to_owned(),
        _ => f(s.std()),
    }
}

fn share(c: &Consistency) -> String {
    match c.n {
        0 => "–".to_owned(),
        _ => format!("{:.1} %", 100.0 * c.share()),
    }
}

/// The goal a train pipeline is held to through the loss of `scenario`: its bound on the
/// position-error std east and north, whether strictly below it, and what it is. On
/// `seed003`, issue 31's; on `seed003_3d`, the real-train issue's: still below the source's
/// PU-RLS, and within 25 % of the same pipeline on the flat twin (`twin`).
fn goal(
    pipeline: &str,
    scenario: &str,
    twin: Option<&PlaneErrors>,
) -> Option<(f64, f64, bool, String)> {
    let pu_rls = SOURCE
        .iter()
        .find(|s| s.pipeline == "pu_rls")?
        .outage_std_en?;
    match (scenario, pipeline) {
        ("seed003", "kf_track") => {
            Some((pu_rls.0, pu_rls.1, true, "below the source's PU-RLS".into()))
        }
        ("seed003", "kf_track_speed") => Some((1.0, 1.0, false, "at most 1 m".into())),
        ("seed003_3d", _) => {
            let twin = twin?;
            let (e, n) = (
                1.25 * twin.outage_east.std(),
                1.25 * twin.outage_north.std(),
            );
            Some((
                e.min(pu_rls.0),
                n.min(pu_rls.1),
                false,
                "within 25 % of the flat twin, below PU-RLS".into(),
            ))
        }
        _ => None,
    }
}

/// railfuse's train pipelines through the loss of source 003's scenario, of its railway in
/// three dimensions and of that railway's flat twin, beside the source's best.
fn constraints(r: &GnssInsResults) -> Table {
    let mut t = Table::new(
        [
            "scenario",
            "pipeline",
            "loss std E",
            "loss std N",
            "source PU-RLS E / N",
            "goal",
            "verdict",
            "loss NEES in 95 %",
        ],
        "llrrrlll",
    );
    let pu_rls = SOURCE
        .iter()
        .find(|s| s.pipeline == "pu_rls")
        .and_then(|s| s.outage_std_en);
    for scenario in ["seed003", "seed003_3d_flat", "seed003_3d"] {
        for row in r
            .rows
            .iter()
            .filter(|x| x.scenario == scenario && TRAIN_PIPELINES.contains(&x.pipeline.as_str()))
        {
            let twin = r
                .rows
                .iter()
                .find(|x| x.scenario == "seed003_3d_flat" && x.pipeline == row.pipeline);
            let (goal, verdict) = verdict(row, goal(&row.pipeline, scenario, twin));
            t.row([
                format!("`{scenario}`"),
                format!("`{}`", row.pipeline),
                f(row.outage_east.std()),
                f(row.outage_north.std()),
                pu_rls.map_or("–".into(), |(se, sn)| format!("{se:.2} / {sn:.2}")),
                goal,
                verdict,
                loss_nees(&row.outage_nees),
            ]);
        }
    }
    t
}

/// A goal in words and whether the row's loss figures meet it.
fn verdict(row: &PlaneErrors, goal: Option<(f64, f64, bool, String)>) -> (String, String) {
    let Some((ge, gn, strict, what)) = goal else {
        return ("–".into(), "–".into());
    };
    let (e, n) = (row.outage_east.std(), row.outage_north.std());
    let within = |x: f64, bound: f64| if strict { x < bound } else { x <= bound };
    let met = within(e, ge) && within(n, gn);
    let op = if strict { "<" } else { "≤" };
    (
        format!("{what}: E {op} {ge:.2}, N {op} {gn:.2}"),
        match met {
            true => "met".to_owned(),
            false => "**not met**".to_owned(),
        },
    )
}

/// The share of the loss's states inside the NEES interval, against the 90 % honesty goal.
fn loss_nees(nees: &Consistency) -> String {
    match nees.n {
        0 => "–".to_owned(),
        _ => format!(
            "{} ({})",
            share(nees),
            match nees.share() >= 0.9 {
                true => "≥ 90 %: met",
                false => "**below 90 %**",
            }
        ),
    }
}

/// A figure compared: its name, railfuse's value of a pipeline, the source's.
struct Figure {
    name: &'static str,
    ours: fn(&PlaneErrors) -> f64,
    source: fn(&SourceFigures) -> Option<f64>,
}

const FIGURES: [Figure; 7] = [
    Figure {
        name: "vel std E",
        ours: |x| x.velocity_east.std(),
        source: |s| s.velocity_std_en.map(|v| v.0),
    },
    Figure {
        name: "vel std N",
        ours: |x| x.velocity_north.std(),
        source: |s| s.velocity_std_en.map(|v| v.1),
    },
    Figure {
        name: "vel max E",
        ours: |x| x.velocity_east.max_abs,
        source: |s| s.velocity_max_en.map(|v| v.0),
    },
    Figure {
        name: "vel max N",
        ours: |x| x.velocity_north.max_abs,
        source: |s| s.velocity_max_en.map(|v| v.1),
    },
    Figure {
        name: "mean abs E",
        ours: |x| x.position_east.mean_abs(),
        source: |s| s.mean_east_m,
    },
    Figure {
        name: "loss std E",
        ours: |x| x.outage_east.std(),
        source: |s| s.outage_std_en.map(|v| v.0),
    },
    Figure {
        name: "loss std N",
        ours: |x| x.outage_north.std(),
        source: |s| s.outage_std_en.map(|v| v.1),
    },
];

/// Each pipeline's improvement over the plain `kf` of its scenario, beside the source's.
fn improvement(r: &GnssInsResults) -> Table {
    let mut t = Table::new(
        [
            "scenario",
            "pipeline",
            "figure",
            "railfuse kf → pipeline",
            "ratio",
            "source kf → pipeline",
            "source ratio",
            "verdict",
        ],
        "lllrrrrl",
    );
    let scenarios: std::collections::BTreeSet<&str> =
        r.rows.iter().map(|x| x.scenario.as_str()).collect();
    for scenario in scenarios.into_iter().rev() {
        let rows: Vec<&PlaneErrors> = r.rows.iter().filter(|x| x.scenario == scenario).collect();
        let Some(kf) = rows.iter().find(|x| x.pipeline == "kf") else {
            continue;
        };
        let source_pipelines = rows
            .iter()
            .filter(|x| x.pipeline != "kf" && !TRAIN_PIPELINES.contains(&x.pipeline.as_str()));
        for row in source_pipelines {
            let src = SOURCE.iter().find(|s| s.pipeline == row.pipeline);
            for fig in &FIGURES {
                if fig.name.starts_with("loss") && row.outage_east.n == 0 {
                    continue;
                }
                let (k, x) = ((fig.ours)(kf), (fig.ours)(row));
                let source = src
                    .and_then(fig.source)
                    .zip((fig.source)(&SOURCE[0]))
                    .map(|(p, k)| (k, p));
                let source_ratio = source.map(|(k, p)| k / p);
                t.row([
                    scenario.to_owned(),
                    format!("`{}`", row.pipeline),
                    fig.name.to_owned(),
                    format!("{} → {}", f(k), f(x)),
                    ratio(k, x),
                    source.map_or("–".into(), |(k, p)| format!("{k} → {p}")),
                    source_ratio.map_or("–".into(), |s| format!("{s:.2}")),
                    against(k / x, source_ratio),
                ]);
            }
        }
    }
    t
}
