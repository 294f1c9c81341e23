//! The roof antenna's lean, taken out of its fixes before the centre line is fitted through
//! them.
//!
//! An antenna `z` above the rail leans with the body: in a curve with the cant's and the
//! body's roll `φ` it sits `z sin φ` towards the inside of the curve (0.4 m for 4 m and 150 mm
//! of cant), and a line fitted through its fixes runs that far inside the track. A run's IMU
//! gives `φ` without a map: what it reads across and up in the body is the level frame's
//! specific force (the centripetal `v ω` across, gravity `g` up) turned by the roll, so
//!
//! ```text
//! φ = atan2(f_y, f_z) − atan2(v ω_z, g)
//! ```
//!
//! with the IMU's readings turned into the body by its mounting (the drawing's, or
//! `calibrate`'s), `v` the receiver's Doppler speed and `ω_z` the gyro's rate about up. What is
//! left of the mounting's roll is the roll on the straights, where a line has no cant: their
//! median is taken off. Each fix is then moved across the track, along its course, by the
//! antenna's place across the level frame, `y cos φ − z sin φ`; a fix with no course within
//! [`MAX_COURSE_AGE_S`] (a train that has not moved yet) is left where it is.

use nalgebra::Vector3;
use railfuse_catalog::messages::{SensorMount, Vehicle};
use railfuse_catalog::vehicle::GRAVITY_MPS2;

use crate::fixes::{Course, RunFixes};
use crate::motion::{Lean, TiltStep};
use crate::multipath::median;

/// A fix takes the roll of the steps this close to it, ns.
const HALF_WINDOW_NS: u64 = 500_000_000;
/// The newest course older (or newer) than this says nothing of a fix's heading, s.
pub const MAX_COURSE_AGE_S: f64 = 30.0;
/// A step turning slower than this at speed is on a straight, rad/s (a 60 km radius at
/// 30 m/s).
const STRAIGHT_RATE_RADPS: f64 = 5e-4;
/// Straights need at least this many steps to say what is left of the mounting's roll.
const MIN_STRAIGHT_STEPS: usize = 50;

/// Moves `run`'s fixes from its antenna to the centre line across the track, with the roll
/// from its IMU's steps ([`crate::fixes::RunFixes::tilt`]), keeps each fix's cant (the roll
/// less the body's lean, [`Vehicle::body_roll`]) in `run.cant_rad`, and notes what it did in
/// `run.lean`. A run without an IMU and a vehicle is left as it is.
pub fn take_out(run: &mut RunFixes) {
    let Some(tilt) = run.tilt.take() else { return };
    run.lean = take_out_with(run, &tilt.steps, &tilt.vehicle, (&tilt.imu, &tilt.antenna));
}

/// [`take_out`] with the IMU's `steps`, `imu` and `antenna` being topics placed by `vehicle`;
/// `None` without IMU steps.
fn take_out_with(
    run: &mut RunFixes,
    steps: &[TiltStep],
    vehicle: &Vehicle,
    (imu, antenna): (&str, &str),
) -> Option<Lean> {
    let (imu, antenna) = (vehicle.mount_or_front(imu), vehicle.mount_or_front(antenna));
    let [_, y, z] = antenna.lever_arm_m;
    if steps.is_empty() || run.fused {
        return None;
    }
    let rolls: Vec<StepRoll> = steps
        .iter()
        .map(|s| roll_of(s, &imu, &run.courses))
        .collect();
    let straight: Vec<f64> = rolls
        .iter()
        .filter(|r| r.straight)
        .map(|r| r.roll_rad)
        .collect();
    let straight_roll_rad = match straight.len() >= MIN_STRAIGHT_STEPS {
        true => median(straight),
        false => 0.0,
    };
    let mut lean = Lean {
        moved: 0,
        max_m: 0.0,
        straight_roll_rad,
    };
    run.cant_rad = vec![None; run.fixes.len()];
    for (f, cant) in run.fixes.iter_mut().zip(&mut run.cant_rad) {
        let lo = rolls.partition_point(|r| r.stamp_ns + HALF_WINDOW_NS < f.stamp_ns);
        let hi = lo + rolls[lo..].partition_point(|r| r.stamp_ns <= f.stamp_ns + HALF_WINDOW_NS);
        if hi == lo {
            continue;
        }
        let (near, n) = (&rolls[lo..hi], (hi - lo) as f64);
        let mean = |x: fn(&StepRoll) -> f64| near.iter().map(x).sum::<f64>() / n;
        let phi = mean(|r| r.roll_rad) - straight_roll_rad;
        let (v, turn) = (mean(|r| r.speed_mps), mean(|r| r.turn_radps));
        *cant = Some(cant_of(vehicle, phi, v, turn));
        let Some(heading) = course_at(&run.courses, f.stamp_ns, MAX_COURSE_AGE_S) else {
            continue;
        };
        // The antenna's place to the left of the centre line, in the level frame.
        let left = y * phi.cos() - z * phi.sin();
        let (s, c) = heading.course_rad.sin_cos();
        // Left of a heading ψ clockwise from north is (−cos ψ, sin ψ).
        f.east_m += left * c;
        f.north_m -= left * s;
        lean.moved += 1;
        lean.max_m = lean.max_m.max(left.abs());
    }
    Some(lean)
}

