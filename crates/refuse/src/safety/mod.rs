//! Source 002: an EKF positioning pipeline whose output is used only when a chain of safety
//! checks passes, and then only as an interval along the track that contains the true position
//! with a stated confidence (`filter = "ekf_safety"`, settings in `[pipeline.safety]`).
//!
//! Sensors: GNSS, the track map, axle sensor 1 (fused) and axle sensor 2 (only checked
//! against). Every epoch (a fix or an axle-1 sample) runs, in order:
//!
//! | step | module | what |
//! |---|---|---|
//! | S1 | [`diagnosis`] | each sensor diagnosed: GNSS fix type, staleness, jumps, non-finite values; each axle's staleness, range, stuck pulses, slip/slide; the map's matching |
//! | S2 | [`plane_filter`] | the constant-acceleration filter per axis (east, north), GNSS coordinates and axle-1 speed resolved with the map heading, axle-1's smoothed acceleration as the input U ([`acceleration_input`]) |
//! | S3 | [`divergence`] | the three divergence tests on the innovations |
//! | S4 | [`map_check`] | the fix's lateral deviation from the track below λσ; with `map_step_window_s` (railfuse's) also its change over a few seconds, which a map off over a stretch steps faster than the receiver's bias moves |
//! | S5 | [`odometry_check`] | the filter's distance against axle 2's over windows ΔT |
//! | S6 | [`safe_interval`] | when all pass, `U_safe = [d − ησ − m, d + ησ + m]` |
//! | – | [`degraded`] | (railfuse's, `degraded = true`) a faulty axle or a fix beside the track left out, or a wider interval while σ grows within ETCS's odometry allowance, instead of no position; named in the check it passes |
//! | S7 | [`summary`] | per check: how often, how long, how often first; availability, containment, caught faults (in `eval`) |
//!
//! Each epoch writes the fused state (along the track, with east/north and lat/lon in its
//! `plane`), a diagnostics record per scalar update, and `/fused/<name>/safety`
//! ([`SafetyStatus`]). A fault or a failed test means "do not use the position now", with
//! the first failure and its reason.

pub mod acceleration_input;
pub mod degraded;
pub mod diagnosis;
pub mod divergence;
pub mod kind;
pub mod map_check;
pub mod odometry_check;
pub mod plane_filter;
pub mod safe_interval;
pub mod settings;

use std::path::Path;

use nalgebra::Matrix2;
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::LogMessage;
use railfuse_catalog::map_matching::{curvature_on, MapMatcher};
use railfuse_catalog::messages::{
    FusedDiagnostics, FusedState, GateDecision, GnssFix, Odometer, PlanePosition, SafeInterval,
    SafetyCheck, SafetyStatus, SensorStateEstimate, TrackMap,
};

use crate::base::PipelineBase;
use crate::error::Result;
use crate::filter::Innovation;
use crate::fused::{Fused, PipelineCounts};
use crate::kinds::MessagePipeline;
use crate::measurement::SensorContext;
use crate::model::{AccelerationInput, ConstantAcceleration};
use crate::noise::VarianceValue;
use crate::reorder::ReorderQueue;
use acceleration_input::AxleAcceleration;
use diagnosis::{Diagnosis, FixVerdict};
use divergence::{DivergenceTests, InnovationKind};
pub use kind::Kind;
use odometry_check::OdometryCheck;
use plane_filter::{Axis, PlaneFilter, PlaneMotion};
pub use settings::SafetySettings;

/// The sensors of the pipeline by role: indices into its `[[pipeline.sensor]]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Roles {
    pub gnss: usize,
    pub axle_1: Option<usize>,
    pub axle_2: Option<usize>,
}

/// A message waiting in the reorder window.
#[derive(Debug, Clone)]
enum Input {
    Fix(GnssFix),
    Axle(usize, Odometer),
}

/// Half the chainage span over which the map's curvature is taken, m.
const CURVATURE_HALF_SPAN_M: f64 = 10.0;
/// Variance added to every resolved speed measurement, (m/s)²: keeps an axis the track runs
/// almost across from a near-zero R.
const SPEED_VARIANCE_FLOOR: f64 = 1e-6;

