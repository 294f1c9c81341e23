//! GNSS receiver with RTK: fix type follows sky visibility (tunnels) and the correction link;
//! position noise and a slowly wandering bias depend on the fix type.
//!
//! The bias is one unit-variance Gauss-Markov process scaled by the current fix type's σ,
//! so it changes size the moment the solution does: an RTK fixed fix has none, as a real
//! receiver's fixed solution drops the single-point error at once rather than letting it
//! decay over the bias's correlation time (which gave fixes reported at 2 cm a hidden error
//! of up to a metre for a minute after every reacquisition).

use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::messages::{FixType, GnssFix, SensorMount};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::gauss;
use crate::simulator::kinematics::motion;
use crate::simulator::world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GnssParams {
    pub rate_hz: f64,
    pub latency_s: f64,
    /// Horizontal 1σ white noise per fix type: single, DGPS, RTK float, RTK fixed (m).
    pub sigma_single_m: f64,
    pub sigma_dgps_m: f64,
    pub sigma_rtk_float_m: f64,
    pub sigma_rtk_fixed_m: f64,
    /// Correlation time of the slowly wandering position bias (single/DGPS), s.
    pub bias_tau_s: f64,
    /// The bias's true σ over the one the receiver's reported variance assumes (1: as
    /// reported). Experiments with a receiver worse or better than its own error model.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub bias_scale: f64,
    pub speed_sigma_mps: f64,
    /// After the sky comes back: seconds without a fix, then seconds of single-point fix
    /// before RTK float, then seconds of float before RTK fixed.
    pub reacquire_none_s: f64,
    pub reacquire_single_s: f64,
    pub reacquire_float_s: f64,
    /// RTK solutions come at this rate, below `rate_hz` (a single-frequency board: single
    /// point at 10 Hz, RTK at 5 Hz); None: at `rate_hz`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rtk_rate_hz: Option<f64>,
}

pub struct Gnss {
    p: GnssParams,
    /// The antenna's place on the train.
    mount: SensorMount,
    origin: GeodeticOrigin,
    schedule: Schedule,
    rng: ChaCha8Rng,
    /// Time the sky became visible (None while in a tunnel).
    sky_since_ns: Option<u64>,
    corrections_since_ns: Option<u64>,
    /// The bias's unit-variance Gauss-Markov state (east, north).
    bias_unit: (f64, f64),
    satellites: f64,
    epochs: u64,
}

impl Gnss {
    pub fn new(
        p: GnssParams,
        mount: SensorMount,
        origin: GeodeticOrigin,
        start_ns: u64,
        rng: ChaCha8Rng,
    ) -> Self {
        // At the start the receiver has been running a while: long since fixed.
        let long_ago = start_ns.saturating_sub(seconds(3600.0));
        Self {
            schedule: Schedule::new(start_ns, p.rate_hz),
            p,
            mount,
            origin,
            rng,
            sky_since_ns: Some(long_ago),
            corrections_since_ns: Some(long_ago),
            bias_unit: (0.0, 0.0),
            satellites: 17.0,
            epochs: 0,
        }
    }

    fn fix_type(&self, t_ns: u64) -> FixType {
        let p = &self.p;
        let Some(sky) = self.sky_since_ns else {
            return FixType::None;
        };
        let since_sky = (t_ns - sky) as f64 / 1e9;
        if since_sky < p.reacquire_none_s {
            return FixType::None;
        }
        let Some(corrections) = self.corrections_since_ns else {
            return FixType::Single;
        };
        // RTK can start once a single-point fix has settled and corrections arrive.
        let rtk_start = corrections.max(sky + seconds(p.reacquire_none_s + p.reacquire_single_s));
        if t_ns < rtk_start {
            FixType::Single
        } else if ((t_ns - rtk_start) as f64 / 1e9) < p.reacquire_float_s {
            FixType::RtkFloat
        } else {
            FixType::RtkFixed
        }
    }

