//! Source 003's `gnss_ins` pipeline: an RTK/single-point GNSS receiver and a MEMS IMU fused in
//! an error-state Kalman filter in the east/north plane.
//!
//! | step | module | what |
//! |---|---|---|
//! | gate | [`quality_gate`] | each fix judged on fix type, satellites and HDOP: RTK fixed taken as the reference, weaker fixes pre-filtered, the rest refused with the reason |
//! | pre-filter | [`crate::prefilter`] | RLS, adaptive RLS or PU-RLS per GNSS axis (position, velocity); the unscented transform for speed and course to velocity |
//! | train | [`train_geometry`] | the vehicle's geometry: the navigation point at the IMU's place, each fix moved there from the antenna, the IMU's readings levelled by its mounting and the map's gradient and cant (looked up through a loss where the gyro's roll puts the cant ramps: [`crate::tilt`]), the front end written |
//! | navigation | [`planar_ins`] | heading from the yaw rate, speed from the forward specific force, both bias-corrected, dead-reckoned at the IMU's rate |
//! | fusion | [`error_state`] | the error-state filter `[δe, δn, δu, δw, δψ, δb_x, δb_y, δb_g, δk…]`, Joseph form, its estimate put into the navigation after each update |
//! | train | [`constraints`] | railfuse's, not the source's: zero lateral speed (NHC) and the track map's centre line and heading, as pseudo-measurements |
//! | speed | [`speed_sensors`] | a radar's or an odometer's speed, with a scale-factor state each |
//! | AKF | [`adaptive_noise`] | R from the innovations, the source's other baseline |
//! | learning | [`error_learning`] | while GNSS is good the residual error rates are learnt; through a loss they keep correcting the navigation |
//!
//! Bad input is refused and counted, never fused: fixes the gate refuses or whose
//! coordinates are absurd; IMU samples that are not finite, saturated or from a stuck axis;
//! anything older than the filter's time. A standing train (a fix slower than
//! `standstill_speed_mps`) gets zero-speed and zero-turn-rate updates, and its IMU's static
//! bias is measured whether or not the filter has started.

pub mod adaptive_noise;
mod constraints;
pub mod error_learning;
pub mod error_state;
pub mod kind;
mod output;
pub mod planar_ins;
pub mod quality_gate;
pub mod settings;
mod speed_sensors;
mod static_bias;
mod train_geometry;

use std::path::Path;

use nalgebra::{SMatrix, SVector};
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::LogMessage;
use railfuse_catalog::map_matching::MapMatcher;
use railfuse_catalog::messages::{GateDecision, GnssFix, Imu, TrackMap};
use railfuse_catalog::seconds_between;

use crate::base::PipelineBase;
use crate::config::ScaleFactorConfig;
use crate::error::Result;
use crate::filter::Innovation;
use crate::fused::{Fused, PipelineCounts};
use crate::kinds::MessagePipeline;
use crate::measurement::{Measurement, SensorContext};
use crate::noise::VarianceValue;
use crate::prefilter::unscented::velocity_from_speed_and_course;
use crate::prefilter::PreFilter;
use crate::reorder::ReorderQueue;
use adaptive_noise::AdaptiveNoise;
use error_learning::ErrorLearning;
use error_state::{
    position_rows, unit, velocity_rows, Calibration, ErrorDynamics, ErrorMatrix, ErrorMeasurement,
    ErrorStateFilter, ErrorVector, BA, BG, BY, GE, GN, K, MAX_SPEED_SENSORS, PSI, V, W,
};
pub use kind::Kind;
use planar_ins::Navigation;
use quality_gate::{GateTally, GateVerdict};
pub use settings::GnssInsSettings;
use static_bias::{ImuHealth, StaticBias};

/// Which of the pipeline's sensors is which.
#[derive(Debug, Clone, PartialEq)]
pub struct Roles {
    pub gnss: usize,
    pub imu: usize,
    /// Every other sensor: a radar's or an odometer's speed.
    pub speed: Vec<SpeedSensor>,
}