/// An `ekf_safety` pipeline.
pub struct SafetyPipeline {
    pub base: PipelineBase,
    settings: SafetySettings,
    roles: Roles,
    plain_motion: ConstantAcceleration,
    /// A map given in the settings (a GeoJSON file); else the log's, from the context.
    own_map: Option<std::sync::Arc<TrackMap>>,
    fix_matcher: MapMatcher,
    state_matcher: MapMatcher,
    filter: Option<PlaneFilter>,
    time_ns: u64,
    input: AxleAcceleration,
    diagnosis: Diagnosis,
    divergence: DivergenceTests,
    odometry: OdometryCheck,
    map_check: Option<SafetyCheck>,
    map_step: map_check::MapStepTest,
    /// Degraded modes: since when fixes have not fitted the map, and whether the last was
    /// dropped.
    unfitting_since: Option<u64>,
    fix_dropped: bool,
    /// Where the position σ was last within `max_position_std_m` (S3c passed): the wide
    /// interval's allowance grows with the distance from there.
    last_useful_chainage_m: Option<f64>,
    /// The drawing's installation tolerance as a chainage variance, m²: in `U_safe` as in the
    /// written state's covariance (a lever arm off by it moves the front end for good).
    installation_variance_m2: f64,
    /// Without a map, S1 still judges the fixes, in a plane around the first of them.
    local_origin: Option<GeodeticOrigin>,
    queue: ReorderQueue<Input>,
    variances: Vec<Option<VarianceValue>>,
    pub counts: PipelineCounts,
}

impl SafetyPipeline {
    /// `plain_motion` moves each axis when the acceleration input is off.
    pub fn new(
        base: PipelineBase,
        settings: SafetySettings,
        roles: Roles,
        plain_motion: ConstantAcceleration,
    ) -> Result<Self> {
        let own_map = match &settings.map {
            Some(path) => Some(std::sync::Arc::new(
                railfuse_catalog::track_geojson::read_track_map(path)
                    .map_err(|e| crate::Error::Map(e.to_string()))?,
            )),
            None => None,
        };
        let window = settings.map_search_window_m;
        let mut diagnosis = Diagnosis::default();
        for (k, (role, sensor)) in [("axle_1", roles.axle_1), ("axle_2", roles.axle_2)]
            .into_iter()
            .enumerate()
        {
            if sensor.is_none() {
                diagnosis.absent_axle(k, role);
            }
        }
        Ok(Self {
            variances: vec![None; base.topics.len()],
            base,
            settings,
            roles,
            plain_motion,
            own_map,
            fix_matcher: MapMatcher::new(window),
            state_matcher: MapMatcher::new(window),
            filter: None,
            time_ns: 0,
            input: AxleAcceleration::default(),
            diagnosis,
            divergence: DivergenceTests::default(),
            odometry: OdometryCheck::default(),
            map_check: None,
            map_step: map_check::MapStepTest::default(),
            unfitting_since: None,
            fix_dropped: false,
            last_useful_chainage_m: None,
            installation_variance_m2: 0.0,
            local_origin: None,
            queue: ReorderQueue::default(),
            counts: PipelineCounts::default(),
        })
    }
}

impl MessagePipeline for SafetyPipeline {
    fn counts(&self) -> &PipelineCounts {
        &self.counts
    }

    /// Sensor `sensor` is bound to its channel with this variance.
    fn bind(&mut self, sensor: usize, variance: Option<VarianceValue>) {
        self.variances[sensor] = variance;
    }

    /// One message of sensor `sensor`, received at `log_time_ns`; releases what the reorder
    /// window lets go. Returns an error only for a message that does not decode.
    fn push(
        &mut self,
        sensor: usize,
        msg: &LogMessage<'_>,
        input: &Path,
        context: &SensorContext,
        out: &mut Vec<Fused>,
    ) -> Result<()> {
        let item = if sensor == self.roles.gnss {
            let fix: GnssFix = msg.decode(input)?;
            (fix.stamp_ns, Input::Fix(fix))
        } else {
            let m: Odometer = msg.decode(input)?;
            let k = usize::from(Some(sensor) == self.roles.axle_2);
            (m.stamp_ns, Input::Axle(k, m))
        };
        self.queue.push(item.0, item.1);
        let up_to = msg.log_time_ns.saturating_sub(self.base.reorder_window_ns);
        self.release(up_to, msg.log_time_ns, context, out);
        Ok(())
    }

    /// Releases everything still queued (the end of the log).
    fn finish(&mut self, log_time_ns: u64, context: &SensorContext, out: &mut Vec<Fused>) {
        self.release(u64::MAX, log_time_ns, context, out);
    }
}

