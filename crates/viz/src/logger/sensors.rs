//! The raw channels as entities: truth, GNSS fixes, the IMU, position sensors, the track
//! map, events, and other tools' channels read as railfuse's.

use std::sync::Arc;

use railfuse_catalog::foreign::{Role, Translated, Translator};
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::{ChannelInfo, LogMessage};
use railfuse_catalog::messages::*;
use railfuse_catalog::reference_track::ReferenceSample;
use rerun::components::TextLogLevel;
use rerun::{Points2D, Radius, TextLog};

use super::*;
use crate::series::TIMELINE;
use crate::{entities as ent, map, palette, Error};

impl Logger {
    /// How a foreign channel is shown: as the catalogue kind it translates to. With no
    /// config to give a role, a twist is drawn as the speed of its topic. One that cannot be
    /// shown goes on the report with why.
    pub(super) fn foreign_channel(
        &mut self,
        c: &ChannelInfo,
    ) -> Option<(Translator, Arc<ChannelInfo>)> {
        let (encoding, schema) = (c.message_encoding.as_str(), c.schema_name());
        let t = Translator::for_channel(c, None)
            .or_else(|_| Translator::for_channel(c, Some(Role::Odometer)));
        match t {
            Ok(Some(t)) => {
                let info = t.channel(c);
                Some((t, info))
            }
            _ => {
                let why = format!(
                    "{schema} ({encoding}) is not a type railfuse reads (it reads {})",
                    Translator::schemas().join(", ")
                );
                self.report.not_shown.insert(c.topic.clone(), why);
                None
            }
        }
    }

    /// A foreign message, drawn as the catalogue message it translates to; one that does not
    /// decode is counted.
    pub(super) fn foreign_message(
        &mut self,
        t: &Translator,
        info: &Arc<ChannelInfo>,
        m: &LogMessage<'_>,
    ) -> Result<(), Error> {
        match t.translate(m.data, m.log_time_ns) {
            Ok(Translated::Message { message, .. }) => {
                let data = message.to_json();
                self.message(&LogMessage {
                    channel: info,
                    sequence: m.sequence,
                    log_time_ns: m.log_time_ns,
                    publish_time_ns: m.publish_time_ns,
                    data: &data,
                })
            }
            Ok(Translated::Skipped(_)) => Ok(()),
            Err(e) => {
                self.report.undecodable.add(&info.topic, e.kind(), || {
                    format!("{}: log time {} ns: {e}", info.topic, m.log_time_ns)
                });
                Ok(())
            }
        }
    }

    /// The IMU is drawn for raw logs, or when asked for by topic: in a fused run its 200 Hz
    /// would cost more than every other channel together and say little.
    pub(super) fn imu_shown(&self) -> bool {
        self.pipelines.is_empty() || !self.options.topics.is_empty()
    }

    pub(super) fn imu(&mut self, i: &Imu) -> Result<(), Error> {
        self.layout.imu = true;
        let t = i.stamp_ns as i64;
        let f = self.raw_series(ent::IMU_SPECIFIC_FORCE, &["forward", "left", "up"])?;
        self.columns.push(&self.rec, f, t, &i.specific_force_mps2)?;
        let w = self.raw_series(
            ent::IMU_ANGULAR_RATE,
            &["roll rate", "pitch rate", "yaw rate"],
        )?;
        self.columns.push(&self.rec, w, t, &i.angular_rate_radps)
    }

    pub(super) fn position_sensor(
        &mut self,
        entity: &str,
        name: &str,
        t: u64,
        chainage_m: f64,
    ) -> Result<(), Error> {
        if let Some((s, _)) = self.truth.at(t) {
            self.layout.position_sensors = true;
            self.raw_value(entity, name, t, chainage_m - s)?;
        }
        Ok(())
    }

    pub(super) fn track_map(&mut self, map: TrackMap) -> Result<(), Error> {
        for e in map::log_track_map(&self.rec, &map)? {
            self.entities.insert(e.to_owned());
        }
        self.origin = Some(map.origin.clone());
        self.map = Some(map);
        self.legend.clear();
        Ok(())
    }