/// A speed sensor of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedSensor {
    /// Its index among the pipeline's sensors.
    pub sensor: usize,
    /// Its scale factor's state, if estimated (the sensor's `scale_factor`).
    pub scale: Option<ScaleFactorConfig>,
    /// The window its speed is the mean over, s (`speed_window_s`; 0: instantaneous).
    pub window_s: f64,
}

#[derive(Debug, Clone)]
enum Input {
    Fix(GnssFix),
    Imu(Imu),
    /// The `j`-th speed sensor's speed.
    Speed(usize, Measurement),
}

/// σ of the zero-speed pseudo-measurement of a standing train, m/s: a creeping train at the
/// standstill threshold is slower than this.
const STANDSTILL_SPEED_STD_MPS: f64 = 0.02;
/// Half-width of the map matcher's search window along the track, m.
const MAP_WINDOW_M: f64 = 200.0;

/// A `gnss_ins` pipeline.
pub struct GnssInsPipeline {
    pub base: PipelineBase,
    settings: GnssInsSettings,
    roles: Roles,
    gnss_variance: Option<VarianceValue>,
    /// Each speed sensor's variance setting.
    speed_variance: Vec<Option<VarianceValue>>,
    /// The speed sensors' scale factors and the receiver's bias; the scale factors'
    /// random-walk PSD, and the bias's driving PSD (set by the latest fix).
    calibration: Calibration,
    scale_walk: [f64; MAX_SPEED_SENSORS],
    receiver_bias_psd: f64,
    /// A speed message's measurements, decoded.
    scratch: Vec<Measurement>,
    queue: ReorderQueue<Input>,
    origin: Option<GeodeticOrigin>,
    nav: Option<Navigation>,
    filter: Option<ErrorStateFilter>,
    time_ns: u64,
    /// The latest healthy IMU reading: forward and lateral specific force, yaw rate.
    held: Option<([f64; 2], f64)>,
    last_acceleration: f64,
    /// The latest interval between IMU samples, s.
    imu_interval_s: f64,
    health: ImuHealth,
    standstill: StaticBias,
    standing: bool,
    /// Position east, north; velocity east, north; IMU forward specific force, yaw rate.
    prefilters: [PreFilter; 6],
    akf: Option<[AdaptiveNoise; 2]>,
    learning: ErrorLearning,
    last_fused_ns: Option<u64>,
    /// The latest fused reference (RTK fixed) fix, while they come one after another.
    last_reference_ns: Option<u64>,
    in_loss: bool,
    matcher: MapMatcher,
    distance_m: f64,
    next_output_ns: u64,
    next_model_ns: u64,
    pub counts: PipelineCounts,
    gate: GateTally,
    constraints: constraints::State,
    /// The navigation point's chainage from the latest fix, before the navigation starts.
    fix_chainage_m: Option<f64>,
    /// The level the IMU's readings are turned into, the gyro carrying the map's.
    tilt: crate::tilt::GyroTilt,
}

/// What one step wrote.
#[derive(Default)]
struct Out {
    items: Vec<Fused>,
}

impl GnssInsPipeline {
    pub fn new(base: PipelineBase, settings: GnssInsSettings, roles: Roles) -> Result<Self> {
        let p = settings.prefilter;
        let prefilters = [p.position, p.position, p.velocity, p.velocity, p.imu, p.imu]
            .iter()
            .enumerate()
            .map(|(k, s)| PreFilter::new(s, k as u64))
            .collect::<Vec<_>>()
            .try_into()
            .expect("six pre-filters");
        let akf = settings
            .adaptive
            .map(|a| [AdaptiveNoise::new(a), AdaptiveNoise::new(a)]);
        let mut scale_walk = [0.0; MAX_SPEED_SENSORS];
        for (j, s) in roles.speed.iter().enumerate() {
            scale_walk[j] = s.scale.map_or(0.0, |f| f.walk_per_s);
        }
        Ok(Self {
            base,
            gnss_variance: None,
            speed_variance: vec![None; roles.speed.len()],
            calibration: Calibration::default(),
            scale_walk,
            receiver_bias_psd: 0.0,
            scratch: Vec::with_capacity(1),
            roles,
            queue: ReorderQueue::default(),
            origin: None,
            nav: None,
            filter: None,
            time_ns: 0,
            held: None,
            last_acceleration: 0.0,
            imu_interval_s: 0.01,
            health: ImuHealth::new(settings.stuck_samples),
            standstill: StaticBias::default(),
            standing: false,
            prefilters,
            akf,
            learning: ErrorLearning::default(),
            last_fused_ns: None,
            last_reference_ns: None,
            in_loss: false,
            matcher: MapMatcher::new(MAP_WINDOW_M),
            distance_m: 0.0,
            next_output_ns: 0,
            next_model_ns: 0,
            counts: PipelineCounts::default(),
            gate: GateTally::default(),
            constraints: constraints::State::default(),
            fix_chainage_m: None,
            tilt: Default::default(),
            settings,
        })
    }
}