impl SafetyPipeline {
    fn release(
        &mut self,
        up_to: u64,
        log_time_ns: u64,
        context: &SensorContext,
        out: &mut Vec<Fused>,
    ) {
        while let Some((stamp, item)) = self.queue.pop_until(up_to) {
            if stamp < self.time_ns {
                self.counts.rejected_late += 1;
                continue;
            }
            // The map is shared, never copied per epoch.
            let own = self.own_map.clone();
            let map = own.as_deref().or(context.track.as_ref());
            let epoch = match item {
                Input::Fix(fix) => self.fix(&fix, map, context),
                Input::Axle(0, m) => self.axle_1(&m, map),
                Input::Axle(_, m) => {
                    self.axle_2(&m);
                    None
                }
            };
            if let Some(epoch) = epoch {
                out.extend(epoch.into_fused(log_time_ns));
            }
        }
    }

    fn variance(&self, sensor: usize, reported: Option<f64>) -> Option<f64> {
        match self.variances[sensor]? {
            VarianceValue::Fixed(v) => Some(v),
            VarianceValue::FromMessage(_) => reported,
        }
    }

    fn topic(&self, sensor: usize) -> &str {
        &self.base.topics[sensor]
    }

    /// The motion model of the plane filter.
    fn motion(&self) -> PlaneMotion {
        match self.settings.acceleration_input {
            true => PlaneMotion::Input {
                known: AccelerationInput {
                    input_std_mps2: self.settings.input_std_mps2,
                    correlation_time_s: self.settings.input_window_s / 2.0,
                },
                unknown: AccelerationInput {
                    input_std_mps2: self.settings.max_acceleration_mps2,
                    correlation_time_s: self.settings.input_window_s / 2.0,
                },
            },
            false => PlaneMotion::ConstantAcceleration(self.plain_motion),
        }
    }

    /// Predicts the filter to `t_ns` with the input at the filter's place on the map.
    fn predict_to(&mut self, t_ns: u64, map: &TrackMap) {
        let Some(f) = &mut self.filter else { return };
        let dt = railfuse_catalog::seconds_between(self.time_ns, t_ns);
        if dt <= 0.0 {
            return;
        }
        let (e, n) = f.position();
        let matched = self.state_matcher.match_point(map, e, n, None);
        let input = matched.zip(self.input.acceleration()).map(|(m, a)| {
            let vertices = map.track(m.track).unwrap_or(&map.vertices);
            let kappa = curvature_on(vertices, m.chainage_m, CURVATURE_HALF_SPAN_M);
            let (x, _) = f.along_track(m.heading_rad);
            acceleration_input::resolve(a, x[1], m.heading_rad, kappa)
        });
        f.predict(dt, input);
        self.time_ns = t_ns;
        if !f.is_finite() {
            // NaN never reaches a fused channel: start again from the next fix.
            self.filter = None;
            self.counts.rejected_invalid += 1;
        }
    }

