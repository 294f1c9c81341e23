//! Expectation–maximisation for a linear-Gaussian Kalman pipeline: the maximum-likelihood
//! motion-noise intensity `q` (`Q_t = q Q₁(dt_t)`, the model's noise at parameter 1, from each
//! step's real `dt`) and sensor variances, over all the logs at once.
//!
//! The model EM fits is the pipeline's own: its motion model and observation rows (a windowed
//! speed's `−W/2` included), every valid measurement in sensor-time order, the same start.
//! What it leaves out, because EM needs a linear-Gaussian model: gates (every measurement
//! counts) and sensor states (a pipeline with them is refused).
//!
//! M-step, with `S_t` the expected process noise of step t (see [`railfuse_refuse::filter::em`]):
//! ```text
//! q = Σ_t tr(Q₁(dt_t)⁺ S_t) / Σ_t rank Q₁(dt_t)
//! r_s = mean over sensor s's measurements of (z − h x_t|T)² + h P_t|T hᵀ
//! ```
//! For a jerk held over each step `Q₁ = g gᵀ` has rank 1 and `tr(Q₁⁺ S) = tr(Q₁ S)/tr(Q₁)²`.

use nalgebra::{RowSVector, SMatrix, SVector};

use super::params::Param;
use super::recording::{Recording, Step};
use crate::error::{Error, Result};
use railfuse_refuse::config::VarianceValue;
use railfuse_refuse::filter::em::{smooth, EmModel, Smoothed};
use railfuse_refuse::measurement::Quantity;
use railfuse_refuse::model::{
    ConstantAcceleration, ConstantVelocity, MotionModel, ProcessNoise, TransitionModel,
};
use railfuse_refuse::spec::{EstimatorSpec, PipelineSpec};

/// What an EM parameter is in the model.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Target {
    /// The motion model's one noise parameter.
    Motion,
    /// The variance of sensor `sensor`'s measurements of `quantity` (all of its quantities
    /// when None).
    Variance(usize, Option<Quantity>),
}

/// One measurement as EM uses it.
#[derive(Debug, Clone, Copy)]
struct Datum {
    sensor: usize,
    quantity: Quantity,
    z: f64,
    /// The variance when it is not tuned (configured, or the message's own).
    fixed_r: Option<f64>,
}

/// One log's epochs: measurements grouped by stamp, in time order.
struct Sequence {
    dts: Vec<f64>,
    /// `data[starts[t]..starts[t + 1]]` are epoch t's.
    starts: Vec<usize>,
    data: Vec<Datum>,
    /// Chainage to start from.
    chainage0: f64,
}

/// The EM problem: the pipeline's model and every log's measurements.
pub(super) struct PipelineEm {
    targets: Vec<Target>,
    spec: PipelineSpec,
    unit: MotionModel,
    rank_one: bool,
    sequences: Vec<Sequence>,
}

fn refuse(why: impl Into<String>) -> String {
    format!("em: {}", why.into())
}