    fn sigma(&self, fix: FixType) -> (f64, f64) {
        // (white noise σ, stationary bias σ)
        match fix {
            FixType::None => (0.0, 0.0),
            FixType::Single => (self.p.sigma_single_m, 0.8 * self.p.sigma_single_m),
            FixType::Dgps => (self.p.sigma_dgps_m, 0.6 * self.p.sigma_dgps_m),
            FixType::RtkFloat => (self.p.sigma_rtk_float_m, 0.3 * self.p.sigma_rtk_float_m),
            FixType::RtkFixed => (self.p.sigma_rtk_fixed_m, 0.0),
        }
    }

    /// Since when the sky and the corrections have been there (reacquisition times count
    /// from those).
    fn track_sky_and_corrections(&mut self, w: &World) {
        match (w.in_tunnel || w.gnss_outage, self.sky_since_ns) {
            (true, Some(_)) => self.sky_since_ns = None,
            (false, None) => self.sky_since_ns = Some(w.t_ns),
            _ => {}
        }
        match (w.corrections, self.corrections_since_ns) {
            (false, Some(_)) => self.corrections_since_ns = None,
            (true, None) => self.corrections_since_ns = Some(w.t_ns),
            _ => {}
        }
    }

    /// The satellites in view: eighteen under an open sky, fewer in cuttings, none in a
    /// tunnel, following slowly with noise; at most 3 without a fix, at least 5 with one.
    fn satellites(&mut self, w: &World, fix: FixType) -> u8 {
        let target_sats = if w.in_tunnel || w.gnss_outage {
            0.0
        } else {
            18.0 * w.sky_view
        };
        self.satellites += 0.2 * (target_sats - self.satellites) + gauss(&mut self.rng, 0.3);
        self.satellites = self.satellites.clamp(0.0, 32.0);
        if fix == FixType::None {
            self.satellites.min(3.0)
        } else {
            self.satellites.max(5.0)
        }
        .round() as u8
    }
}

impl SimSensor for Gnss {
    fn step(&mut self, w: &World<'_>, out: &mut Outbox) {
        self.track_sky_and_corrections(w);
        if !self.schedule.due(w.t_ns) {
            return;
        }
        let dt = self.schedule.period_s();
        let fix = self.fix_type(w.t_ns);
        let (sigma, bias_sigma) = self.sigma(fix);
        // First-order Gauss-Markov bias with stationary σ `bias_sigma`.
        let phi = (-dt / self.p.bias_tau_s).exp();
        let q = (1.0 - phi * phi).sqrt();
        self.bias_unit = (
            phi * self.bias_unit.0 + gauss(&mut self.rng, q),
            phi * self.bias_unit.1 + gauss(&mut self.rng, q),
        );
        let scale = bias_sigma * self.p.bias_scale;
        let bias = (scale * self.bias_unit.0, scale * self.bias_unit.1);
        let satellites = self.satellites(w, fix);
        let mut msg = GnssFix {
            stamp_ns: w.t_ns,
            fix_type: fix,
            satellites,
            hdop: (satellites > 0).then(|| 0.5 + 10.0 / satellites as f64),
            latitude_deg: None,
            longitude_deg: None,
            altitude_m: None,
            altitude_msl_m: None,
            position_covariance_enu_m2: None,
            speed_mps: None,
            course_rad: None,
        };
        if fix.has_position() {
            // The antenna's phase centre, where it sits on the train.
            let m = motion(w, &self.mount);
            let (me, mn) = w.gnss_multipath;
            let e = m.position.x + bias.0 + me + gauss(&mut self.rng, sigma);
            let n = m.position.y + bias.1 + mn + gauss(&mut self.rng, sigma);
            let u = m.position.z + gauss(&mut self.rng, 1.8 * sigma);
            let ground_speed = m.velocity.xy().norm();
            let (lat, lon, alt) = self.origin.to_geodetic(e, n, u);
            let var = sigma * sigma + bias_sigma * bias_sigma;
            msg.latitude_deg = Some(lat);
            msg.longitude_deg = Some(lon);
            msg.altitude_m = Some(alt);
            msg.position_covariance_enu_m2 =
                Some([var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, 3.24 * var]);
            msg.speed_mps =
                Some((ground_speed + gauss(&mut self.rng, self.p.speed_sigma_mps)).max(0.0));
            if ground_speed > 0.5 {
                let course = m.velocity.x.atan2(m.velocity.y);
                let c = course + gauss(&mut self.rng, self.p.speed_sigma_mps / ground_speed);
                msg.course_rad = Some(c.rem_euclid(std::f64::consts::TAU));
            }
        }
        self.epochs += 1;
        let rtk = matches!(fix, FixType::RtkFloat | FixType::RtkFixed);
        if let (true, Some(rtk_rate)) = (rtk, self.p.rtk_rate_hz) {
            // Every n-th epoch of the solution rate carries the RTK solution.
            let every = (self.p.rate_hz / rtk_rate).round().max(1.0) as u64;
            if !self.epochs.is_multiple_of(every) {
                return;
            }
        }
        let latency = seconds(self.p.latency_s);
        out.push(w.t_ns + latency, Emit::Gnss(msg));
    }
}