    fn fix(&mut self, fix: &GnssFix, map: Option<&TrackMap>, ctx: &SensorContext) -> Option<Epoch> {
        let sensor = self.roles.gnss;
        let topic = self.topic(sensor).to_owned();
        self.installation_variance_m2 = ctx.vehicle.installation_variance();
        let mut epoch = Epoch::new(fix.stamp_ns, &topic);
        let Some(map) = map else {
            return Some(self.fix_without_map(fix, epoch));
        };
        let enu = match (fix.latitude_deg, fix.longitude_deg) {
            (Some(lat), Some(lon)) => {
                let (e, n, _) =
                    map.origin
                        .to_enu(lat, lon, fix.altitude_m.unwrap_or(map.origin.altitude_m));
                Some(self.antenna_to_front(ctx, map, (e, n), fix))
            }
            _ => None,
        };
        let cov = fix.position_covariance_enu_m2;
        let r = (
            self.variance(sensor, cov.map(|c| c[0])),
            self.variance(sensor, cov.map(|c| c[4])),
        );
        let worst = match r {
            (Some(a), Some(b)) => Some(a.max(b)),
            _ => None,
        };
        let verdict = self.diagnosis.fix(fix, enu, worst, &self.settings);
        let (FixVerdict::Usable, Some((e, n)), (Some(re), Some(rn))) = (&verdict, enu, r) else {
            let why = match verdict {
                FixVerdict::NoPosition(w) | FixVerdict::Fault(w) => w,
                FixVerdict::Usable => "no variance".into(),
            };
            self.counts.rejected_invalid += 1;
            epoch.refused(&topic, &why);
            return Some(self.finish_epoch(epoch, map));
        };
        let m = match self.match_fix(map, (e, n)) {
            Ok(m) => m,
            Err(why) => {
                self.counts.rejected_invalid += 1;
                epoch.refused(&topic, &why);
                // Degraded mode: a fix that does not fit the map while the filter does.
                let on_map = self.filter.as_ref().is_some_and(|f| {
                    let (fe, fn_) = f.position();
                    let place = self.state_matcher.match_point(map, fe, fn_, None);
                    place.is_some_and(|p| !p.beyond_end)
                });
                self.fix_dropped = self.drop_fix(fix.stamp_ns, true) && on_map;
                return Some(self.finish_epoch(epoch, map));
            }
        };
        if self.filter.is_none() {
            self.start_filter((e, n), re.max(rn), m.heading_rad);
            self.time_ns = fix.stamp_ns;
            self.counts.accepted += 1;
            epoch.used(&topic, "east", e, re, None);
            epoch.used(&topic, "north", n, rn, None);
            return Some(self.finish_epoch(epoch, map));
        }
        self.predict_to(fix.stamp_ns, map);
        let s4_failed = self.check_against_map(fix.stamp_ns, &m, (re, rn))?;
        self.fix_dropped = self.drop_fix(fix.stamp_ns, s4_failed);
        if self.fix_dropped {
            epoch.refused(&topic, "beside the track (S4): not fused (degraded mode)");
            return Some(self.finish_epoch(epoch, map));
        }
        self.update_axes(
            InnovationKind::Position,
            &mut epoch,
            [(Axis::East, e, re), (Axis::North, n, rn)],
        );
        Some(self.finish_epoch(epoch, map))
    }

    /// The antenna's fix at (east, north) moved to the front end, which the filter estimates:
    /// the train placed at the filter's chainage, or before it starts at the fix's own.
    fn antenna_to_front(
        &self,
        ctx: &SensorContext,
        map: &TrackMap,
        (e, n): (f64, f64),
        fix: &GnssFix,
    ) -> (f64, f64) {
        let topic = self.topic(self.roles.gnss);
        let front = match (&self.filter, self.state_matcher.last()) {
            (Some(_), Some((0, s))) => Some(s),
            _ => ctx.front_chainage_of_measured(map, topic, (e, n)),
        };
        let speed = fix.speed_mps.filter(|v| v.is_finite()).unwrap_or(0.0);
        let heading = fix.course_rad.unwrap_or(0.0);
        let place = ctx.place(Some(map), front, speed, heading);
        ctx.move_measured(topic, (e, n), place, 0.0)
    }

    /// What degraded mode weighs for an epoch at `chainage` (with its variance): a dropped
    /// fix, the wide interval since the last useful position, and the odometry so far where
    /// no window completed (`window_done`); `None` with degraded mode off.
    fn cover(
        &self,
        t_ns: u64,
        (chainage_m, variance_m2): (f64, f64),
        sigma_max: f64,
        window_done: bool,
    ) -> Option<degraded::Cover> {
        let s = &self.settings;
        let margin = s.map_margin * s.map_std_m;
        s.degraded.then(|| degraded::Cover {
            fix_dropped: self.fix_dropped,
            wide_interval: self.last_useful_chainage_m.map(|at| {
                let since_useful_m = (chainage_m - at).abs();
                degraded::WideInterval {
                    half_width_m: s.eta * sigma_max + margin,
                    allowance_m: s.eta * s.max_position_std_m
                        + margin
                        + s.wide_interval_fraction * since_useful_m,
                    since_useful_m,
                }
            }),
            odometry_so_far: match window_done {
                true => None,
                false => self.odometry.judge(
                    t_ns,
                    chainage_m,
                    variance_m2,
                    s.odometry_sigmas,
                    s.axle_2_scale_std,
                ),
            },
        })
    }