impl PipelineEm {
    /// Checks that the pipeline and parameters suit EM and gathers the measurements.
    pub(super) fn new(
        spec: &PipelineSpec,
        params: &[Param],
        recordings: &[Recording],
    ) -> std::result::Result<Self, String> {
        if !matches!(spec.estimator, EstimatorSpec::Kalman { .. }) {
            return Err(refuse("needs a kalman pipeline (a linear-Gaussian model)"));
        }
        if !spec.sensor_states().is_empty() {
            return Err(refuse(
                "needs a linear-Gaussian model: this pipeline estimates sensor states",
            ));
        }
        let (unit, rank_one, motion_key) = match spec.motion {
            MotionModel::ConstantAcceleration(ConstantAcceleration {
                noise: ProcessNoise::WhiteJerkPsd(_),
            }) => (ProcessNoise::WhiteJerkPsd(1.0), false, "jerk_psd"),
            MotionModel::ConstantAcceleration(ConstantAcceleration {
                noise: ProcessNoise::PiecewiseJerkVariance(_),
            }) => (
                ProcessNoise::PiecewiseJerkVariance(1.0),
                true,
                "jerk_variance",
            ),
            MotionModel::ConstantVelocity(_) => {
                (ProcessNoise::WhiteJerkPsd(1.0), false, "acceleration_psd")
            }
            MotionModel::Singer(_) => {
                return Err(refuse(
                    "the Singer model's noise is not linear in one parameter",
                ))
            }
        };
        let unit = match spec.motion {
            MotionModel::ConstantVelocity(_) => MotionModel::ConstantVelocity(ConstantVelocity {
                acceleration_psd: 1.0,
            }),
            _ => MotionModel::ConstantAcceleration(ConstantAcceleration { noise: unit }),
        };
        let targets = params
            .iter()
            .map(|p| target(spec, p, motion_key))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let sequences = recordings
            .iter()
            .map(|r| sequence(spec, r))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        Ok(Self {
            targets,
            spec: spec.clone(),
            unit,
            rank_one,
            sequences,
        })
    }

    /// EM from `start` (one value per parameter, clamped to their bounds after each step),
    /// `iterations` at most, stopping when no value moves by more than 1e-6 of itself.
    /// Calls `each` with every iterate; returns the last and the log-likelihoods.
    pub(super) fn run(
        &self,
        params: &[Param],
        start: &[f64],
        iterations: usize,
        mut each: impl FnMut(&[f64]) -> Result<()>,
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let mut values = start.to_vec();
        let mut log_likelihood = Vec::new();
        for _ in 0..iterations {
            let (next, ll) = match self.spec.motion.dimension() {
                2 => self.step::<2>(&values),
                _ => self.step::<3>(&values),
            };
            log_likelihood.push(ll);
            let next: Vec<f64> = next
                .iter()
                .zip(params)
                .map(|(v, p)| v.clamp(p.min, p.max))
                .collect();
            let moved = next
                .iter()
                .zip(&values)
                .any(|(a, b)| (a - b).abs() > 1e-6 * b.abs().max(1e-300));
            values = next;
            match each(&values) {
                // The budget or Ctrl-C: this iterate is the answer.
                Err(Error::Budget | Error::Interrupted) => break,
                other => other?,
            }
            if !moved {
                break;
            }
        }
        Ok((values, log_likelihood))
    }

    /// The noise parameter and the variance of each measurement under `values`.
    fn q(&self, values: &[f64]) -> f64 {
        self.targets
            .iter()
            .zip(values)
            .find(|(t, _)| **t == Target::Motion)
            .map(|(_, v)| *v)
            .unwrap_or_else(|| motion_parameter(&self.spec.motion))
    }

    fn r(&self, values: &[f64], d: &Datum) -> Option<f64> {
        let tuned = self.targets.iter().zip(values).find(|(t, _)| {
            matches!(t, Target::Variance(s, q) if *s == d.sensor && q.is_none_or(|q| q == d.quantity))
        });
        tuned.map(|(_, v)| *v).or(d.fixed_r)
    }

