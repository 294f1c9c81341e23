//! The searches over the parameters, in unit coordinates (each parameter mapped onto 0 … 1
//! between its bounds, on its own scale): grid search, and argmin's Nelder–Mead simplex and
//! particle swarm. Every evaluation goes through one [`Evaluations`] book, which numbers the
//! evaluations in the order they are asked for (so a parallel batch gives the same trace and
//! the same best on every run), keeps the best, stops at the budget or on Ctrl-C, and tells the
//! progress callback.
//!
//! Bayesian optimisation is egobox's efficient global optimisation (EGO): a Gaussian-process
//! model of the objective over the unit box, fitted to every evaluation so far, sampled next
//! where the expected improvement is largest; it starts from a Latin-hypercube design.

use std::borrow::Borrow;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use argmin::core::{CostFunction, Executor, SendAlias, SyncAlias};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand_xoshiro::rand_core::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use railfuse_refuse::config::OptimiserKind;

/// One evaluation of the trace.
#[derive(Debug, Clone, Serialize)]
pub struct TraceRow {
    /// 0 is the file's own values.
    pub evaluation: usize,
    pub elapsed_s: f64,
    pub objective: f64,
    /// The best objective up to and including this evaluation.
    pub best: f64,
    /// The candidate, in the parameters' own units.
    pub values: Vec<f64>,
}

/// How the search goes, for a progress display.
#[derive(Debug, Clone, Copy)]
pub struct SearchProgress {
    pub evaluations: usize,
    pub budget: usize,
    pub best: f64,
    pub elapsed_s: f64,
}

/// The book of every evaluation a search makes.
pub struct Evaluations<'a> {
    /// Unit coordinates to the parameters' own values.
    values_of: &'a (dyn Fn(&[f64]) -> Vec<f64> + Sync),
    /// The objective at those values.
    objective: &'a (dyn Fn(&[f64]) -> Result<f64> + Sync),
    pub budget: usize,
    asked: AtomicUsize,
    rows: Mutex<Vec<TraceRow>>,
    /// Objective by candidate (bit patterns of its values): a simplex that comes back to a
    /// point, or a swarm clamped onto a bound, is not replayed again.
    seen: Mutex<HashMap<Vec<u64>, f64>>,
    started: Instant,
    stop: Option<&'a AtomicBool>,
    progress: Option<&'a (dyn Fn(SearchProgress) + Sync)>,
}

/// Why a search ended before its optimiser said it had converged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    Converged,
    Budget,
    Interrupted,
}

impl<'a> Evaluations<'a> {
    pub fn new(
        values_of: &'a (dyn Fn(&[f64]) -> Vec<f64> + Sync),
        objective: &'a (dyn Fn(&[f64]) -> Result<f64> + Sync),
        budget: usize,
        stop: Option<&'a AtomicBool>,
        progress: Option<&'a (dyn Fn(SearchProgress) + Sync)>,
    ) -> Self {
        Self {
            values_of,
            objective,
            budget,
            asked: AtomicUsize::new(0),
            rows: Mutex::new(Vec::new()),
            seen: Mutex::new(HashMap::new()),
            started: Instant::now(),
            stop,
            progress,
        }
    }

    /// Enters an evaluation made outside the search (the file's own values), as the next.
    pub fn record(&self, values: Vec<f64>, objective: f64) {
        let key = values.iter().map(|x| x.to_bits()).collect();
        self.seen.lock().expect("memo lock").insert(key, objective);
        let evaluation = self.asked.fetch_add(1, Ordering::SeqCst);
        self.rows.lock().expect("trace lock").push(TraceRow {
            evaluation,
            elapsed_s: self.started.elapsed().as_secs_f64(),
            objective,
            best: f64::NAN,
            values,
        });
    }