    /// S4 on the predicted position, then its step test, kept as the epoch's map check;
    /// whether S4 failed (`None` without a filter). A fix beside the track may be dropped
    /// (degraded); a step says the map may be off as well as the fix, so it only fails the
    /// check: the fix is still fused, and the map heading not trusted alone.
    fn check_against_map(
        &mut self,
        t_ns: u64,
        m: &railfuse_catalog::map_matching::MapMatch,
        (re, rn): (f64, f64),
    ) -> Option<bool> {
        let s = &self.settings;
        let p = self.filter.as_ref()?.position_covariance();
        let r = Matrix2::new(re, 0.0, 0.0, rn);
        let s4 = map_check::map_check(m.lateral_m, m.heading_rad, &p, &r, s.map_std_m, s.lambda);
        let s4_failed = !s4.passed;
        // Only fixes that fit the map are a reference: a dropped one (a jump, a reflection)
        // would make the next good fix look like a step.
        let step = match s.map_step_window_s > 0.0 && !s4_failed {
            true => self.map_step.check(
                t_ns,
                m.track,
                m.lateral_m,
                map_check::across(m.heading_rad, &r),
                s.map_step_window_s,
                s.gnss_bias,
                s.map_std_m,
                s.lambda,
            ),
            false => None,
        };
        self.map_check = Some(match step {
            Some(step) if !step.passed => step,
            _ => s4,
        });
        Some(s4_failed)
    }

    /// Degraded mode: whether a fix that does not fit the map (`failed`: beside the track by
    /// S4, or beyond its ends) is dropped instead of the epoch: fixes have not fitted for at
    /// most `max_dropped_fix_s`.
    fn drop_fix(&mut self, t_ns: u64, failed: bool) -> bool {
        let since = match failed {
            true => *self.unfitting_since.get_or_insert(t_ns),
            false => {
                self.unfitting_since = None;
                t_ns
            }
        };
        self.settings.degraded
            && failed
            && railfuse_catalog::seconds_between(since, t_ns) <= self.settings.max_dropped_fix_s
    }

    /// Map matching of a fix (S1 map), near where the filter expects the train: the match, or
    /// why the fix does not fit the map (which the diagnosis is told either way).
    fn match_fix(
        &mut self,
        map: &TrackMap,
        (e, n): (f64, f64),
    ) -> Result<railfuse_catalog::map_matching::MapMatch, String> {
        let expected = self.filter.as_ref().and_then(|f| {
            let (fe, fn_) = f.position();
            self.state_matcher
                .clone()
                .match_point(map, fe, fn_, None)
                .map(|m| m.chainage_m)
        });
        let matched = self.fix_matcher.match_point(map, e, n, expected);
        let map_fault = match matched {
            None => Some("the fix matches no track".to_owned()),
            Some(m) => {
                let distance = (m.east_m - e).hypot(m.north_m - n);
                if distance > self.settings.max_map_distance_m {
                    Some(format!(
                        "the fix is {distance:.1} m from the nearest track (limit {} m)",
                        self.settings.max_map_distance_m
                    ))
                } else if m.beyond_end {
                    Some("the fix lies beyond the ends of the map".to_owned())
                } else {
                    None
                }
            }
        };
        self.diagnosis.map(map_fault.clone());
        match (matched, map_fault) {
            (Some(m), None) => Ok(m),
            (_, why) => Err(why.unwrap_or_else(|| "no match".into())),
        }
    }

    /// The filter started at the first usable fix, at the axle's speed along the track.
    fn start_filter(&mut self, at: (f64, f64), variance: f64, heading_rad: f64) {
        let speed = self.diagnosis.axles[0]
            .speed_mps
            .unwrap_or(self.base.initial.speed_mps);
        let gm = |b: Option<settings::BiasSettings>| {
            b.map(|b| plane_filter::GaussMarkov {
                std: b.std,
                time_constant_s: b.time_constant_s,
            })
        };
        self.filter = Some(PlaneFilter::new(
            self.motion(),
            gm(self.settings.gnss_bias),
            gm(self.settings.axle_1_bias),
            at,
            variance,
            (speed, heading_rad),
            self.base.initial.speed_variance,
            self.base.initial.acceleration_variance,
        ));
    }