    /// One E-step and M-step over every log; the new values and the log-likelihood.
    fn step<const N: usize>(&self, values: &[f64]) -> (Vec<f64>, f64) {
        let q = self.q(values);
        let unit = self.unit.with_sensor_states::<N>(Vec::new());
        let initial = &self.spec.initial;
        let (mut q_sum, mut q_rank) = (0.0, 0.0);
        let mut r_sum = vec![0.0; self.targets.len()];
        let mut r_n = vec![0usize; self.targets.len()];
        let mut ll = 0.0;
        for seq in &self.sequences {
            let model = Model::<N> {
                seq,
                em: self,
                values,
                unit: &*unit,
                q,
            };
            let mut x0 = SVector::<f64, N>::zeros();
            let mut p0 = SMatrix::<f64, N, N>::zeros();
            x0[0] = seq.chainage0;
            p0[(0, 0)] = 1e6;
            x0[1] = initial.speed_mps;
            p0[(1, 1)] = initial.speed_variance;
            if N > 2 {
                x0[2] = initial.acceleration_mps2;
                p0[(2, 2)] = initial.acceleration_variance;
            }
            let s: Smoothed<N> = smooth(&model, x0, p0);
            ll += s.log_likelihood;
            for t in 1..seq.starts.len() - 1 {
                let dt = seq.dts[t];
                let q1 = unit.process_noise(dt);
                let moment = s.process_moment(t, &unit.transition(dt));
                if self.rank_one {
                    let tr = q1.trace();
                    if tr > 0.0 {
                        q_sum += (q1 * moment).trace() / (tr * tr);
                        q_rank += 1.0;
                    }
                } else if let Some(c) = q1.cholesky() {
                    q_sum += (c.solve(&moment)).trace();
                    q_rank += N as f64;
                }
            }
            for t in 0..seq.starts.len() - 1 {
                for d in &seq.data[seq.starts[t]..seq.starts[t + 1]] {
                    let Some(k) = self.targets.iter().position(|tg| {
                        matches!(tg, Target::Variance(s, q) if *s == d.sensor && q.is_none_or(|q| q == d.quantity))
                    }) else {
                        continue;
                    };
                    let h = self.row::<N>(d);
                    let e = d.z - (h * s.means[t])[0];
                    r_sum[k] += e * e + (h * s.covariances[t] * h.transpose())[0];
                    r_n[k] += 1;
                }
            }
        }
        let next = self
            .targets
            .iter()
            .enumerate()
            .map(|(k, t)| match t {
                Target::Motion if q_rank > 0.0 => q_sum / q_rank,
                Target::Variance(..) if r_n[k] > 0 => r_sum[k] / r_n[k] as f64,
                _ => values[k],
            })
            .collect();
        (next, ll)
    }

    fn row<const N: usize>(&self, d: &Datum) -> RowSVector<f64, N> {
        d.quantity
            .motion_row::<N>(self.spec.sensors[d.sensor].speed_window_s)
            .unwrap_or_else(RowSVector::zeros)
    }
}

/// The pipeline's model under some values, as the E-step sees it.
struct Model<'a, const N: usize> {
    seq: &'a Sequence,
    em: &'a PipelineEm,
    values: &'a [f64],
    unit: &'a dyn TransitionModel<N>,
    q: f64,
}

impl<const N: usize> EmModel<N> for Model<'_, N> {
    fn epochs(&self) -> usize {
        self.seq.starts.len() - 1
    }
    fn transition(&self, t: usize) -> SMatrix<f64, N, N> {
        self.unit.transition(self.seq.dts[t])
    }
    fn process_noise(&self, t: usize) -> SMatrix<f64, N, N> {
        self.unit.process_noise(self.seq.dts[t]) * self.q
    }
    fn update(&self, t: usize, x: &mut SVector<f64, N>, p: &mut SMatrix<f64, N, N>) -> f64 {
        let mut ll = 0.0;
        for d in &self.seq.data[self.seq.starts[t]..self.seq.starts[t + 1]] {
            let Some(r) = self.em.r(self.values, d) else {
                continue;
            };
            let h = self.em.row::<N>(d);
            let nu = d.z - (h * *x)[0];
            let s = (h * *p * h.transpose())[0] + r;
            if !(s > 0.0) {
                continue;
            }
            let k: SVector<f64, N> = *p * h.transpose() / s;
            *x += k * nu;
            let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
            *p = railfuse_refuse::filter::symmetric(
                i_kh * *p * i_kh.transpose() + k * r * k.transpose(),
            );
            ll -= 0.5 * ((std::f64::consts::TAU * s).ln() + nu * nu / s);
        }
        ll
    }
}

