//! Streaming statistics of one signed error: RMSE, mean, signed envelope, maximum and the
//! 95th percentile from a log-bucketed histogram (1 % relative resolution), in memory that
//! does not grow with the number of samples.

use serde::Serialize;

/// Histogram of |error| in buckets growing by 1 % from 1 µ(unit) up to 10⁹.
#[derive(Debug, Clone)]
struct LogHistogram {
    counts: Vec<u64>,
}

const HIST_MIN: f64 = 1e-6;
const HIST_RATIO_LN: f64 = 0.009950330853168083; // ln(1.01)
const HIST_BUCKETS: usize = 3500; // 1e-6 · 1.01^3500 ≈ 1.4e9

impl LogHistogram {
    fn new() -> Self {
        Self {
            counts: vec![0; HIST_BUCKETS + 1],
        }
    }
    fn bucket(x: f64) -> usize {
        if x <= HIST_MIN {
            0
        } else {
            (((x / HIST_MIN).ln() / HIST_RATIO_LN).floor() as usize + 1).min(HIST_BUCKETS)
        }
    }
    fn upper_edge(bucket: usize) -> f64 {
        HIST_MIN * (HIST_RATIO_LN * bucket as f64).exp()
    }
    fn add(&mut self, x: f64) {
        self.counts[Self::bucket(x)] += 1;
    }
    /// The smallest bucket edge below which a share `q` of the samples lie.
    fn quantile(&self, q: f64, n: u64) -> f64 {
        let target = (q * n as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= target {
                return Self::upper_edge(i);
            }
        }
        f64::NAN
    }
}

/// Streaming statistics of one signed error.
#[derive(Debug, Clone)]
pub struct ErrorStats {
    n: u64,
    sum: f64,
    sum_sq: f64,
    max_abs: f64,
    min: f64,
    max: f64,
    hist: LogHistogram,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorSummary {
    pub samples: u64,
    pub rmse: f64,
    pub mean: f64,
    pub max_abs: f64,
    /// 95th percentile of |error| (to 1 %).
    pub p95_abs: f64,
    /// The signed envelope: most negative and most positive error.
    pub min: f64,
    pub max: f64,
}

impl Default for ErrorStats {
    fn default() -> Self {
        Self {
            n: 0,
            sum: 0.0,
            sum_sq: 0.0,
            max_abs: 0.0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            hist: LogHistogram::new(),
        }
    }
}

impl ErrorStats {
    pub fn add(&mut self, e: f64) {
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.max_abs = self.max_abs.max(e.abs());
        self.min = self.min.min(e);
        self.max = self.max.max(e);
        self.hist.add(e.abs());
    }

    /// Takes in the errors of `other` (another log's, to pool them).
    pub fn merge(&mut self, other: &ErrorStats) {
        self.n += other.n;
        self.sum += other.sum;
        self.sum_sq += other.sum_sq;
        self.max_abs = self.max_abs.max(other.max_abs);
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
        for (a, b) in self.hist.counts.iter_mut().zip(&other.hist.counts) {
            *a += b;
        }
    }

    pub fn summary(&self) -> Option<ErrorSummary> {
        (self.n > 0).then(|| ErrorSummary {
            samples: self.n,
            rmse: (self.sum_sq / self.n as f64).sqrt(),
            mean: self.sum / self.n as f64,
            max_abs: self.max_abs,
            p95_abs: self.hist.quantile(0.95, self.n).min(self.max_abs),
            min: self.min,
            max: self.max,
        })
    }
}