/// The cant's roll in a body rolled `phi` at `v` turning `turn` (counter-clockwise about up):
/// `phi` less the body's lean, which itself depends on the cant (a few fixed-point steps: the
/// lean is a tenth of the roll).
fn cant_of(vehicle: &Vehicle, phi: f64, v: f64, turn: f64) -> f64 {
    let curvature = match v > 1.0 {
        true => -turn / v,
        false => 0.0,
    };
    let mut cant = phi;
    for _ in 0..4 {
        cant = phi - vehicle.body_roll(v, curvature, cant);
    }
    cant
}

/// What one IMU step says of the body.
struct StepRoll {
    stamp_ns: u64,
    /// The left side up positive.
    roll_rad: f64,
    /// On a straight at speed.
    straight: bool,
    /// The receiver's speed.
    speed_mps: f64,
    /// The gyro's rate about the body's up axis (counter-clockwise).
    turn_radps: f64,
}

/// A step's roll, speed and turn, the IMU's readings turned into the body by its mounting.
fn roll_of(s: &TiltStep, imu: &SensorMount, courses: &[Course]) -> StepRoll {
    let r = imu.mounting();
    let f = r * Vector3::from(s.specific_force);
    let w = r * Vector3::from(s.angular_rate);
    let v = course_at(courses, s.stamp_ns, 1.0).map_or(0.0, |c| c.speed_mps);
    let roll = |turn: f64| f.y.atan2(f.z) - (v * turn).atan2(GRAVITY_MPS2);
    // The turn about up is the body's rates rolled back (`q sin φ + r cos φ`): once with the
    // roll the body's z rate gives, which is enough (0.1 rad of roll: 2 mm at 4 m otherwise).
    let first = roll(w.z);
    let phi = roll(w.y * first.sin() + w.z * first.cos());
    StepRoll {
        stamp_ns: s.stamp_ns,
        roll_rad: phi,
        straight: v >= crate::fixes::MIN_COURSE_SPEED_MPS && w.z.abs() < STRAIGHT_RATE_RADPS,
        speed_mps: v,
        turn_radps: w.z,
    }
}

/// The course nearest `stamp_ns`, if one is within `max_age_s`.
fn course_at(courses: &[Course], stamp_ns: u64, max_age_s: f64) -> Option<Course> {
    let i = courses.partition_point(|c| c.stamp_ns < stamp_ns);
    let near = [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|k| courses.get(k))
        .min_by_key(|c| c.stamp_ns.abs_diff(stamp_ns))?;
    (near.stamp_ns.abs_diff(stamp_ns) as f64 / 1e9 <= max_age_s).then_some(*near)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixes::Fix;
    use nalgebra::Rotation3;

    /// A train heading north at 30 m/s through a right-hand curve of 1 km rolled 0.1 rad (left
    /// side up), its IMU turned 1° in roll: the antenna 4 m up sits 0.4 m right of the centre
    /// line (east), and the fix is moved back west by that; the cant is the roll.
    #[test]
    fn a_roof_antennas_fix_in_a_canted_curve_moves_back_to_the_centre_line() {
        let (v, omega_z, phi) = (30.0, -30.0 / 1000.0, 0.1);
        let imu = SensorMount {
            mounting_deg: [1.0, 0.0, 0.0],
            ..SensorMount::at_front("/imu")
        };
        let level = Vector3::new(0.0, v * omega_z, GRAVITY_MPS2);
        let body = Rotation3::from_euler_angles(phi, 0.0, 0.0).inverse() * level;
        let rate =
            Rotation3::from_euler_angles(phi, 0.0, 0.0).inverse() * Vector3::new(0.0, 0.0, omega_z);
        let sensor = |x: Vector3<f64>| (imu.mounting().inverse() * x).into();
        let s = 1_000_000_000u64;
        let steps: Vec<TiltStep> = (0..20)
            .map(|k| TiltStep {
                stamp_ns: k * s / 10,
                specific_force: sensor(body),
                angular_rate: sensor(rate),
            })
            .collect();
        let course = |k: u64| Course {
            stamp_ns: k * s / 10,
            course_rad: 0.0,
            speed_mps: v,
        };
        let fix = Fix {
            stamp_ns: s,
            east_m: 0.4,
            north_m: 0.0,
            sigma_m: 0.02,
            up_m: None,
        };
        let mut run = RunFixes {
            fixes: vec![fix],
            courses: (0..20).map(course).collect(),
            ..RunFixes::default()
        };
        let antenna = SensorMount {
            lever_arm_m: [-12.0, 0.0, 4.0],
            ..SensorMount::at_front("/gnss/fix")
        };
        let vehicle = Vehicle {
            sensors: vec![imu, antenna],
            ..Vehicle::point()
        };
        let lean = take_out_with(&mut run, &steps, &vehicle, ("/imu", "/gnss/fix")).unwrap();
        assert_eq!(lean.moved, 1);
        // A body without suspension: its roll is the cant.
        assert!(
            (run.cant_rad[0].unwrap() - phi).abs() < 1e-5,
            "{:?}",
            run.cant_rad
        );
        let moved = run.fixes[0];
        assert!(
            (moved.east_m - (0.4 - 4.0 * phi.sin())).abs() < 1e-5,
            "{moved:?}"
        );
        assert!(moved.north_m.abs() < 1e-9);
    }
}