/// The value of the motion model's noise parameter.
fn motion_parameter(m: &MotionModel) -> f64 {
    match *m {
        MotionModel::ConstantAcceleration(ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(q) | ProcessNoise::PiecewiseJerkVariance(q),
        }) => q,
        MotionModel::ConstantVelocity(ConstantVelocity { acceleration_psd }) => acceleration_psd,
        MotionModel::Singer(_) => f64::NAN,
    }
}

/// What parameter `p` is to EM: the motion noise (`motion.<key>`) or a sensor's fixed
/// variance (`sensor[T].variance`, `sensor[T].variance.<quantity>`).
fn target(spec: &PipelineSpec, p: &Param, motion_key: &str) -> std::result::Result<Target, String> {
    let text = p.path.to_string();
    if text == format!("motion.{motion_key}") {
        return Ok(Target::Motion);
    }
    let not_for_em = || {
        refuse(format!(
            "estimates the motion noise (motion.{motion_key}) and sensors' variances \
             (sensor[TOPIC].variance), not {text}"
        ))
    };
    let rest = text.strip_prefix("sensor[").ok_or_else(not_for_em)?;
    let (topic, key) = rest.split_once("].").ok_or_else(not_for_em)?;
    let sensor = spec.sensor_for(topic).ok_or_else(not_for_em)?;
    match key {
        "variance" => Ok(Target::Variance(sensor, None)),
        k => match k.strip_prefix("variance.") {
            Some(q) => serde_json::from_value::<Quantity>(serde_json::Value::String(q.into()))
                .map(|q| Target::Variance(sensor, Some(q)))
                .map_err(|_| not_for_em()),
            None => Err(not_for_em()),
        },
    }
}

/// A log's valid measurements grouped into epochs from its first chainage measurement (its
/// first measurement, at chainage 0, for a pipeline with no chainage sensor).
fn sequence(spec: &PipelineSpec, r: &Recording) -> std::result::Result<Sequence, String> {
    let mut all: Vec<(u64, Datum)> = Vec::new();
    for (si, schema) in r.schemas.iter().enumerate() {
        let Some(schema) = schema else {
            continue;
        };
        let binding = spec.bind(&r.path, si, schema).map_err(|e| e.to_string())?;
        for step in &r.steps {
            let Step::Sensor {
                sensor, start, end, ..
            } = *step
            else {
                continue;
            };
            if sensor != si {
                continue;
            }
            for m in &r.measurements[start as usize..end as usize] {
                let Some(&(_, variance)) = binding.fields.iter().find(|(q, _)| *q == m.quantity)
                else {
                    continue;
                };
                if !(m.valid && m.value.is_finite()) {
                    continue;
                }
                let fixed_r = match variance {
                    VarianceValue::Fixed(v) => Some(v),
                    VarianceValue::FromMessage(_) => m.reported_variance,
                };
                all.push((
                    m.stamp_ns,
                    Datum {
                        sensor: si,
                        quantity: m.quantity,
                        z: m.value,
                        fixed_r,
                    },
                ));
            }
        }
    }
    all.sort_by_key(|(t, _)| *t);
    let has_chainage = all.iter().any(|(_, d)| d.quantity == Quantity::Chainage);
    let first = match has_chainage {
        true => all
            .iter()
            .position(|(_, d)| d.quantity == Quantity::Chainage),
        false => (!all.is_empty()).then_some(0),
    };
    let Some(first) = first else {
        return Err(format!("{}: em: no measurements", r.path.display()));
    };
    let chainage0 = match has_chainage {
        true => all[first].1.z,
        false => 0.0,
    };
    let mut seq = Sequence {
        dts: Vec::new(),
        starts: Vec::new(),
        data: Vec::new(),
        chainage0,
    };
    let mut last: Option<u64> = None;
    for (t, d) in &all[first..] {
        if last != Some(*t) {
            seq.dts.push(last.map_or(0.0, |l| (t - l) as f64 / 1e9));
            seq.starts.push(seq.data.len());
            last = Some(*t);
        }
        seq.data.push(*d);
    }
    seq.starts.push(seq.data.len());
    Ok(seq)
}