    /// Evaluates a batch of points in parallel, numbered in order.
    pub fn batch(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        if self.stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
            return Err(Error::Interrupted);
        }
        let first = self.asked.fetch_add(points.len(), Ordering::SeqCst);
        if first >= self.budget {
            return Err(Error::Budget);
        }
        // Points past the budget are not evaluated.
        let take = points.len().min(self.budget - first);
        let key = |u: &[f64]| u.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        let results: Vec<Result<(f64, Vec<f64>)>> = points[..take]
            .par_iter()
            .map(|u| {
                let values = (self.values_of)(u);
                let known = self
                    .seen
                    .lock()
                    .expect("memo lock")
                    .get(&key(&values))
                    .copied();
                let objective = match known {
                    Some(o) => o,
                    None => (self.objective)(&values)?,
                };
                self.seen
                    .lock()
                    .expect("memo lock")
                    .insert(key(&values), objective);
                Ok((objective, values))
            })
            .collect();
        let mut values = Vec::with_capacity(take);
        {
            let mut rows = self.rows.lock().expect("trace lock");
            for (k, r) in results.into_iter().enumerate() {
                let (objective, candidate) = r?;
                rows.push(TraceRow {
                    evaluation: first + k,
                    elapsed_s: self.started.elapsed().as_secs_f64(),
                    objective,
                    best: f64::NAN, // filled in order in `finish`
                    values: candidate,
                });
                values.push(objective);
            }
            if let Some(progress) = self.progress {
                progress(SearchProgress {
                    evaluations: rows.len(),
                    budget: self.budget,
                    best: rows
                        .iter()
                        .map(|r| r.objective)
                        .fold(f64::INFINITY, f64::min),
                    elapsed_s: self.started.elapsed().as_secs_f64(),
                });
            }
        }
        if take < points.len() {
            return Err(Error::Budget);
        }
        Ok(values)
    }

    /// The trace in evaluation order with its running best, and the best row (lowest
    /// objective, the earliest of equals).
    pub fn finish(self) -> (Vec<TraceRow>, Option<TraceRow>) {
        let mut rows = self.rows.into_inner().expect("trace lock");
        rows.sort_by_key(|r| r.evaluation);
        let mut best: Option<TraceRow> = None;
        for r in &mut rows {
            if best.as_ref().is_none_or(|b| r.objective < b.objective) {
                best = Some(r.clone());
            }
            r.best = best.as_ref().map_or(f64::INFINITY, |b| b.objective);
        }
        (rows, best)
    }
}

/// The settings of one search.
#[derive(Debug, Clone)]
pub struct SearchSettings {
    pub optimiser: OptimiserKind,
    /// Grid points per parameter.
    pub steps: Vec<usize>,
    /// Where the search starts (the file's values), unit coordinates.
    pub start: Vec<f64>,
    pub seed: u64,
}

/// Particles of the swarm: enough to cover a few parameters, few enough to iterate.
pub fn swarm_size(dimensions: usize) -> usize {
    (10 + 2 * dimensions).min(40)
}

/// Runs the search; the best point is in the book.
pub fn search(s: &SearchSettings, book: &Evaluations<'_>) -> Result<Ending> {
    let ended = match s.optimiser {
        OptimiserKind::Grid => grid(s, book),
        OptimiserKind::NelderMead => nelder_mead(s, book),
        OptimiserKind::Pso => swarm(s, book),
        #[cfg(feature = "bayesian")]
        OptimiserKind::Bayesian => bayesian(s, book),
        #[cfg(not(feature = "bayesian"))]
        OptimiserKind::Bayesian => unreachable!("refused by the tuner: {}", WITHOUT_BAYESIAN),
        OptimiserKind::Em => unreachable!("EM is run by the tuner, not searched"),
    };
    match ended {
        Ok(()) => Ok(Ending::Converged),
        Err(Error::Budget) => Ok(Ending::Budget),
        Err(Error::Interrupted) => Ok(Ending::Interrupted),
        Err(e) => Err(e),
    }
}

/// Every point of the grid, in batches (so Ctrl-C and the budget are heard).
fn grid(s: &SearchSettings, book: &Evaluations<'_>) -> Result<()> {
    let total: usize = s.steps.iter().product();
    let point = |mut k: usize| -> Vec<f64> {
        s.steps
            .iter()
            .map(|&n| {
                let i = k % n;
                k /= n;
                i as f64 / (n - 1) as f64
            })
            .collect()
    };
    let batch = 4 * rayon::current_num_threads();
    let mut k = 0;
    while k < total {
        let points: Vec<Vec<f64>> = (k..(k + batch).min(total)).map(point).collect();
        book.batch(&points)?;
        k += points.len();
    }
    Ok(())
}

/// argmin's view of the objective: unit coordinates in, objective out; batches through the
/// book.
struct Problem<'a, 'b> {
    book: &'a Evaluations<'b>,
}