impl MessagePipeline for GnssInsPipeline {
    fn counts(&self) -> &PipelineCounts {
        &self.counts
    }

    fn report(&self) -> Option<String> {
        let g = self.gate;
        Some(format!(
            "GNSS gate: {} fixes taken as the reference, {} pre-filtered, {} refused; {}",
            g.reference,
            g.pre_filtered,
            g.refused,
            self.constraints.report(&self.settings)
        ))
    }

    /// Sensor `sensor` is bound with this variance setting (the GNSS receiver's; the IMU's
    /// error model is `imu_noise`).
    fn bind(&mut self, sensor: usize, variance: Option<VarianceValue>) {
        if sensor == self.roles.gnss {
            self.gnss_variance = variance;
        }
        if let Some(j) = self.speed_index(sensor) {
            self.speed_variance[j] = variance;
        }
    }

    /// One message of sensor `sensor`, received at `log_time_ns`.
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
        } else if sensor == self.roles.imu {
            let imu: Imu = msg.decode(input)?;
            (imu.stamp_ns, Input::Imu(imu))
        } else {
            let j = self
                .speed_index(sensor)
                .expect("every other sensor is a speed sensor");
            let m = self.decode_speed(msg, input, context)?;
            (m.stamp_ns, Input::Speed(j, m))
        };
        self.queue.push(item.0, item.1);
        let up_to = msg.log_time_ns.saturating_sub(self.base.reorder_window_ns);
        self.release(up_to, msg.log_time_ns, context, out);
        Ok(())
    }

    fn finish(&mut self, log_time_ns: u64, context: &SensorContext, out: &mut Vec<Fused>) {
        self.release(u64::MAX, log_time_ns, context, out);
        // The model as it stands at the end, whatever the once-a-second clock says.
        let mut o = Out::default();
        self.next_model_ns = 0;
        match self.nav {
            Some(nav) => self.write_model(
                self.time_ns,
                (nav.accel_bias_mps2, nav.gyro_bias_radps),
                &mut o,
            ),
            None => self.static_model(self.standstill_end_ns(), &mut o),
        }
        out.extend(o.items.into_iter().map(|mut f| {
            f.log_time_ns = log_time_ns;
            f
        }));
    }
}

impl GnssInsPipeline {
    /// Which speed sensor (its index in [`Roles::speed`]) sensor `sensor` is, if one.
    fn speed_index(&self, sensor: usize) -> Option<usize> {
        self.roles.speed.iter().position(|s| s.sensor == sensor)
    }

    /// Brings the navigation to `t` with the latest IMU reading (for a measurement between
    /// two samples).
    fn advance_to(&mut self, t: u64) {
        if let Some((force, yaw_rate)) = self.held {
            self.advance(t, force, yaw_rate, seconds_between(self.time_ns, t));
        }
    }

    /// The stamp of the last standstill sample (0 before any).
    fn standstill_end_ns(&self) -> u64 {
        self.standstill.last_ns().unwrap_or(0)
    }