    /// S1 on a fix of a log without a track map (a real recording of GNSS alone, say): the fix
    /// is judged and its verdict written, but nothing can be fused or declared usable, since
    /// S2 resolves along the map and S4 checks against it.
    fn fix_without_map(&mut self, fix: &GnssFix, mut epoch: Epoch) -> Epoch {
        let no_map = "no track map (neither the log's /track/map nor safety.map)";
        let sensor = self.roles.gnss;
        let topic = epoch.source.clone();
        let position = fix.latitude_deg.zip(fix.longitude_deg);
        let enu = position.and_then(|(lat, lon)| {
            let alt = fix.altitude_m.unwrap_or(0.0);
            let origin = *self.local_origin.get_or_insert(GeodeticOrigin {
                latitude_deg: lat,
                longitude_deg: lon,
                altitude_m: alt,
            });
            let (e, n, _) = origin.to_enu(lat, lon, alt);
            (e.is_finite() && n.is_finite()).then_some((e, n))
        });
        let cov = fix.position_covariance_enu_m2;
        let worst = self
            .variance(sensor, cov.map(|c| c[0]))
            .zip(self.variance(sensor, cov.map(|c| c[4])))
            .map(|(a, b)| a.max(b));
        let why = match self.diagnosis.fix(fix, enu, worst, &self.settings) {
            FixVerdict::NoPosition(w) | FixVerdict::Fault(w) => w,
            FixVerdict::Usable => format!("a usable fix, not fused: {no_map}"),
        };
        self.diagnosis.map(Some(no_map.into()));
        self.counts.rejected_invalid += 1;
        epoch.refused_with_variance(&topic, worst, &why);
        let checks = self.diagnosis.checks(epoch.stamp_ns, &self.settings).into();
        epoch.safety = Some(status(epoch.stamp_ns, checks, None));
        epoch
    }

    /// The configured speed variances of axles 1 and 2 (NaN for an axle not configured).
    fn axle_variances(&self) -> [f64; 2] {
        [self.roles.axle_1, self.roles.axle_2]
            .map(|s| s.and_then(|s| self.variance(s, None)).unwrap_or(f64::NAN))
    }

    fn axle_1(&mut self, m: &Odometer, map: Option<&TrackMap>) -> Option<Epoch> {
        let sensor = self.roles.axle_1?;
        let topic = self.topic(sensor).to_owned();
        let variances = self.axle_variances();
        let filter_speed = self.filter_speed(map);
        self.diagnosis
            .axle(0, m, variances, filter_speed, &self.settings);
        // A faulty axle's speeds must not drive the filter either: without U the prediction
        // takes the train's whole acceleration range as its uncertainty.
        let healthy = self.diagnosis.checks(m.stamp_ns, &self.settings)[1].passed;
        match healthy {
            true => self
                .input
                .push(m.stamp_ns, m.speed_mps, self.settings.input_window_s),
            false => self.input.clear(),
        }
        let map = map?;
        if self.filter.is_none() {
            self.counts.before_initialisation += 1;
            return None;
        }
        self.predict_to(m.stamp_ns, map);
        let mut epoch = Epoch::new(m.stamp_ns, &topic);
        let r = variances[0];
        if !healthy || !r.is_finite() {
            self.counts.rejected_invalid += 1;
            epoch.refused(&topic, "axle sensor 1 diagnosed faulty (S1)");
            return Some(self.finish_epoch(epoch, map));
        }
        let (e, n) = self.filter.as_ref()?.position();
        let place = self.state_matcher.match_point(map, e, n, None)?;
        let h = place.heading_rad;
        let v = m.speed_mps;
        let resolved = Axis::BOTH.map(|axis| {
            let u = axis.component(h);
            let var = r * u * u
                + (v * self.settings.heading_std_rad).powi(2) * (1.0 - u * u)
                + SPEED_VARIANCE_FLOOR;
            (axis, v * u, var)
        });
        self.update_axes(InnovationKind::Speed, &mut epoch, resolved);
        Some(self.finish_epoch(epoch, map))
    }

    /// One measurement on each axis: its innovations go to S3, and both axes are updated
    /// unless one of them is beyond S3b's limit (a fault, which must not pull the filter).
    fn update_axes(
        &mut self,
        kind: InnovationKind,
        epoch: &mut Epoch,
        measured: [(Axis, f64, f64); 2],
    ) {
        let Some(f) = self.filter.as_mut() else {
            return;
        };
        let innovations = measured.map(|(axis, z, r)| match kind {
            InnovationKind::Position => f.position_innovation(axis, r, z),
            InnovationKind::Speed => f.speed_innovation(axis, r, z),
        });
        let s = &self.settings;
        self.divergence
            .update(kind, &innovations, s.divergence_window);
        let limit = match kind {
            InnovationKind::Position => s.innovation_limit_m,
            InnovationKind::Speed => s.innovation_limit_mps,
        };
        let too_big = innovations.iter().any(|i| !(i.residual.abs() <= limit));
        let topic = epoch.source.clone();
        for ((axis, z, r), i) in measured.into_iter().zip(innovations) {
            if too_big {
                epoch.gated(&topic, axis.name(), z, r, i);
                continue;
            }
            match kind {
                InnovationKind::Position => f.update_position(axis, r, z),
                InnovationKind::Speed => f.update_speed(axis, r, z),
            };
            epoch.used(&topic, axis.name(), z, r, Some(i));
        }
        match too_big {
            true => self.counts.rejected_gate += 1,
            false => self.counts.accepted += 1,
        }
    }