    pub(super) fn truth(&mut self, t: &GroundTruth) -> Result<(), Error> {
        self.truth.push(ReferenceSample {
            stamp_ns: t.stamp_ns,
            chainage_m: t.chainage_m,
            speed_mps: t.speed_mps,
        });
        let (sin, cos) = t.heading_rad.sin_cos();
        self.truth_velocity
            .push(t.stamp_ns, (t.speed_mps * sin, t.speed_mps * cos));
        if !self.in_window(t.stamp_ns) {
            return Ok(());
        }
        if !self.layout.truth {
            self.layout.truth = true;
            self.static_(
                ent::TRUTH_TRAIN,
                &Points2D::update_fields()
                    .with_colors([palette::truth()])
                    .with_radii([Radius::new_ui_points(8.0)])
                    .with_labels(["train (truth)"]),
            )?;
            self.static_(
                ent::TRUTH_PATH,
                &Points2D::update_fields()
                    .with_colors([palette::truth()])
                    .with_radii([Radius::new_ui_points(1.0)]),
            )?;
            self.truth_train = Some(self.columns.points(ent::TRUTH_TRAIN, None));
            self.truth_path = Some(self.columns.points(ent::TRUTH_PATH, Some(TRAIL_EVERY_NS)));
        }
        let (p, ts) = (map::plan(t.east_m, t.north_m), t.stamp_ns as i64);
        for id in [self.truth_train, self.truth_path].into_iter().flatten() {
            self.columns.point(&self.rec, id, ts, p)?;
        }
        self.raw_value(ent::SPEED_TRUTH, "truth", t.stamp_ns, t.speed_mps)
    }

    /// A GNSS fix on the map (by fix type) and its speed.
    pub(super) fn gnss(&mut self, g: &GnssFix) -> Result<(), Error> {
        if let (Some(lat), Some(lon)) = (g.latitude_deg, g.longitude_deg) {
            let alt = g.altitude_m.unwrap_or(0.0);
            let origin = self.origin.get_or_insert_with(|| GeodeticOrigin {
                latitude_deg: lat,
                longitude_deg: lon,
                altitude_m: alt,
            });
            let (e, n, _) = origin.to_enu(lat, lon, g.altitude_m.unwrap_or(origin.altitude_m));
            let id = match self.gnss.get(&g.fix_type) {
                Some(&id) => id,
                None => {
                    let entity = ent::gnss_fixes(g.fix_type);
                    self.static_(
                        &entity,
                        &Points2D::update_fields()
                            .with_colors([palette::fix_type(g.fix_type)])
                            .with_radii([Radius::new_ui_points(2.5)]),
                    )?;
                    self.layout.gnss_fixes.push(entity.clone());
                    let id = self.columns.points(&entity, None);
                    self.gnss.insert(g.fix_type, id);
                    id
                }
            };
            self.columns
                .point(&self.rec, id, g.stamp_ns as i64, map::plan(e, n))?;
        }
        if let Some(v) = g.speed_mps {
            self.raw_value(ent::SPEED_GNSS, "GNSS", g.stamp_ns, v)?;
        }
        // Fix quality over time, fix or no fix: what a field engineer checks first.
        self.layout.gnss_quality = true;
        let id = self.raw_series(ent::GNSS_QUALITY, &["satellites", "HDOP"])?;
        let hdop = g.hdop.unwrap_or(f64::NAN);
        if hdop.is_finite() {
            self.columns.push(
                &self.rec,
                id,
                g.stamp_ns as i64,
                &[g.satellites as f64, hdop],
            )?;
        } else {
            let sats = self.raw_series(ent::GNSS_SATELLITES, &["satellites (no HDOP)"])?;
            self.columns
                .push(&self.rec, sats, g.stamp_ns as i64, &[g.satellites as f64])?;
        }
        Ok(())
    }

    pub(super) fn text(&mut self, t_ns: u64, text: String, level: &str) -> Result<(), Error> {
        self.rec
            .set_timestamp_nanos_since_epoch(TIMELINE, t_ns as i64);
        self.rec
            .log(
                ent::EVENTS,
                &TextLog::new(text).with_level(TextLogLevel::from(level)),
            )
            .map_err(|e| Error::Rerun(e.to_string()))?;
        self.entities.insert(ent::EVENTS.to_owned());
        self.report.logged += 1;
        Ok(())
    }

    pub(super) fn event(&mut self, e: &Event) -> Result<(), Error> {
        let level = match e.kind.describe().1 {
            Severity::Info => "INFO",
            Severity::Warning => "WARN",
            Severity::Error => "ERROR",
        };
        self.text(e.stamp_ns, e.line(), level)
    }
}