    fn release(&mut self, up_to: u64, log_time_ns: u64, ctx: &SensorContext, out: &mut Vec<Fused>) {
        while let Some((stamp, item)) = self.queue.pop_until(up_to) {
            let mut o = Out::default();
            if self.nav.is_some() && stamp < self.time_ns {
                self.counts.rejected_late += 1;
                let topic = match &item {
                    Input::Fix(_) => self.topic(self.roles.gnss),
                    Input::Imu(_) => self.topic(self.roles.imu),
                    Input::Speed(j, _) => self.topic(self.roles.speed[*j].sensor),
                }
                .to_owned();
                o.diagnostics(
                    stamp,
                    &topic,
                    GateDecision::RejectedLate,
                    "older than the filter's time",
                );
            } else {
                match item {
                    Input::Fix(fix) => self.fix(&fix, ctx, &mut o),
                    Input::Imu(imu) => self.imu(&imu, ctx, &mut o),
                    Input::Speed(j, m) => self.speed(j, &m, &mut o),
                }
            }
            out.extend(o.items.into_iter().map(|mut f| {
                f.log_time_ns = log_time_ns;
                f
            }));
        }
    }

    fn topic(&self, sensor: usize) -> &str {
        &self.base.topics[sensor]
    }

    // --- IMU --------------------------------------------------------------------------

    fn imu(&mut self, m: &Imu, ctx: &SensorContext, o: &mut Out) {
        let map = ctx.track.as_ref();
        let topic = self.topic(self.roles.imu).to_owned();
        if let Err(why) = self.health.judge(m, &self.settings) {
            self.counts.rejected_invalid += 1;
            // One record per episode: a stuck axis at 200 Hz must not flood the channel.
            if self.health.first_of_episode() {
                o.diagnostics(m.stamp_ns, &topic, GateDecision::RejectedInvalid, &why);
            }
            return;
        }
        let ([mut forward, lateral], mut yaw_rate) = self.level_reading(ctx, m);
        if self.standing {
            self.standstill.push(m.stamp_ns, forward, yaw_rate);
        }
        let dt = seconds_between(self.time_ns, m.stamp_ns);
        if self.nav.is_some() && dt > 0.0 {
            self.imu_interval_s = dt;
        }
        if !matches!(
            self.settings.prefilter.imu,
            crate::prefilter::PreFilterSettings::None
        ) {
            // Each sample's white-noise variance: the density squared over its interval.
            let n = &self.settings.imu_noise;
            let per_sample = |density: f64| density * density / self.imu_interval_s;
            let (rf, rw) = (
                per_sample(n.accel_noise_density),
                per_sample(n.gyro_noise_density),
            );
            forward = self.prefilters[4].step(m.stamp_ns, forward, rf).value;
            yaw_rate = self.prefilters[5].step(m.stamp_ns, yaw_rate, rw).value;
        }
        self.held = Some(([forward, lateral], yaw_rate));
        if self.nav.is_none() {
            return self.static_model(m.stamp_ns, o);
        }
        self.advance(m.stamp_ns, [forward, lateral], yaw_rate, dt);
        self.constrain(m.stamp_ns, map);
        if m.stamp_ns >= self.next_output_ns {
            self.output(m.stamp_ns, &topic, ctx, o);
        }
    }

    /// Dead-reckons navigation and error covariance by `dt` with one IMU reading (forward and
    /// lateral specific force, yaw rate); through a GNSS loss the learnt error model keeps
    /// correcting.
    fn advance(&mut self, t_ns: u64, force: [f64; 2], yaw_rate: f64, dt: f64) {
        let (Some(nav), Some(filter)) = (self.nav.as_mut(), self.filter.as_mut()) else {
            return;
        };
        if dt <= 0.0 {
            return;
        }
        filter.predict(
            &ErrorDynamics {
                navigation: nav,
                noise: &self.settings.imu_noise,
                rate_radps: yaw_rate - nav.gyro_bias_radps,
                scale_walk: &self.scale_walk,
                receiver_bias: (
                    self.settings.receiver_bias.time_constant_s,
                    self.receiver_bias_psd,
                ),
            },
            dt,
        );
        self.calibration
            .decay(dt, self.settings.receiver_bias.time_constant_s);
        self.last_acceleration = nav.propagate(force, yaw_rate, dt);
        self.distance_m += nav.speed_mps * dt;
        let lost = self
            .last_fused_ns
            .is_none_or(|l| seconds_between(l, t_ns) > self.settings.learning.loss_after_s);
        self.in_loss = lost;
        if lost {
            if let Some((dv, dpsi)) = self.learning.correction(dt, &self.settings.learning) {
                nav.speed_mps += dv;
                nav.heading_rad = (nav.heading_rad + dpsi).rem_euclid(std::f64::consts::TAU);
            }
        }
        self.time_ns = t_ns;
        if !(nav.is_finite() && filter.kf.estimate.is_finite()) {
            // NaN never reaches a fused channel: start again from the next good fix.
            self.nav = None;
            self.filter = None;
            self.counts.rejected_invalid += 1;
        }
    }

