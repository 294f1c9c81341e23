//! `railfuse tune`'s evaluations as entities: each candidate's score and values.

use railfuse_catalog::messages::*;
use rerun::components::{AggregationPolicy, InterpolationMode};
use rerun::{SeriesLines, SeriesPoints};

use super::*;
use crate::series::SeriesId;
use crate::{entities as ent, palette, Error};

impl Logger {
    /// One evaluation of a tuning run: its objective and each value as points (a parallel
    /// search enters a batch of evaluations at once), the best so far as a line.
    pub(super) fn tune_evaluation(
        &mut self,
        pipeline: &str,
        e: &TuneEvaluation,
    ) -> Result<(), Error> {
        let t = e.stamp_ns as i64;
        let objective = format!("{}/evaluations", ent::tune_objective(pipeline));
        let id = self.tune_points(&objective, "objective of each evaluation", 0)?;
        self.columns
            .push(&self.rec, id, t, &[e.objective.unwrap_or(f64::NAN)])?;
        let best = format!("{}/best", ent::tune_objective(pipeline));
        let id = match self.raw.get(&best) {
            Some(&id) => id,
            None => {
                // A step: the best holds until an evaluation beats it.
                self.static_(
                    &best,
                    &SeriesLines::new()
                        .with_names(["best so far"])
                        .with_colors([palette::truth()])
                        .with_widths([2.0])
                        .with_interpolation_mode(InterpolationMode::StepAfter)
                        // A batch's evaluations share a pixel: draw its lowest best.
                        .with_aggregation_policy(AggregationPolicy::Min),
                )?;
                let id = self.columns.series(&best, 1);
                self.raw.insert(best.clone(), id);
                id
            }
        };
        self.columns
            .push(&self.rec, id, t, &[e.best.unwrap_or(f64::NAN)])?;
        let k = match self.layout.tune.iter().position(|(p, _)| p == pipeline) {
            Some(k) => k,
            None => {
                self.layout.tune.push((pipeline.to_owned(), Vec::new()));
                self.layout.tune.len() - 1
            }
        };
        for (i, v) in e.values.iter().enumerate() {
            let entity = ent::tune_value(pipeline, i);
            if !self.layout.tune[k].1.iter().any(|(e, _)| *e == entity) {
                self.layout.tune[k].1.push((entity.clone(), v.name.clone()));
            }
            let id = self.tune_points(&entity, &v.name, i + 1)?;
            self.columns.push(&self.rec, id, t, &[v.value])?;
        }
        Ok(())
    }

    pub(super) fn tune_points(
        &mut self,
        entity: &str,
        name: &str,
        colour: usize,
    ) -> Result<SeriesId, Error> {
        if let Some(&id) = self.raw.get(entity) {
            return Ok(id);
        }
        self.static_(
            entity,
            &SeriesPoints::new()
                .with_names([name])
                .with_colors([palette::raw_sensor(colour)])
                .with_marker_sizes([2.0]),
        )?;
        let id = self.columns.series(entity, 1);
        self.raw.insert(entity.to_owned(), id);
        Ok(id)
    }
}