impl CostFunction for Problem<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, u: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        Ok(self.book.batch(std::slice::from_ref(u)).map_err(wrap)?[0])
    }

    fn bulk_cost<P>(&self, params: &[P]) -> std::result::Result<Vec<f64>, argmin::core::Error>
    where
        P: Borrow<Vec<f64>> + SyncAlias,
        f64: SendAlias,
        Self: SyncAlias,
    {
        let points: Vec<Vec<f64>> = params.iter().map(|p| p.borrow().clone()).collect();
        self.book.batch(&points).map_err(wrap)
    }
}

/// Our error through argmin's (anyhow) error, to be taken back out by [`unwrap`].
fn wrap(e: Error) -> argmin::core::Error {
    argmin::core::Error::new(e)
}

fn unwrap(e: argmin::core::Error) -> Error {
    match e.downcast::<Error>() {
        Ok(e) => e,
        Err(other) => Error::Search(other.to_string()),
    }
}

/// Nelder–Mead from the file's values, the first simplex a fifth of each range away.
fn nelder_mead(s: &SearchSettings, book: &Evaluations<'_>) -> Result<()> {
    let mut simplex = vec![s.start.clone()];
    for i in 0..s.start.len() {
        let mut v = s.start.clone();
        v[i] = if v[i] + 0.2 <= 1.0 {
            v[i] + 0.2
        } else {
            v[i] - 0.2
        };
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-6)
        .map_err(unwrap)?;
    Executor::new(Problem { book }, solver)
        .configure(|state| state.max_iters(u64::MAX))
        .run()
        .map_err(unwrap)?;
    Ok(())
}

/// A seeded particle swarm over the unit box.
fn swarm(s: &SearchSettings, book: &Evaluations<'_>) -> Result<()> {
    let n = s.start.len();
    let rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(s.seed);
    let solver =
        ParticleSwarm::new((vec![0.0; n], vec![1.0; n]), swarm_size(n)).with_rng_generator(rng);
    Executor::new(Problem { book }, solver)
        .configure(|state| state.max_iters(u64::MAX))
        .run()
        .map_err(unwrap)?;
    Ok(())
}

/// Points EGO's first design holds: enough to fit a Gaussian process in `n` dimensions.
pub fn initial_design(dimensions: usize) -> usize {
    (2 * dimensions + 1).max(5)
}

/// Why a build without the `bayesian` feature refuses `--optimiser bayesian`.
pub const WITHOUT_BAYESIAN: &str =
    "this railfuse was built without Bayesian optimisation: build it with `--features bayesian`";

/// egobox's EGO over the unit box, its first design a seeded Latin hypercube (the file's
/// values are already in the book as evaluation 0).
#[cfg(feature = "bayesian")]
fn bayesian(s: &SearchSettings, book: &Evaluations<'_>) -> Result<()> {
    use egobox_ego::EgorBuilder;
    use ndarray::{Array1, Array2, ArrayView2};
    let n = s.start.len();
    let limits = Array2::from_shape_fn((n, 2), |(_, j)| j as f64);
    let failure = std::sync::Mutex::new(None::<Error>);
    let objective = |x: &ArrayView2<f64>| -> std::result::Result<Array2<f64>, String> {
        let points: Vec<Vec<f64>> = x.rows().into_iter().map(|r| r.to_vec()).collect();
        match book.batch(&points) {
            // An infinite objective (a refused candidate) would break the model: a large
            // finite one keeps EGO away from it.
            Ok(v) => Ok(Array2::from_shape_fn((v.len(), 1), |(i, _)| {
                v[i].min(1e300)
            })),
            Err(e) => {
                let why = e.to_string();
                *failure.lock().expect("failure lock") = Some(e);
                Err(why)
            }
        }
    };
    let design = initial_design(n);
    let result = EgorBuilder::optimize(objective)
        .configure(|c| {
            c.n_doe(design)
                .max_iters(book.budget)
                .seed(s.seed)
                .stop_on_error(true)
        })
        .min_within(&limits)
        .and_then(|egor| egor.run());
    if let Some(e) = failure.into_inner().expect("failure lock") {
        return Err(e);
    }
    let _: Array1<f64> = result.map_err(|e| Error::Search(e.to_string()))?.x_opt;
    Ok(())
}