    // --- GNSS -------------------------------------------------------------------------

    fn fix(&mut self, fix: &GnssFix, ctx: &SensorContext, o: &mut Out) {
        let map = ctx.track.as_ref();
        let topic = self.topic(self.roles.gnss).to_owned();
        let t = fix.stamp_ns;
        let verdict = quality_gate::judge(fix, &self.settings.gate);
        let checked = match &verdict {
            GateVerdict::Refused(why) => Err(why.clone()),
            _ => self.check_fix(fix, ctx),
        };
        let (e, n, re, rn) = match checked {
            Ok(checked) => checked,
            Err(why) => {
                self.counts.rejected_invalid += 1;
                self.gate.refused += 1;
                o.diagnostics(t, &topic, GateDecision::RejectedInvalid, &why);
                return self.after_fix(t, &topic, ctx, o);
            }
        };
        // Counted once the fix has passed every check: its class, or (above) refused.
        self.gate.count(&verdict);
        let speed = fix.speed_mps.filter(|v| v.is_finite() && *v >= 0.0);
        self.standing = speed.is_some_and(|v| v < self.settings.standstill_speed_mps);
        let use_filtered = verdict == GateVerdict::PreFiltered;
        let (pe, pn, rpe, rpn) = self.prefiltered(t, (e, n, re, rn), use_filtered);
        let velocity = self.gnss_velocity(fix, speed);
        if self.nav.is_none() {
            self.start(fix, (e, n, re.max(rn)), speed, &topic, o);
            return self.after_fix(t, &topic, ctx, o);
        }
        self.advance_to(t);
        let (Some(nav), Some(_)) = (self.nav, self.filter.as_ref()) else {
            return self.after_fix(t, &topic, ctx, o);
        };
        // A fix beside the track is multipath, whatever its covariance says: at least as
        // wrong as its offset, and beyond the gate its position stays out (its Doppler speed
        // and course do not).
        let beside = match map {
            Some(m) => self.track_check(m, (pe, pn), rpe.max(rpn)),
            None => Ok(0.0),
        };
        // The fix's bias share is the receiver bias state's; the rest is white.
        let bias = self.settings.receiver_bias;
        let share2 = bias.share(fix.fix_type).powi(2);
        self.receiver_bias_psd = 2.0 * share2 * rpe.max(rpn) / bias.time_constant_s;
        let [be, bn] = self.calibration.receiver_bias_m;
        let white = |r: f64| (1.0 - share2) * r + beside.as_ref().map_or(0.0, |x| *x);
        let position = ErrorMeasurement {
            residual: SVector::<f64, 2>::new(pe - nav.east_m - be, pn - nav.north_m - bn),
            rows: position_rows(),
            covariance: SMatrix::<f64, 2, 2>::new(white(rpe), 0.0, 0.0, white(rpn)),
        };
        let class = match use_filtered {
            true => format!("pre-filtered: fix type {}", fix.fix_type.name()),
            false => format!("reference: fix type {}", fix.fix_type.name()),
        };
        let axes = ["east", "north"];
        let position_fused = match beside {
            Err(why) => {
                self.counts.rejected_gate += 1;
                let z = (Some(pe), Some(rpe));
                let decision = GateDecision::RejectedGate;
                o.record(t, &topic, Some("east"), z, None, decision, Some(&why));
                false
            }
            Ok(_) => self.update(0, position, [pe, pn], t, &topic, axes, Some(&class), o),
        };
        let mut fused_any = position_fused;
        if self.standing {
            fused_any |= self.standstill_update(t, &topic, o);
        } else if let Some(velocity) = velocity {
            fused_any |= self.velocity_update(t, &topic, velocity, o);
        }
        if fused_any {
            self.inject_and_learn(t, position_fused && verdict == GateVerdict::Reference);
            self.counts.accepted += 1;
        }
        self.after_fix(t, &topic, ctx, o);
    }

