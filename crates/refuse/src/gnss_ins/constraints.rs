//! What a train knows that a car does not, as pseudo-measurements of the error state
//! (railfuse's, not source 003's; each switchable, `[pipeline.gnss_ins.nhc]` and
//! `[pipeline.gnss_ins.track]`):
//!
//! - **non-holonomic constraint:** the body neither slides sideways nor lifts off its rails,
//!   so the lateral body speed is zero: `0 = w + δw`, row `δw`;
//! - **track constraint:** the train is on its track's centre line, `0 = d + n̂·δp` with `d`
//!   the navigation's signed offset from the map's centre line and `n̂ = (cos ψ_t, −sin ψ_t)`
//!   the normal to its right; and heads along it, `0 = ψ + δψ − ψ_t(p + δp)`, which through
//!   a curve (`∂ψ_t/∂s = κ` along the tangent `t̂ = (sin ψ_t, cos ψ_t)`) also says where
//!   along the track the train is: row `δψ − κ t̂·δp`.
//!
//! Each update is put into the navigation at once, as the GNSS ones are. Through a GNSS loss
//! the track holds the cross-track error to the map's and the heading to the track's; what is
//! left is along the track, which speed sensors bound ([`super::speed_sensors`]).

use railfuse_catalog::map_matching::{curvature_on, locate_on};
use railfuse_catalog::messages::TrackMap;

use super::error_state::{unit, ErrorVector, E, N, PSI, W};
use super::settings::GnssInsSettings;
use super::GnssInsPipeline;

/// The track's heading is that of the chord this far either side of the matched point, m:
/// smooth across the map's vertices (every 10–20 m), where a segment's own heading steps.
const HEADING_HALF_CHORD_M: f64 = 10.0;
/// The curvature is the heading change over this far either side, m.
const CURVATURE_HALF_SPAN_M: f64 = 25.0;

/// When each constraint is next due, and how often each was fused.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct State {
    next_nhc_ns: u64,
    next_track_ns: u64,
    nhc: u64,
    track: u64,
    /// Due with no map in the log, or with the navigation off the map's ends.
    no_map: u64,
    off_map: u64,
}

impl State {
    /// One phrase for the pipeline's report line.
    pub(super) fn report(&self, s: &GnssInsSettings) -> String {
        let nhc = match s.nhc.enabled {
            true => format!("NHC: {} updates", self.nhc),
            false => "NHC: off".into(),
        };
        let track = match (s.track.enabled, self.track, self.no_map) {
            (false, _, _) => "track constraint: off".into(),
            (true, 0, n) if n > 0 => "track constraint: no track map in the log".into(),
            (true, t, _) => format!(
                "track constraint: {t} updates ({} off the map's ends)",
                self.off_map
            ),
        };
        format!("{nhc}; {track}")
    }
}

impl GnssInsPipeline {
    /// The constraints due at `t` (after an IMU step).
    pub(super) fn constrain(&mut self, t: u64, map: Option<&TrackMap>) {
        let (nhc, track) = (self.settings.nhc, self.settings.track);
        let Some(nav) = self.nav else { return };
        let c = &mut self.constraints;
        if nhc.enabled && t >= c.next_nhc_ns {
            c.next_nhc_ns = t + (nhc.period_s * 1e9) as u64;
            c.nhc += 1;
            self.pseudo(&[(unit(W), nhc.lateral_std_mps.powi(2), -nav.lateral_mps)]);
        }
        let c = &mut self.constraints;
        if track.enabled && t >= c.next_track_ns {
            c.next_track_ns = t + (track.period_s * 1e9) as u64;
            match map {
                Some(map) => self.track(map),
                None => self.constraints.no_map += 1,
            }
        }
    }

    /// The cross-track offset and, if its σ is set, the heading against the track's.
    fn track(&mut self, map: &TrackMap) {
        let Some(nav) = self.nav else { return };
        let settings = self.settings.track;
        let matched = self
            .matcher
            .match_point(map, nav.east_m, nav.north_m, None)
            .filter(|m| !m.beyond_end);
        let (Some(m), Some(vertices)) = (matched, matched.and_then(|m| map.track(m.track))) else {
            self.constraints.off_map += 1;
            return;
        };
        self.constraints.track += 1;
        let (sin, cos) = m.heading_rad.sin_cos();
        let mut cross = ErrorVector::zeros();
        cross[E] = cos;
        cross[N] = -sin;
        let cross = (cross, settings.cross_track_std_m.powi(2), -m.lateral_m);
        let mut rows = [cross; 2];
        let mut n = 1;
        let chord = (
            locate_on(vertices, m.chainage_m - HEADING_HALF_CHORD_M),
            locate_on(vertices, m.chainage_m + HEADING_HALF_CHORD_M),
        );
        if let (true, (Some(a), Some(b))) = (settings.heading_std_rad > 0.0, chord) {
            let along = (b.0 - a.0).atan2(b.1 - a.1);
            let kappa = curvature_on(vertices, m.chainage_m, CURVATURE_HALF_SPAN_M);
            // Either way along the track: the direction nearer the train's heading.
            let mut residual = wrap(along - nav.heading_rad);
            if residual.abs() > std::f64::consts::FRAC_PI_2 {
                residual = wrap(residual + std::f64::consts::PI);
            }
            let (ts, tc) = along.sin_cos();
            let mut row = unit(PSI);
            row[E] = -kappa * ts;
            row[N] = -kappa * tc;
            rows[1] = (row, settings.heading_std_rad.powi(2), residual);
            n = 2;
        }
        self.pseudo(&rows[..n]);
    }

    /// A fix at (east, north) with variance `variance` against the track: a train is on its
    /// rails, so a fix beside them is at least as wrong as its offset, in any direction
    /// (multipath, however small the receiver's σ). Returns the variance to add to the fix's,
    /// the offset squared; or why it is refused, further from the track than
    /// `max_fix_offset_sigma` of its σ and the map's.
    pub(super) fn track_check(
        &mut self,
        map: &TrackMap,
        (east_m, north_m): (f64, f64),
        variance: f64,
    ) -> Result<f64, String> {
        let t = self.settings.track;
        if !t.enabled {
            return Ok(0.0);
        }
        let Some(m) = self
            .matcher
            .match_point(map, east_m, north_m, None)
            .filter(|m| !m.beyond_end)
        else {
            return Ok(0.0);
        };
        let sigma = (variance + t.cross_track_std_m.powi(2)).sqrt();
        let offset = m.lateral_m.abs();
        match t.max_fix_offset_sigma > 0.0 && offset > t.max_fix_offset_sigma * sigma {
            true => Err(format!(
                "{offset:.2} m off the track ({:.1} σ of the fix and the map): multipath",
                offset / sigma
            )),
            false => Ok(offset * offset),
        }
    }

    /// Scalar pseudo-measurements `(row, variance, residual)`, fused in turn and put into the
    /// navigation.
    fn pseudo(&mut self, rows: &[(ErrorVector, f64, f64)]) {
        let (Some(nav), Some(filter)) = (self.nav.as_mut(), self.filter.as_mut()) else {
            return;
        };
        for (row, r, residual) in rows {
            filter.kf.update(&row.transpose(), *r, *residual);
        }
        filter.inject(nav, &mut self.calibration);
    }
}

/// An angle wrapped into (−π, π].
pub(super) fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}