    fn axle_2(&mut self, m: &Odometer) {
        let variances = self.axle_variances();
        let speed = self.filter.as_ref().map(|f| {
            let (e, n) = (f.east.estimate.state[1], f.north.estimate.state[1]);
            e.hypot(n)
        });
        self.diagnosis.axle(1, m, variances, speed, &self.settings);
        let healthy = self.diagnosis.checks(m.stamp_ns, &self.settings)[2].passed;
        match (healthy, self.settings.degraded) {
            (false, true) => self.odometry.restart(),
            _ => self.odometry.axle_2(m),
        }
    }

    /// The estimated receiver bias and axle speed error per axis, where modelled.
    fn sensor_states(&self, f: &PlaneFilter) -> Vec<SensorStateEstimate> {
        let mut out = Vec::new();
        let std = |k: &crate::filter::KalmanFilter<5>, i: usize| {
            k.estimate.covariance[(i, i)].max(0.0).sqrt()
        };
        for (axis, k) in [("east", &f.east), ("north", &f.north)] {
            let roles = [
                (
                    self.settings.gnss_bias.is_some(),
                    Some(self.roles.gnss),
                    "position_bias",
                    3,
                ),
                (
                    self.settings.axle_1_bias.is_some(),
                    self.roles.axle_1,
                    "speed_bias",
                    4,
                ),
            ];
            for (on, sensor, kind, i) in roles {
                if let (true, Some(sensor)) = (on, sensor) {
                    out.push(SensorStateEstimate {
                        topic: self.topic(sensor).to_owned(),
                        kind: format!("{axis}_{kind}"),
                        value: k.estimate.state[i],
                        std: std(k, i),
                    });
                }
            }
        }
        out
    }

    fn filter_speed(&self, map: Option<&TrackMap>) -> Option<f64> {
        let (f, map) = (self.filter.as_ref()?, map?);
        let (e, n) = f.position();
        let m = self.state_matcher.clone().match_point(map, e, n, None)?;
        Some(f.along_track(m.heading_rad).0[1])
    }

    /// The fused state and the safety status of an epoch whose updates are done.
    fn finish_epoch(&mut self, mut epoch: Epoch, map: &TrackMap) -> Epoch {
        let s = &self.settings;
        let Some(f) = &self.filter else {
            return epoch;
        };
        let (e, n) = f.position();
        let Some(place) = self.state_matcher.match_point(map, e, n, None) else {
            return epoch;
        };
        let (x, p) = f.along_track(place.heading_rad);
        let chainage_std = p[(0, 0)].max(0.0).sqrt();
        let mut covariance = [0.0; 9];
        for (k, c) in covariance.iter_mut().enumerate() {
            *c = p[(k / 3, k % 3)];
        }
        let pos_cov = f.position_covariance();
        let (lat, lon, _) = map.origin.to_geodetic(e, n, 0.0);
        epoch.state = Some(FusedState {
            stamp_ns: epoch.stamp_ns,
            chainage_m: place.chainage_m,
            speed_mps: x[1],
            acceleration_mps2: x[2],
            covariance,
            source: epoch.source.clone(),
            sensor_states: self.sensor_states(f),
            plane: Some(PlanePosition {
                east_m: e,
                north_m: n,
                covariance_en_m2: [pos_cov[(0, 0)], 0.0, 0.0, pos_cov[(1, 1)]],
                latitude_deg: lat,
                longitude_deg: lon,
                ..Default::default()
            }),
        });
        let mut checks: Vec<SafetyCheck> = self.diagnosis.checks(epoch.stamp_ns, s).into();
        checks.extend(self.divergence.checks(&pos_cov, s));
        checks.push(
            self.map_check
                .clone()
                .unwrap_or_else(|| diagnosis::verdict("s4_map", Some("no fix checked yet".into()))),
        );
        let sigma_max = pos_cov.symmetric_eigenvalues().max().max(0.0).sqrt();
        if sigma_max <= s.max_position_std_m {
            self.last_useful_chainage_m = Some(place.chainage_m);
        }
        let odometry = self
            .odometry
            .epoch(
                epoch.stamp_ns,
                place.chainage_m,
                p[(0, 0)],
                s.odometry_window_s,
                s.odometry_sigmas,
                s.axle_2_scale_std,
            )
            .cloned();
        let margin = s.map_margin * s.map_std_m;
        let cover = self.cover(
            epoch.stamp_ns,
            (place.chainage_m, p[(0, 0)]),
            sigma_max,
            odometry.is_some(),
        );
        checks.push(odometry.unwrap_or_else(|| {
            diagnosis::verdict(
                "s5_odometry",
                Some("no odometry window completed yet".into()),
            )
        }));
        if let Some(cover) = cover {
            degraded::degrade(&mut checks, &cover);
        }
        let interval_std = (chainage_std.powi(2) + self.installation_variance_m2).sqrt();
        let interval = safe_interval::safe_interval(place.chainage_m, interval_std, s.eta, margin);
        epoch.safety = Some(status(epoch.stamp_ns, checks, Some(interval)));
        epoch
    }
}