    /// The fix's position (east, north and their variances) through the pre-filters where
    /// `use_filtered`, else as it is. The pre-filters follow every gated fix, so that a
    /// single-point fix after an RTK stretch meets a current trend; only the pre-filtered
    /// class fuses their output.
    fn prefiltered(
        &mut self,
        t: u64,
        (e, n, re, rn): (f64, f64, f64, f64),
        use_filtered: bool,
    ) -> (f64, f64, f64, f64) {
        let filtered = [(0, e, re), (1, n, rn)].map(|(k, z, r)| self.prefilters[k].step(t, z, r));
        match use_filtered {
            true => (
                filtered[0].value,
                filtered[1].value,
                filtered[0].variance,
                filtered[1].variance,
            ),
            false => (e, n, re, rn),
        }
    }

    /// The fix's velocity in the plane (from its speed and course), through its pre-filters,
    /// as a measurement of the velocity error; whether it was fused.
    fn velocity_update(
        &mut self,
        t: u64,
        topic: &str,
        (v, cov): (SVector<f64, 2>, SMatrix<f64, 2, 2>),
        o: &mut Out,
    ) -> bool {
        let nav = self.nav.expect("started");
        let filtered = [(2, v[0], cov[(0, 0)]), (3, v[1], cov[(1, 1)])]
            .map(|(k, z, r)| self.prefilters[k].step(t, z, r));
        let (ve, vn) = (filtered[0].value, filtered[1].value);
        let r = match self.settings.prefilter.velocity {
            crate::prefilter::PreFilterSettings::None => cov,
            _ => SMatrix::<f64, 2, 2>::new(filtered[0].variance, 0.0, 0.0, filtered[1].variance),
        };
        let (nve, nvn) = nav.velocity();
        let m = ErrorMeasurement {
            residual: SVector::<f64, 2>::new(ve - nve, vn - nvn),
            rows: velocity_rows(&nav),
            covariance: r,
        };
        let axes = ["velocity_east", "velocity_north"];
        self.update(1, m, [ve, vn], t, topic, axes, None, o)
    }

    /// The fix's place in the plane, moved from the antenna to the navigation point, and its
    /// variance per axis, or why it cannot be used.
    fn check_fix(
        &mut self,
        fix: &GnssFix,
        ctx: &SensorContext,
    ) -> Result<(f64, f64, f64, f64), String> {
        let Some((e, n)) = self.plane(fix, ctx.track.as_ref()) else {
            return Err(
                "absurd coordinates (not finite, off the globe or too far from the origin)".into(),
            );
        };
        let cov = fix.position_covariance_enu_m2;
        let variance = |c: Option<f64>| match self.gnss_variance? {
            VarianceValue::Fixed(v) => Some(v),
            VarianceValue::FromMessage(_) => c,
        };
        let (Some(re), Some(rn)) = (variance(cov.map(|c| c[0])), variance(cov.map(|c| c[4])))
        else {
            return Err("a fix without its variance".into());
        };
        if !(re > 0.0 && rn > 0.0 && re.is_finite() && rn.is_finite()) {
            return Err("a fix with a variance that is not positive".into());
        }
        let (e, n) = self.antenna_to_nav(ctx, (e, n), fix.course_rad);
        Ok((e, n, re, rn))
    }

