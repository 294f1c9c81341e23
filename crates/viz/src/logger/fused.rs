//! A pipeline's channels as entities: states with their error bands, diagnostics (NIS, gate
//! decisions, β shares, eddy-current windows), the safety status and the IMU error model.

use railfuse_catalog::messages::fused::CHI2_95_1DOF;
use railfuse_catalog::messages::*;
use rerun::components::{InterpolationMode, MarkerShape};
use rerun::{Color, Radius, SeriesLines, SeriesPoints};

use super::*;
use crate::blueprint::NIS_AXIS_MAX;
use crate::series::SeriesId;
use crate::series::{OutlinesId, SegmentsId};
use crate::{entities as ent, map, palette, Error};

/// How often a pipeline's train is drawn at most, ns.
const TRAIN_EVERY_NS: i64 = 500_000_000;

impl Logger {
    pub(super) fn fused(&mut self, p: usize, smoothed: bool, f: &FusedState) -> Result<(), Error> {
        let t = f.stamp_ns as i64;
        if smoothed && self.pipelines[p].smoothed.is_none() {
            let (name, index) = (self.pipelines[p].name.clone(), self.pipelines[p].index);
            self.pipelines[p].smoothed = Some(self.fused_series(&name, index, true)?);
        }
        let (s3, v3) = (3.0 * f.chainage_std_m(), 3.0 * f.speed_std_mps());
        let truth = self.truth.at(f.stamp_ns);
        let state = &self.pipelines[p];
        let series = if smoothed {
            state.smoothed.as_ref()
        } else {
            Some(&state.filtered)
        };
        let Some(series) = series else { return Ok(()) };
        let (speed, chainage_error, speed_error) =
            (series.speed, series.chainage_error, series.speed_error);
        let (position, extent) = (state.position, state.extent);
        self.columns.push(&self.rec, speed, t, &[f.speed_mps])?;
        if let Some((s, v)) = truth {
            let e = f.chainage_m - s;
            self.columns
                .push(&self.rec, chainage_error, t, &[e, e + s3, e - s3])?;
            let e = f.speed_mps - v;
            self.columns
                .push(&self.rec, speed_error, t, &[e, e + v3, e - v3])?;
        }
        if smoothed {
            return Ok(());
        }
        if let Some(plane) = &f.plane {
            self.plane_position(p, t, plane)?;
        } else if let Some(m) = &self.map {
            if let (Some(here), Some(behind), Some(ahead)) = (
                map::at(m, f.chainage_m),
                map::at(m, f.chainage_m - s3),
                map::at(m, f.chainage_m + s3),
            ) {
                self.columns.point(&self.rec, position, t, here)?;
                self.columns
                    .segment(&self.rec, extent, t, [behind, ahead])?;
            }
        }
        let name = self.pipelines[p].name.clone();
        for st in &f.sensor_states {
            let entity = ent::sensor_state(&name, &st.topic, &st.kind);
            let title = format!("{} {}", st.topic, st.kind.replace('_', " "));
            self.band_value(p, &entity, &title, "3σ", t, st.value, 3.0 * st.std)?;
        }
        // A 2-D pipeline's velocity: east and north errors against the truth.
        let plane = f.plane.as_ref();
        if let (Some([ve, vn]), Some(c), Some((te, tn))) = (
            plane.and_then(|p| p.velocity_en_mps),
            plane.and_then(|p| p.velocity_covariance_en),
            self.truth_velocity.at(f.stamp_ns),
        ) {
            for (axis, e, var) in [("east", ve - te, c[0]), ("north", vn - tn, c[3])] {
                let entity = ent::velocity_error(&name, axis);
                let title = format!("{axis} velocity error (m/s)");
                self.band_value(p, &entity, &title, "3σ", t, e, 3.0 * var.max(0.0).sqrt())?;
            }
        }
        Ok(())
    }

