//! S2: the filter in the plane. One constant-acceleration Kalman filter per axis, east and
//! north, each on `[d, v, a]` (source 002 keeps the axes apart): the GNSS coordinate and axle
//! 1's speed resolved on the axis with the map heading are its measurements, and, with an
//! acceleration input, the axle's smoothed acceleration resolved the same way drives it.
//!
//! Each axis also carries two sensor states, railfuse's answer to errors the source treats
//! as white: the GNSS receiver's bias on the axis (first-order Gauss–Markov: a fix measures
//! `d + b_g`) and axle 1's speed error resolved on the axis (wheel wear: the axle measures
//! `v + b_v`). Without their settings they stay exactly 0 with no variance, and the filter
//! is the source's. The state per axis is `[d, v, a, b_g, b_v]`.

use nalgebra::{Matrix2, Matrix3, RowSVector, SMatrix, SVector, Vector3};

use crate::filter::{Innovation, KalmanFilter};
use crate::model::{AccelerationInput, ConstantAcceleration, TransitionModel};

/// A first-order Gauss–Markov error: standard deviation and time constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussMarkov {
    pub std: f64,
    pub time_constant_s: f64,
}

impl GaussMarkov {
    /// `φ = e^(−dt/τ)` and the variance `σ² (1 − φ²)` it gains over `dt`.
    fn step(&self, dt: f64) -> (f64, f64) {
        let phi = (-dt / self.time_constant_s).exp();
        (phi, self.std * self.std * (1.0 - phi * phi))
    }
}

/// One axis's model: the motion states and the two sensor states.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AxisModel {
    motion: PlaneMotion,
    /// Whether this step has a measured input.
    input_known: bool,
    gnss_bias: Option<GaussMarkov>,
    axle_bias: Option<GaussMarkov>,
}

impl AxisModel {
    /// The motion part's F and Q over `dt`; `input_known` picks an input model's σ.
    fn motion_matrices(&self, dt: f64) -> (Matrix3<f64>, Matrix3<f64>) {
        match self.motion {
            PlaneMotion::Input { known, unknown } => {
                let m = if self.input_known { known } else { unknown };
                (m.transition(dt), m.process_noise(dt))
            }
            PlaneMotion::ConstantAcceleration(m) => (m.transition(dt), m.process_noise(dt)),
        }
    }
}

impl TransitionModel<5> for AxisModel {
    fn transition(&self, dt: f64) -> SMatrix<f64, 5, 5> {
        let mut f = SMatrix::<f64, 5, 5>::zeros();
        f.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&self.motion_matrices(dt).0);
        f[(3, 3)] = self.gnss_bias.map_or(1.0, |b| b.step(dt).0);
        f[(4, 4)] = self.axle_bias.map_or(1.0, |b| b.step(dt).0);
        f
    }

    fn process_noise(&self, dt: f64) -> SMatrix<f64, 5, 5> {
        let mut q = SMatrix::<f64, 5, 5>::zeros();
        q.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&self.motion_matrices(dt).1);
        q[(3, 3)] = self.gnss_bias.map_or(0.0, |b| b.step(dt).1);
        q[(4, 4)] = self.axle_bias.map_or(0.0, |b| b.step(dt).1);
        q
    }
}

/// East or north.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    East,
    North,
}

impl Axis {
    pub const BOTH: [Axis; 2] = [Axis::East, Axis::North];

    pub fn name(self) -> &'static str {
        match self {
            Axis::East => "east",
            Axis::North => "north",
        }
    }

    /// The axis component of a unit vector along heading `h` (clockwise from north).
    pub fn component(self, heading_rad: f64) -> f64 {
        match self {
            Axis::East => heading_rad.sin(),
            Axis::North => heading_rad.cos(),
        }
    }
}

/// What moves the state between measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlaneMotion {
    /// Driven by a measured acceleration per axis; while none is at hand (the axle failed,
    /// too few samples yet), by 0 with the `unknown` model's σ (the train's whole range).
    Input {
        known: AccelerationInput,
        unknown: AccelerationInput,
    },
    /// Plain constant acceleration (white jerk).
    ConstantAcceleration(ConstantAcceleration),
}

#[derive(Debug, Clone)]
pub struct PlaneFilter {
    pub east: KalmanFilter<5>,
    pub north: KalmanFilter<5>,
    model: AxisModel,
}

/// A fix measures the position and the receiver's bias.
const POSITION: RowSVector<f64, 5> =
    RowSVector::from_array_storage(nalgebra::ArrayStorage([[1.0], [0.0], [0.0], [1.0], [0.0]]));