    /// The fix's position in the plane, the origin set by the map or else by the first fix.
    fn plane(&mut self, fix: &GnssFix, map: Option<&TrackMap>) -> Option<(f64, f64)> {
        let (lat, lon) = (fix.latitude_deg?, fix.longitude_deg?);
        if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0) {
            return None;
        }
        let alt = fix.altitude_m.filter(|a| a.is_finite()).unwrap_or(0.0);
        let origin = *self.origin.get_or_insert_with(|| match map {
            Some(m) => m.origin,
            None => GeodeticOrigin {
                latitude_deg: lat,
                longitude_deg: lon,
                altitude_m: alt,
            },
        });
        let (e, n, _) = origin.to_enu(lat, lon, alt);
        let far = e.hypot(n) > self.settings.max_distance_m;
        (e.is_finite() && n.is_finite() && !far).then_some((e, n))
    }

    /// East/north velocity and its covariance from the fix's speed and course.
    fn gnss_velocity(
        &self,
        fix: &GnssFix,
        speed: Option<f64>,
    ) -> Option<(SVector<f64, 2>, SMatrix<f64, 2, 2>)> {
        let s = &self.settings;
        let (v, c) = (speed?, fix.course_rad.filter(|c| c.is_finite())?);
        if !s.velocity || v < s.min_course_speed_mps {
            return None;
        }
        let sv = s.speed_std_mps;
        let sc = sv / v;
        Some(match s.unscented_velocity {
            true => velocity_from_speed_and_course(v, sv * sv, c, sc * sc),
            false => {
                // First order: J diag(σv², σc²) Jᵀ with J = ∂(v sin c, v cos c)/∂(v, c).
                let j = SMatrix::<f64, 2, 2>::new(c.sin(), v * c.cos(), c.cos(), -v * c.sin());
                let r = j * SMatrix::<f64, 2, 2>::new(sv * sv, 0.0, 0.0, sc * sc) * j.transpose();
                (SVector::<f64, 2>::new(v * c.sin(), v * c.cos()), r)
            }
        })
    }

    /// The filter starts at a moving fix: position from it, heading from its course.
    fn start(
        &mut self,
        fix: &GnssFix,
        (e, n, r): (f64, f64, f64),
        speed: Option<f64>,
        topic: &str,
        o: &mut Out,
    ) {
        let s = &self.settings;
        let moving = speed.filter(|v| *v >= s.init_speed_mps);
        let (Some(v), Some(course)) = (moving, fix.course_rad.filter(|c| c.is_finite())) else {
            self.counts.before_initialisation += 1;
            o.diagnostics(
                fix.stamp_ns,
                topic,
                GateDecision::BeforeInitialisation,
                "waiting for a moving fix with a course",
            );
            return;
        };
        let bias = self.standstill.estimate();
        let n_ = &s.imu_noise;
        let nav = Navigation {
            east_m: e,
            north_m: n,
            speed_mps: v,
            heading_rad: course,
            accel_bias_mps2: bias.map_or(0.0, |b| b.forward_mps2),
            gyro_bias_radps: bias.map_or(0.0, |b| b.yaw_rate_radps),
            ..Navigation::default()
        };
        let heading_std = s.speed_std_mps / v + 0.02;
        let mut diagonal = ErrorVector::zeros();
        diagonal[0] = r;
        diagonal[1] = r;
        diagonal[V] = s.speed_std_mps.powi(2);
        // The course says the velocity's direction: the lateral speed is as uncertain as the
        // speed.
        diagonal[W] = s.speed_std_mps.powi(2);
        diagonal[PSI] = heading_std.powi(2);
        diagonal[BA] = n_.accel_bias_std_mps2.powi(2);
        diagonal[BY] = n_.accel_bias_std_mps2.powi(2);
        diagonal[BG] = n_.gyro_bias_std_radps.powi(2);
        let bias = s.receiver_bias.share(fix.fix_type).powi(2) * r;
        diagonal[GE] = bias;
        diagonal[GN] = bias;
        for (j, sensor) in self.roles.speed.iter().enumerate() {
            diagonal[K + j] = sensor.scale.map_or(0.0, |f| f.std.powi(2));
        }
        let p = ErrorMatrix::from_diagonal(&diagonal);
        self.nav = Some(nav);
        self.filter = Some(ErrorStateFilter::new(p));
        self.time_ns = fix.stamp_ns;
        self.last_fused_ns = Some(fix.stamp_ns);
        self.counts.accepted += 1;
        o.record(
            fix.stamp_ns,
            topic,
            Some("east"),
            (Some(e), Some(r)),
            None,
            GateDecision::Accepted,
            None,
        );
    }

    /// A pair of measurements (`kind` 0 position, 1 velocity) through the AKF (if on) and the
    /// filter; returns whether it was fused.
    fn update(
        &mut self,
        kind: usize,
        mut m: ErrorMeasurement,
        measured: [f64; 2],
        t: u64,
        topic: &str,
        axes: [&str; 2],
        class: Option<&str>,
        o: &mut Out,
    ) -> bool {
        let filter = self.filter.as_mut().expect("started");
        let projected = filter.projected(&m.rows);
        if let Some(akf) = self.akf.as_mut() {
            let reported = m.covariance;
            m.covariance = akf[kind].noise(reported);
            akf[kind].push(m.residual, projected, reported);
        }
        let gate = self.base.gates[self.roles.gnss];
        let s = projected + m.covariance;
        let nis = s
            .try_inverse()
            .map(|si| (m.residual.transpose() * si * m.residual)[0]);
        // Two degrees of freedom: the gate is per scalar in the config, so doubled.
        let gated = matches!((gate, nis), (Some(g), Some(nis)) if nis > 2.0 * g);
        if !gated && filter.update_pair(&m).is_none() {
            self.counts.rejected_invalid += 1;
            o.diagnostics(
                t,
                topic,
                GateDecision::RejectedInvalid,
                "a measurement covariance that is not positive definite",
            );
            return false;
        }
        let (decision, reason) = match gated {
            true => (GateDecision::RejectedGate, Some("NIS beyond the gate")),
            false => (GateDecision::Accepted, class),
        };
        for (k, axis) in axes.iter().enumerate() {
            let i = Innovation::new(m.residual[k], s[(k, k)]);
            let z = (Some(measured[k]), Some(m.covariance[(k, k)]));
            o.record(t, topic, Some(axis), z, Some(i), decision, reason);
        }
        self.counts.rejected_gate += u64::from(gated);
        !gated
    }

    /// A standing train: zero speed, and the mean yaw rate since the last fix is the gyro's
    /// bias (the earth's rate, 0.004 °/s at these latitudes, is below what a MEMS gyro shows).
    fn standstill_update(&mut self, t: u64, topic: &str, o: &mut Out) -> bool {
        let nav = self.nav.expect("started");
        let filter = self.filter.as_mut().expect("started");
        let r = STANDSTILL_SPEED_STD_MPS.powi(2);
        let i = filter.kf.update(&unit(V).transpose(), r, -nav.speed_mps);
        o.record(
            t,
            topic,
            Some("standstill_speed"),
            (Some(0.0), Some(r)),
            Some(i),
            GateDecision::Accepted,
            None,
        );
        if let Some(rate) = self.standstill.since_last_take() {
            let r = self.settings.imu_noise.gyro_noise_density.powi(2) / rate.seconds.max(1e-3);
            let i = filter.kf.update(
                &unit(BG).transpose(),
                r,
                rate.mean_yaw_rate - nav.gyro_bias_radps,
            );
            o.record(
                t,
                topic,
                Some("standstill_yaw_rate"),
                (Some(rate.mean_yaw_rate), Some(r)),
                Some(i),
                GateDecision::Accepted,
                None,
            );
        }
        true
    }

    /// Puts the update into the navigation; learns from it when the fix was a reference one
    /// ("while GNSS is good": a single-point fix's corrections carry the receiver's own
    /// wandering bias, which learnt as an IMU error and applied through a long loss does more
    /// harm than good: on seed003, 2.0 m chainage RMSE against 0.5 m without learning).
    fn inject_and_learn(&mut self, t: u64, reference: bool) {
        let (Some(nav), Some(filter)) = (self.nav.as_mut(), self.filter.as_mut()) else {
            return;
        };
        let dx = filter.kf.estimate.state;
        filter.inject(nav, &mut self.calibration);
        match (self.last_reference_ns, reference) {
            (Some(last), true) => {
                let dt = seconds_between(last, t);
                self.learning
                    .learn(dx[V], dx[PSI], dt, &self.settings.learning);
            }
            _ => {}
        }
        self.last_reference_ns = reference.then_some(t);
        self.last_fused_ns = Some(t);
        self.in_loss = false;
    }

    /// After every fix: a state (once started) and, once a second, the learnt IMU model.
    fn after_fix(&mut self, t: u64, topic: &str, ctx: &SensorContext, o: &mut Out) {
        if self.nav.is_some() {
            self.output(t, topic, ctx, o);
        }
    }
}