    /// The whole train after a pipeline's state: its body along the track from the rear end
    /// to the front end, the safe front end interval, and (with the log's drawing) each
    /// sensor where it sits; twice a second at most (a train moves 20 m in that at line
    /// speed, and a map holds few more).
    pub(super) fn train(&mut self, p: usize, tp: &TrainPosition) -> Result<(), Error> {
        let t = tp.stamp_ns as i64;
        let Some(m) = &self.map else { return Ok(()) };
        if self.pipelines[p]
            .last_train_ns
            .is_some_and(|last| t < last + TRAIN_EVERY_NS)
        {
            return Ok(());
        }
        let body = map::stretch(m, tp.rear_chainage_m, tp.front_chainage_m);
        let safe = map::at(m, tp.min_safe_front_m).zip(map::at(m, tp.max_safe_front_m));
        // Unlabelled: at a whole line's zoom eight labels on one spot hide the map; hovering
        // a point in the viewer names its entity.
        let sensors: Vec<[f32; 2]> = self
            .vehicle
            .iter()
            .flat_map(|v| &v.sensors)
            .filter_map(|s| map::at(m, s.chainage(tp.front_chainage_m)))
            .collect();
        let (body_id, safe_id) = match self.pipelines[p].train {
            Some(ids) => ids,
            None => self.register_train(p)?,
        };
        self.pipelines[p].last_train_ns = Some(t);
        self.columns.outline(&self.rec, body_id, t, body)?;
        if let Some((low, high)) = safe {
            self.columns.segment(&self.rec, safe_id, t, [low, high])?;
        }
        if !sensors.is_empty() {
            let entity = ent::fused_train_sensors(&self.pipelines[p].name);
            self.rec
                .set_timestamp_nanos_since_epoch(crate::series::TIMELINE, t);
            self.rec
                .log(
                    entity.as_str(),
                    &rerun::Points2D::new(sensors)
                        .with_colors([palette::pipeline(self.pipelines[p].index)])
                        .with_radii([Radius::new_ui_points(3.0)]),
                )
                .map_err(|e| Error::Rerun(e.to_string()))?;
            self.entities.insert(entity);
        }
        Ok(())
    }

    /// The train's entities, styled in the pipeline's colour.
    fn register_train(&mut self, p: usize) -> Result<(OutlinesId, SegmentsId), Error> {
        let (name, index) = (self.pipelines[p].name.clone(), self.pipelines[p].index);
        self.static_(
            &ent::fused_train(&name),
            &rerun::LineStrips2D::update_fields()
                .with_colors([palette::pipeline(index)])
                .with_radii([Radius::new_ui_points(4.0)]),
        )?;
        self.static_(
            &ent::fused_safe_front(&name),
            &rerun::LineStrips2D::update_fields()
                .with_colors([palette::band(index)])
                .with_radii([Radius::new_ui_points(7.0)]),
        )?;
        let ids = (
            self.columns.outlines(&ent::fused_train(&name)),
            self.columns.segments(&ent::fused_safe_front(&name)),
        );
        self.pipelines[p].train = Some(ids);
        Ok(ids)
    }

    /// A 2-D pipeline: where it is in the plane, with its 3σ ellipse (its entity styled on
    /// first use).
    fn plane_position(&mut self, p: usize, t: i64, plane: &PlanePosition) -> Result<(), Error> {
        let position = self.pipelines[p].position;
        let ellipse = match self.pipelines[p].ellipse {
            Some(id) => id,
            None => {
                let entity = ent::fused_ellipse(&self.pipelines[p].name);
                let index = self.pipelines[p].index;
                self.static_(
                    &entity,
                    &rerun::LineStrips2D::update_fields()
                        .with_colors([palette::band(index)])
                        .with_radii([Radius::new_ui_points(1.5)]),
                )?;
                let id = self.columns.outlines(&entity);
                self.pipelines[p].ellipse = Some(id);
                id
            }
        };
        let outline: Vec<[f32; 2]> = plane
            .ellipse_3sigma(36)
            .into_iter()
            .map(|(e, n)| map::plan(e, n))
            .collect();
        self.columns.point(
            &self.rec,
            position,
            t,
            map::plan(plane.east_m, plane.north_m),
        )?;
        self.columns.outline(&self.rec, ellipse, t, outline)?;
        Ok(())
    }