fn one() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::scenario::LineScenario;
    use crate::simulator::sensors::rng_stream;

    /// Fixes (east error, north error, fix type) over `seconds` at 10 Hz, standing at the
    /// origin, with RTK corrections from `corrections_from_s` on.
    fn fixes(seconds: f64, corrections_from_s: f64) -> Vec<(f64, f64, FixType)> {
        let origin = GeodeticOrigin {
            latitude_deg: 44.65,
            longitude_deg: 10.93,
            altitude_m: 40.0,
        };
        let mut gnss = Gnss::new(
            LineScenario::default_gnss(),
            SensorMount::at_front("/gnss/fix"),
            origin,
            0,
            rng_stream(7, 3),
        );
        let track = crate::simulator::track::straight_line(origin, None);
        let vehicle = railfuse_catalog::messages::Vehicle::point();
        let mut out = Outbox::default();
        let mut got = Vec::new();
        let step = 10_000_000;
        for t_ns in (0..super::seconds(seconds)).step_by(step as usize) {
            let w = World {
                t_ns,
                dt: step as f64 / 1e9,
                chainage_m: 0.0,
                speed_mps: 0.0,
                acceleration_mps2: 0.0,
                east_m: 0.0,
                north_m: 0.0,
                heading_rad: 0.0,
                curvature: 0.0,
                in_tunnel: false,
                corrections: t_ns >= super::seconds(corrections_from_s),
                gnss_outage: false,
                sky_view: 1.0,
                gnss_multipath: (0.0, 0.0),
                track: &track,
                vehicle: &vehicle,
                ride: Default::default(),
            };
            gnss.step(&w, &mut out);
            while let Some((_, Emit::Gnss(fix))) = out.pop_due(u64::MAX) {
                if let (Some(lat), Some(lon)) = (fix.latitude_deg, fix.longitude_deg) {
                    let (e, n, _) = origin.to_enu(lat, lon, fix.altitude_m.unwrap_or(0.0));
                    got.push((e, n, fix.fix_type));
                }
            }
        }
        got
    }

    #[test]
    fn an_rtk_fixed_fix_carries_no_single_point_bias_from_before_it_fixed() {
        // Two minutes of single-point fixes (a bias of metres), then corrections: float for
        // 12 s, then fixed. The fixed fixes must be as good as their 2 cm, from the first.
        let got = fixes(200.0, 120.0);
        let single: Vec<_> = got.iter().filter(|f| f.2 == FixType::Single).collect();
        let fixed: Vec<_> = got.iter().filter(|f| f.2 == FixType::RtkFixed).collect();
        assert!(
            single.len() > 1000 && fixed.len() > 400,
            "{} {}",
            single.len(),
            fixed.len()
        );
        let worst_single = single.iter().map(|f| f.0.hypot(f.1)).fold(0.0, f64::max);
        assert!(
            worst_single > 0.5,
            "single-point fixes err by metres: {worst_single}"
        );
        let worst_fixed = fixed.iter().map(|f| f.0.hypot(f.1)).fold(0.0, f64::max);
        assert!(worst_fixed < 0.1, "an RTK fixed fix is {worst_fixed} m off");
    }
}