/// Axle 1 measures the speed and its own error.
const SPEED: RowSVector<f64, 5> =
    RowSVector::from_array_storage(nalgebra::ArrayStorage([[0.0], [1.0], [0.0], [0.0], [1.0]]));

impl PlaneFilter {
    /// Starts at (east, north) with variance `position_var` per axis, moving at `speed` along
    /// `heading_rad` with variance `speed_var`, acceleration 0 ± `acceleration_std`.
    /// `gnss_bias` and `axle_bias` turn on the sensor states (each axis's share of the
    /// receiver's bias, of axle 1's speed error).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        motion: PlaneMotion,
        gnss_bias: Option<GaussMarkov>,
        axle_bias: Option<GaussMarkov>,
        (east_m, north_m): (f64, f64),
        position_var: f64,
        (speed_mps, heading_rad): (f64, f64),
        speed_var: f64,
        acceleration_var: f64,
    ) -> Self {
        let var = |b: Option<GaussMarkov>| b.map_or(0.0, |b| b.std * b.std);
        let axis = |d: f64, u: f64| {
            KalmanFilter::new(
                SVector::<f64, 5>::from([d, speed_mps * u, 0.0, 0.0, 0.0]),
                SMatrix::<f64, 5, 5>::from_diagonal(&SVector::<f64, 5>::from([
                    position_var,
                    speed_var,
                    acceleration_var,
                    var(gnss_bias),
                    var(axle_bias),
                ])),
            )
        };
        Self {
            east: axis(east_m, heading_rad.sin()),
            north: axis(north_m, heading_rad.cos()),
            model: AxisModel {
                motion,
                input_known: false,
                gnss_bias,
                axle_bias,
            },
        }
    }

    pub fn axis(&self, a: Axis) -> &KalmanFilter<5> {
        match a {
            Axis::East => &self.east,
            Axis::North => &self.north,
        }
    }

    fn axis_mut(&mut self, a: Axis) -> &mut KalmanFilter<5> {
        match a {
            Axis::East => &mut self.east,
            Axis::North => &mut self.north,
        }
    }

    /// Time update over `dt` s; `input` is `U` per axis (east, north), used when the motion
    /// takes an input.
    pub fn predict(&mut self, dt: f64, input: Option<(f64, f64)>) {
        let m = AxisModel {
            input_known: input.is_some(),
            ..self.model
        };
        let (ue, un) = input.unwrap_or((0.0, 0.0));
        let term = |u: f64| match m.motion {
            PlaneMotion::Input { known, .. } => {
                let b = known.input_term(dt, u);
                SVector::<f64, 5>::from([b[0], b[1], b[2], 0.0, 0.0])
            }
            PlaneMotion::ConstantAcceleration(_) => SVector::zeros(),
        };
        self.east.predict_with_input(&m, dt, &term(ue));
        self.north.predict_with_input(&m, dt, &term(un));
    }

    /// The innovation a position measurement on `axis` would give.
    pub fn position_innovation(&self, axis: Axis, r: f64, z: f64) -> Innovation {
        self.axis(axis).innovation(&POSITION, r, z)
    }

    pub fn speed_innovation(&self, axis: Axis, r: f64, z: f64) -> Innovation {
        self.axis(axis).innovation(&SPEED, r, z)
    }

    /// Joseph-form update of `axis` with a position measurement.
    pub fn update_position(&mut self, axis: Axis, r: f64, z: f64) -> Innovation {
        self.axis_mut(axis).update(&POSITION, r, z)
    }

    pub fn update_speed(&mut self, axis: Axis, r: f64, z: f64) -> Innovation {
        self.axis_mut(axis).update(&SPEED, r, z)
    }

    /// (east, north).
    pub fn position(&self) -> (f64, f64) {
        (self.east.estimate.state[0], self.north.estimate.state[0])
    }

    /// The 2×2 covariance of (east, north): diagonal, the axes being separate filters.
    pub fn position_covariance(&self) -> Matrix2<f64> {
        Matrix2::new(
            self.east.estimate.covariance[(0, 0)],
            0.0,
            0.0,
            self.north.estimate.covariance[(0, 0)],
        )
    }

    /// The along-track state `[s-offset, v, a]` and covariance at heading `h`: each axis's
    /// state weighted by its component of the track direction, `x = u_e x_e + u_n x_n`,
    /// `P = u_e² P_e + u_n² P_n`. The first component is the along-track position offset
    /// from the plane origin; the caller replaces it with the matched chainage.
    pub fn along_track(&self, heading_rad: f64) -> (Vector3<f64>, Matrix3<f64>) {
        let (ue, un) = (heading_rad.sin(), heading_rad.cos());
        let (e, n) = (&self.east.estimate, &self.north.estimate);
        let x = |k: &crate::filter::StateAndCovariance<5>| k.state.fixed_rows::<3>(0).into_owned();
        let p = |k: &crate::filter::StateAndCovariance<5>| {
            k.covariance.fixed_view::<3, 3>(0, 0).into_owned()
        };
        (x(e) * ue + x(n) * un, p(e) * (ue * ue) + p(n) * (un * un))
    }

    /// The sensor states of each axis: (receiver bias, axle speed error) east and north.
    pub fn sensor_states(&self) -> [(f64, f64); 2] {
        [&self.east, &self.north].map(|k| (k.estimate.state[3], k.estimate.state[4]))
    }

    pub fn is_finite(&self) -> bool {
        self.east.estimate.is_finite() && self.north.estimate.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ProcessNoise;

    #[test]
    fn a_train_heading_north_east_moves_on_both_axes_and_reads_its_speed_back() {
        let h = std::f64::consts::FRAC_PI_4;
        let mut f = PlaneFilter::new(
            PlaneMotion::ConstantAcceleration(ConstantAcceleration {
                noise: ProcessNoise::WhiteJerkPsd(0.01),
            }),
            None,
            None,
            (0.0, 0.0),
            1.0,
            (20.0, h),
            0.01,
            0.01,
        );
        f.predict(1.0, None);
        let (e, n) = f.position();
        let s = 20.0 * h.sin();
        assert!((e - s).abs() < 1e-12 && (n - s).abs() < 1e-12);
        let (x, p) = f.along_track(h);
        assert!((x[1] - 20.0).abs() < 1e-12, "{}", x[1]);
        assert!(p[(0, 0)] > 1.0 && p == p.transpose());
    }

    #[test]
    fn the_acceleration_input_drives_the_speed_where_the_plain_model_coasts() {
        let start =
            |motion| PlaneFilter::new(motion, None, None, (0.0, 0.0), 1.0, (10.0, 0.0), 0.01, 0.01);
        let input = |input_std_mps2| AccelerationInput {
            input_std_mps2,
            correlation_time_s: 0.5,
        };
        let mut driven = start(PlaneMotion::Input {
            known: input(0.1),
            unknown: input(1.5),
        });
        let mut coasting = start(PlaneMotion::ConstantAcceleration(ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(0.01),
        }));
        for _ in 0..10 {
            driven.predict(0.1, Some((0.0, 1.0)));
            coasting.predict(0.1, Some((0.0, 1.0)));
        }
        assert!((driven.north.estimate.state[1] - 11.0).abs() < 1e-9);
        assert!((coasting.north.estimate.state[1] - 10.0).abs() < 1e-9);
        // Without a measured input the speed's variance grows with the train's whole range.
        let before = driven.north.estimate.covariance[(1, 1)];
        driven.predict(1.0, None);
        let grown = driven.north.estimate.covariance[(1, 1)] - before;
        assert!(grown > 1.5 * 1.5 * 0.9, "{grown}");
    }

    #[test]
    fn a_modelled_receiver_bias_takes_a_persistent_offset_the_plain_filter_believes() {
        // Fixes 2 m east of a train standing still, precise to 10 cm: the plain filter moves
        // 2 m and claims centimetres; with the bias state it keeps an honest σ.
        let cv = PlaneMotion::ConstantAcceleration(ConstantAcceleration {
            noise: ProcessNoise::WhiteJerkPsd(1e-4),
        });
        let bias = GaussMarkov {
            std: 2.0,
            time_constant_s: 300.0,
        };
        let run = |b: Option<GaussMarkov>| {
            let mut f = PlaneFilter::new(cv, b, None, (0.0, 0.0), 0.01, (0.0, 0.0), 1e-4, 1e-4);
            for _ in 0..100 {
                f.predict(0.1, None);
                f.update_speed(Axis::East, 1e-4, 0.0);
                f.update_position(Axis::East, 0.01, 2.0);
            }
            (f.position().0, f.position_covariance()[(0, 0)].sqrt())
        };
        let (plain, plain_std) = run(None);
        let (modelled, modelled_std) = run(Some(bias));
        assert!(plain > 1.9 && plain_std < 0.1, "{plain} ± {plain_std}");
        assert!(
            modelled < 0.2 && modelled_std > 0.05,
            "{modelled} ± {modelled_std}"
        );
    }
}