    /// One row of a banded value in a pipeline's tab (`[v, v + b, v − b]`), its plot
    /// registered on first use under `title` with the band's `width` named.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn band_value(
        &mut self,
        p: usize,
        entity: &str,
        title: &str,
        width: &str,
        t: i64,
        value: f64,
        band: f64,
    ) -> Result<(), Error> {
        let id = match self.pipelines[p].bands.get(entity) {
            Some(&id) => id,
            None => {
                let index = self.pipelines[p].index;
                let id = self.band_series_of(entity, title, index, false, width)?;
                self.pipelines[p].bands.insert(entity.to_owned(), id);
                let title = format!("{title} ±{width}");
                self.layout.pipelines[p]
                    .bands
                    .push((entity.to_owned(), title));
                id
            }
        };
        self.columns
            .push(&self.rec, id, t, &[value, value + band, value - band])
    }

    /// A GNSS/INS pipeline's learnt IMU error model (once a second): the mean residual
    /// rates ψ with their spread σ; when it starts or stops being applied, a log line.
    pub(super) fn imu_error_model(&mut self, p: usize, m: &ImuErrorModel) -> Result<(), Error> {
        let (t, name) = (m.stamp_ns as i64, self.pipelines[p].name.clone());
        let terms = [
            (
                "speed_residual",
                "learnt ψ speed (m/s²)",
                m.speed_residual_mps2,
                m.speed_residual_std_mps2,
            ),
            (
                "heading_residual",
                "learnt ψ heading (rad/s)",
                m.heading_residual_radps,
                m.heading_residual_std_radps,
            ),
        ];
        for (term, title, value, std) in terms {
            let entity = ent::imu_error_model(&name, term);
            self.band_value(p, &entity, title, "σ", t, value, std)?;
        }
        if self.pipelines[p].model_applied.replace(m.applied) != Some(m.applied) {
            let text = if m.applied {
                format!(
                    "{name}: GNSS lost: the learnt IMU model corrects the inertial solution \
                     (ψ speed {:+.2e} m/s², heading {:+.2e} rad/s, learnt over {:.0} s)",
                    m.speed_residual_mps2, m.heading_residual_radps, m.learnt_s
                )
            } else {
                format!("{name}: learning the IMU error model from GNSS")
            };
            self.text(m.stamp_ns, text, if m.applied { "WARN" } else { "INFO" })?;
        }
        Ok(())
    }

    /// One epoch's safety status: U_safe's ends relative to the reference and the usable
    /// flag as series; each change of the first failing check as a log line.
    pub(super) fn safety(&mut self, p: usize, s: &SafetyStatus) -> Result<(), Error> {
        let t = s.stamp_ns as i64;
        let (interval, flag) = match self.pipelines[p].safety {
            Some(ids) => ids,
            None => {
                let (name, index) = (self.pipelines[p].name.clone(), self.pipelines[p].index);
                let interval = self.line_series(
                    &ent::safe_interval(&name),
                    &[format!("{name} U_safe high"), format!("{name} U_safe low")],
                    &[palette::smoothed(index), palette::smoothed(index)],
                    &[1.0, 1.0],
                )?;
                let flag = self.line_series(
                    &ent::safety(&name),
                    &["usable".into()],
                    &[palette::pipeline(index)],
                    &[1.5],
                )?;
                self.pipelines[p].safety = Some((interval, flag));
                self.layout.pipelines[p].safety = true;
                (interval, flag)
            }
        };
        let truth = self.truth.at(s.stamp_ns).map(|(c, _)| c);
        let (high, low) = match (s.safe_interval, truth) {
            (Some(u), Some(c)) => (u.high_m - c, u.low_m - c),
            _ => (f64::NAN, f64::NAN),
        };
        self.columns.push(&self.rec, interval, t, &[high, low])?;
        let usable = if s.usable { 1.0 } else { 0.0 };
        self.columns.push(&self.rec, flag, t, &[usable])?;
        if self.pipelines[p].last_failure.as_ref() != Some(&s.first_failure) {
            self.pipelines[p].last_failure = Some(s.first_failure.clone());
            let name = self.pipelines[p].name.clone();
            let (text, level) = match (&s.first_failure, &s.reason) {
                (Some(check), reason) => (
                    format!(
                        "{name}: not usable: {check}: {}",
                        reason.as_deref().unwrap_or("")
                    ),
                    "WARN",
                ),
                (None, _) => (format!("{name}: usable again, every check passes"), "INFO"),
            };
            self.text(s.stamp_ns, text, level)?;
        }
        Ok(())
    }

    pub(super) fn diagnostics(&mut self, p: usize, d: &FusedDiagnostics) -> Result<(), Error> {
        let t = d.stamp_ns as i64;
        let name = self.pipelines[p].name.clone();
        // The χ² bounds as lines under the whole NIS plot: drawn on as time goes.
        let state = &mut self.pipelines[p];
        state.last_diagnostics_ns = Some(t);
        if state.bounds_to_ns.is_none_or(|b| t > b + 10_000_000_000) {
            state.bounds_to_ns = Some(t);
            let bounds = state.bounds;
            self.columns
                .push(&self.rec, bounds, t, &[CHI2_95_1DOF.0, CHI2_95_1DOF.1])?;
        }
        match d.decision {
            GateDecision::Accepted => {
                if let Some(nis) = d.nis {
                    let id = self.nis_series(p, &d.source)?;
                    self.columns.push(&self.rec, id, t, &[nis])?;
                }
            }
            // Not yet a filter to disagree with: nothing to mark.
            GateDecision::BeforeInitialisation => {}
            decision => {
                let id = self.gate_series(p, decision)?;
                let y = d.nis.map_or(NIS_AXIS_MAX, |n| n.min(NIS_AXIS_MAX)) * 0.97;
                self.columns.push(&self.rec, id, t, &[y])?;
                let warning = match decision {
                    GateDecision::AcceptedAfterLockout => {
                        Some("accepted after a gate lockout (variance widened)")
                    }
                    GateDecision::ResetToFix => {
                        Some("rejected too often in a row: position reset to it")
                    }
                    _ => None,
                };
                if let Some(what) = warning {
                    self.text(d.stamp_ns, format!("{name}: {} {what}", d.source), "WARN")?;
                }
            }
        }
        if let Some(ess) = d.effective_sample_size {
            let id = match self.pipelines[p].effective_sample_size {
                Some(id) => id,
                None => {
                    let index = self.pipelines[p].index;
                    let id = self.line_series(
                        &ent::effective_sample_size(&name),
                        &["effective sample size".into()],
                        &[palette::pipeline(index)],
                        &[1.5],
                    )?;
                    self.pipelines[p].effective_sample_size = Some(id);
                    self.layout.pipelines[p].effective_sample_size = true;
                    id
                }
            };
            self.columns.push(&self.rec, id, t, &[ess])?;
        }
        if let Some(sharing) = &d.sharing {
            self.sharing(p, d.stamp_ns, sharing)?;
        }
        if let Some(e) = &d.eddy_current {
            self.eddy_current(p, t, e)?;
        }
        Ok(())
    }

    /// An eddy-current window: its correlation with and without warping, the warp's
    /// acceleration beside the filter's, and the two sensors' sleeper counts' difference.
    pub(super) fn eddy_current(
        &mut self,
        p: usize,
        t: i64,
        e: &EddyCurrentDiagnostics,
    ) -> Result<(), Error> {
        let name = self.pipelines[p].name.clone();
        let rows: [(&str, &str, [&str; 2], [f64; 2]); 3] = [
            (
                "correlation",
                "correlation peak ρ",
                ["ρ", "ρ unwarped"],
                [
                    e.rho.unwrap_or(f64::NAN),
                    e.unwarped_rho.unwrap_or(f64::NAN),
                ],
            ),
            (
                "acceleration",
                "acceleration (m/s²): warp and filter",
                ["warp", "filter"],
                [
                    e.warp_acceleration_mps2.unwrap_or(f64::NAN),
                    e.filter_acceleration_mps2.unwrap_or(f64::NAN),
                ],
            ),
            (
                "sleepers",
                "sleepers counted: a, b",
                ["sensor a", "sensor b"],
                [e.sleepers_a as f64, e.sleepers_b as f64],
            ),
        ];
        for (what, title, names, values) in rows {
            let plot = ent::eddy_current(&name, what);
            for (k, (component, value)) in names.iter().zip(values).enumerate() {
                if !value.is_finite() {
                    continue;
                }
                let entity = format!("{plot}/{}", component.replace(' ', "_"));
                let id = match self.raw.get(&entity) {
                    Some(&id) => id,
                    None => {
                        let index = self.pipelines[p].index;
                        let color = [palette::pipeline(index), palette::smoothed(index)][k];
                        let id = self.line_series(
                            &entity,
                            &[(*component).to_owned()],
                            &[color],
                            &[[1.5, 1.0][k]],
                        )?;
                        // ρ and the accelerations exist only in moving windows: the line
                        // breaks over a stop instead of joining its two ends.
                        if what != "sleepers" {
                            self.columns.break_on_silence(id);
                        }
                        self.raw.insert(entity.clone(), id);
                        let lines = &mut self.layout.pipelines[p].lines;
                        if !lines.iter().any(|(e, _)| *e == plot) {
                            lines.push((plot.clone(), title.to_owned()));
                        }
                        id
                    }
                };
                self.columns.push(&self.rec, id, t, &[value])?;
            }
        }
        Ok(())
    }

    pub(super) fn nis_series(&mut self, p: usize, source: &str) -> Result<SeriesId, Error> {
        if let Some(&id) = self.pipelines[p].nis.get(source) {
            return Ok(id);
        }
        let entity = ent::nis(&self.pipelines[p].name, source);
        let color = palette::raw_sensor(self.pipelines[p].nis.len());
        self.static_(
            &entity,
            &SeriesPoints::new()
                .with_names([source])
                .with_colors([color])
                .with_marker_sizes([1.0]),
        )?;
        let id = self.columns.series(&entity, 1);
        self.pipelines[p].nis.insert(source.to_owned(), id);
        Ok(id)
    }

    pub(super) fn gate_series(
        &mut self,
        p: usize,
        decision: GateDecision,
    ) -> Result<SeriesId, Error> {
        if let Some(&id) = self.pipelines[p].gates.get(&decision) {
            return Ok(id);
        }
        let entity = ent::gate_decisions(&self.pipelines[p].name, decision);
        let (marker, color) = match decision {
            GateDecision::AcceptedAfterLockout | GateDecision::ResetToFix => {
                (MarkerShape::Diamond, palette::after_lockout())
            }
            GateDecision::RejectedGate => (MarkerShape::Cross, palette::rejected()),
            _ => (MarkerShape::Asterisk, palette::bound()),
        };
        self.static_(
            &entity,
            &SeriesPoints::new()
                .with_names([ent::gate_decision_name(decision).replace('_', " ")])
                .with_colors([color])
                .with_markers([marker])
                .with_marker_sizes([4.0]),
        )?;
        let id = self.columns.series(&entity, 1);
        self.pipelines[p].gates.insert(decision, id);
        Ok(id)
    }

    /// A federated pipeline's β per device, logged when it changes, and devices going out
    /// or coming back as events.
    pub(super) fn sharing(
        &mut self,
        p: usize,
        t_ns: u64,
        sharing: &[DeviceShare],
    ) -> Result<(), Error> {
        let beta: Vec<f64> = sharing.iter().map(|s| s.beta).collect();
        let name = self.pipelines[p].name.clone();
        let id = match self.pipelines[p].sharing {
            // β's of another set of devices cannot share the series.
            Some((_, width)) if width != beta.len() => return Ok(()),
            Some((id, _)) => id,
            None => {
                let names: Vec<String> =
                    sharing.iter().map(|s| format!("β {}", s.device)).collect();
                let colors: Vec<Color> = (0..names.len()).map(palette::pipeline).collect();
                let entity = ent::sharing(&name);
                // β holds between fusions: steps, not slopes.
                self.static_(
                    &entity,
                    &SeriesLines::new()
                        .with_names(names.iter().cloned())
                        .with_colors(colors)
                        .with_widths(vec![1.5; names.len()])
                        .with_interpolation_mode(InterpolationMode::StepAfter),
                )?;
                let id = self.columns.series(&entity, names.len());
                self.pipelines[p].sharing = Some((id, beta.len()));
                self.layout.pipelines[p].sharing = true;
                id
            }
        };
        if self.pipelines[p].last_beta != beta {
            self.columns.push(&self.rec, id, t_ns as i64, &beta)?;
            self.pipelines[p].last_beta = beta;
        }
        for s in sharing {
            let was_out = self.pipelines[p].out.contains(&s.device);
            match (&s.fault, was_out) {
                (Some(why), false) => {
                    self.pipelines[p].out.insert(s.device.clone());
                    self.text(
                        t_ns,
                        format!("{name}: {} out of the fusion ({why})", s.device),
                        "WARN",
                    )?;
                }
                (None, true) => {
                    self.pipelines[p].out.remove(&s.device);
                    self.text(
                        t_ns,
                        format!("{name}: {} back in the fusion", s.device),
                        "INFO",
                    )?;
                }
                _ => {}
            }
        }
        Ok(())
    }
}