/// An epoch's safety status from its checks: usable when all passed, and then with `U_safe`.
fn status(stamp_ns: u64, checks: Vec<SafetyCheck>, interval: Option<SafeInterval>) -> SafetyStatus {
    let first = checks.iter().find(|c| !c.passed);
    let usable = first.is_none();
    SafetyStatus {
        stamp_ns,
        usable,
        first_failure: first.map(|c| c.check.clone()),
        reason: first.and_then(|c| c.reason.clone()),
        safe_interval: interval.filter(|_| usable),
        checks,
    }
}

/// What one epoch produced.
struct Epoch {
    stamp_ns: u64,
    source: String,
    diagnostics: Vec<FusedDiagnostics>,
    state: Option<FusedState>,
    safety: Option<SafetyStatus>,
}

impl Epoch {
    fn new(stamp_ns: u64, source: &str) -> Self {
        Self {
            stamp_ns,
            source: source.to_owned(),
            diagnostics: Vec::new(),
            state: None,
            safety: None,
        }
    }

    fn record(
        &mut self,
        topic: &str,
        axis: Option<&str>,
        (z, r): (Option<f64>, Option<f64>),
        i: Option<Innovation>,
        decision: GateDecision,
        reason: Option<&str>,
    ) {
        let stamp = self.stamp_ns;
        let d = crate::fused::measurement_record(stamp, topic, axis, (z, r), i, decision, reason);
        self.diagnostics.push(d);
    }

    fn used(&mut self, topic: &str, axis: &str, z: f64, r: f64, i: Option<Innovation>) {
        let d = GateDecision::Accepted;
        self.record(topic, Some(axis), (Some(z), Some(r)), i, d, None);
    }

    fn gated(&mut self, topic: &str, axis: &str, z: f64, r: f64, i: Innovation) {
        let (d, why) = (
            GateDecision::RejectedGate,
            "an innovation beyond the S3b limit",
        );
        self.record(topic, Some(axis), (Some(z), Some(r)), Some(i), d, Some(why));
    }

    fn refused(&mut self, topic: &str, why: &str) {
        self.refused_with_variance(topic, None, why);
    }

    /// Refused, with the variance the sensor reported for it (the accuracy it claimed).
    fn refused_with_variance(&mut self, topic: &str, variance: Option<f64>, why: &str) {
        let d = GateDecision::RejectedInvalid;
        self.record(topic, None, (None, variance), None, d, Some(why));
    }

    fn into_fused(self, log_time_ns: u64) -> Vec<Fused> {
        let mut out: Vec<Fused> = self
            .diagnostics
            .into_iter()
            .map(|d| Fused {
                log_time_ns,
                state: None,
                diagnostics: Some(d),
                ..Default::default()
            })
            .collect();
        if self.state.is_some() || self.safety.is_some() {
            out.push(Fused {
                log_time_ns,
                state: self.state,
                safety: self.safety,
                ..Default::default()
            });
        }
        out
    }
}
