//! Data logged in columns (`send_columns`, one chunk per few thousand rows rather than one call
//! per row), optionally decimated to what a screen can show.
//!
//! Decimation splits the run into bins. A plotted series keeps, per bin, each component's
//! minimum and maximum in the order they occurred (two rows at the bin's first and last sample
//! time): drawn at screen resolution that min/max envelope looks like the full-rate line, spikes
//! included. A map position keeps the last sample of each bin.

use rerun::{
    LineStrips2D, Points2D, RecordingStream, Scalars, SerializedComponentColumn, TimeColumn,
};

use crate::Error;

/// The timeline every entity is logged on: the MCAP log time.
pub const TIMELINE: &str = "log_time";

/// Rows buffered per entity before they go out as one chunk: bounds memory whatever the run's
/// length.
const CHUNK_ROWS: usize = 4096;

/// How densely series are kept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decimation {
    /// Every sample.
    Full,
    /// Min/max envelopes (plots) and last samples (map) per bin of this many nanoseconds.
    Bins { bin_ns: u64 },
}

impl Decimation {
    fn bin_of(self, t: i64) -> Option<i64> {
        match self {
            Decimation::Full => None,
            Decimation::Bins { bin_ns } => Some(t.div_euclid(bin_ns.max(1) as i64)),
        }
    }
}

/// Index of a series in a [`Columns`] store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeriesId(usize);

/// Index of map points over time in a [`Columns`] store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointsId(usize);

/// Index of map segments over time in a [`Columns`] store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentsId(usize);

/// Index of map outlines (a closed polygon per row: a covariance ellipse) in a [`Columns`] store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutlinesId(usize);

/// Every buffered series and map track of one recording.
pub struct Columns {
    decimation: Decimation,
    series: Vec<Series>,
    points: Vec<Track<[f32; 2]>>,
    segments: Vec<Track<[[f32; 2]; 2]>>,
    outlines: Vec<Track<Vec<[f32; 2]>>>,
    /// Rows handed to Rerun, for the report.
    pub rows_sent: u64,
    /// First and last time of any row.
    span: Option<(i64, i64)>,
}

struct Series {
    entity: String,
    width: usize,
    times: Vec<i64>,
    values: Vec<f64>,
    bin: Option<Envelope>,
    /// A sensor's own series breaks where it fell silent (see [`Silence`]).
    silence: Option<Silence>,
}

/// When a sensor counts as silent: longer than [`Silence::MIN_NS`] and than
/// [`Silence::PERIODS`] of its usual interval without a sample. The line breaks there
/// instead of drawing a straight line across a tunnel or an outage as if it were data.
#[derive(Debug, Clone, Copy, Default)]
struct Silence {
    last_t: Option<i64>,
    /// The usual interval, ns: a running mean of the intervals that were not silences.
    typical_ns: Option<f64>,
}

impl Silence {
    const MIN_NS: f64 = 1e9;
    const PERIODS: f64 = 5.0;

    /// A new sample at `t`: the time just after the last sample when the sensor was silent
    /// since then.
    fn broken_after(&mut self, t: i64) -> Option<i64> {
        let last = self.last_t.replace(t)?;
        let dt = (t - last) as f64;
        if dt <= 0.0 {
            return None;
        }
        let limit = self
            .typical_ns
            .map(|p| (Self::PERIODS * p).max(Self::MIN_NS));
        if limit.is_some_and(|l| dt > l) {
            return Some(last + 1);
        }
        self.typical_ns = Some(self.typical_ns.map_or(dt, |p| 0.9 * p + 0.1 * dt));
        None
    }
}

/// One bin's extremes per component, with when they happened.
struct Envelope {
    index: i64,
    first_t: i64,
    last_t: i64,
    samples: u32,
    lo: Vec<(f64, i64)>,
    hi: Vec<(f64, i64)>,
}

impl Envelope {
    fn new(index: i64, t: i64, row: &[f64]) -> Self {
        let ext: Vec<_> = row.iter().map(|&v| (v, t)).collect();
        Envelope {
            index,
            first_t: t,
            last_t: t,
            samples: 1,
            lo: ext.clone(),
            hi: ext,
        }
    }

    fn add(&mut self, t: i64, row: &[f64]) {
        self.last_t = t;
        self.samples += 1;
        for (i, &v) in row.iter().enumerate() {
            if v < self.lo[i].0 {
                self.lo[i] = (v, t);
            }
            if v > self.hi[i].0 {
                self.hi[i] = (v, t);
            }
        }
    }

    /// The bin as rows: its only sample, or per component the extreme that came first at the
    /// bin's first time and the other at its last.
    fn rows(&self, times: &mut Vec<i64>, values: &mut Vec<f64>) {
        if self.samples == 1 || self.first_t == self.last_t {
            times.push(self.first_t);
            values.extend(self.lo.iter().map(|e| e.0));
            return;
        }
        let (first, second): (Vec<f64>, Vec<f64>) = self
            .lo
            .iter()
            .zip(&self.hi)
            .map(|(lo, hi)| {
                if lo.1 <= hi.1 {
                    (lo.0, hi.0)
                } else {
                    (hi.0, lo.0)
                }
            })
            .unzip();
        times.push(self.first_t);
        values.extend(first);
        times.push(self.last_t);
        values.extend(second);
    }
}

/// Positions of one map entity over time; decimated to the last one per bin.
struct Track<T> {
    entity: String,
    times: Vec<i64>,
    rows: Vec<T>,
    /// Own interval, for a trail that keeps fewer samples than the plots: the first sample of
    /// each interval is kept.
    every_ns: Option<u64>,
    last_bin: Option<i64>,
}

impl<T> Track<T> {
    fn new(entity: &str, every_ns: Option<u64>) -> Self {
        Track {
            entity: entity.to_owned(),
            times: Vec::new(),
            rows: Vec::new(),
            every_ns,
            last_bin: None,
        }
    }

    /// Adds a row; true when the buffer is full.
    fn place(&mut self, decimation: Decimation, t: i64, row: T) -> bool {
        let bin = match self.every_ns {
            Some(every) => Decimation::Bins { bin_ns: every }.bin_of(t),
            None => decimation.bin_of(t),
        };
        if bin.is_some() && bin == self.last_bin {
            if self.every_ns.is_some() {
                return false;
            }
            // The last sample of a bin wins.
            self.times.pop();
            self.rows.pop();
        }
        self.last_bin = bin;
        self.times.push(t);
        self.rows.push(row);
        self.times.len() >= CHUNK_ROWS
    }
}

/// What a map row is drawn as.
trait MapRow: Sized {
    fn columns(rows: Vec<Self>) -> rerun::SerializationResult<Vec<SerializedComponentColumn>>;
}

impl MapRow for [f32; 2] {
    fn columns(rows: Vec<Self>) -> rerun::SerializationResult<Vec<SerializedComponentColumn>> {
        Ok(Points2D::update_fields()
            .with_positions(rows)
            .columns_of_unit_batches()?
            .collect())
    }
}

impl MapRow for [[f32; 2]; 2] {
    fn columns(rows: Vec<Self>) -> rerun::SerializationResult<Vec<SerializedComponentColumn>> {
        Ok(LineStrips2D::update_fields()
            .with_strips(rows.into_iter().map(|s| s.to_vec()))
            .columns_of_unit_batches()?
            .collect())
    }
}

impl MapRow for Vec<[f32; 2]> {
    fn columns(rows: Vec<Self>) -> rerun::SerializationResult<Vec<SerializedComponentColumn>> {
        Ok(LineStrips2D::update_fields()
            .with_strips(rows)
            .columns_of_unit_batches()?
            .collect())
    }
}

fn send_track<T: MapRow>(rec: &RecordingStream, tr: &mut Track<T>) -> Result<u64, Error> {
    let n = tr.times.len();
    if n == 0 {
        return Ok(0);
    }
    let times = TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE, tr.times.drain(..));
    let columns = T::columns(std::mem::take(&mut tr.rows)).map_err(rerun_error)?;
    rec.send_columns(tr.entity.as_str(), [times], columns)
        .map_err(rerun_error)?;
    Ok(n as u64)
}

impl Columns {
    pub fn new(decimation: Decimation) -> Self {
        Columns {
            decimation,
            series: Vec::new(),
            points: Vec::new(),
            segments: Vec::new(),
            outlines: Vec::new(),
            rows_sent: 0,
            span: None,
        }
    }

    pub fn decimation(&self) -> Decimation {
        self.decimation
    }

    /// First and last log time of everything pushed so far.
    pub fn span(&self) -> Option<(i64, i64)> {
        self.span
    }

    fn saw(&mut self, t: i64) {
        self.span = Some(self.span.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
    }

    /// Registers a series of `width` scalars per row (a value and its bounds, β per device).
    pub fn series(&mut self, entity: &str, width: usize) -> SeriesId {
        self.series.push(Series {
            entity: entity.to_owned(),
            width,
            times: Vec::new(),
            values: Vec::new(),
            bin: None,
            silence: None,
        });
        SeriesId(self.series.len() - 1)
    }

    /// Makes a series break where its sensor fell silent (a receiver in a tunnel, a radar
    /// without echo at standstill): a `Clear` just after the last sample before the silence,
    /// which Rerun's plots draw as a gap.
    pub fn break_on_silence(&mut self, id: SeriesId) {
        self.series[id.0].silence = Some(Silence::default());
    }

    /// Registers map points over time; `every_ns` keeps at most one per that interval.
    pub fn points(&mut self, entity: &str, every_ns: Option<u64>) -> PointsId {
        self.points.push(Track::new(entity, every_ns));
        PointsId(self.points.len() - 1)
    }

    /// Registers map segments (one two-point line per row) over time.
    pub fn segments(&mut self, entity: &str) -> SegmentsId {
        self.segments.push(Track::new(entity, None));
        SegmentsId(self.segments.len() - 1)
    }

    /// One row of a series at log time `t` (ns). Rows with a non-finite value are skipped: a
    /// plot has nothing to draw for them.
    pub fn push(
        &mut self,
        rec: &RecordingStream,
        id: SeriesId,
        t: i64,
        row: &[f64],
    ) -> Result<(), Error> {
        if !row.iter().all(|v| v.is_finite()) {
            return Ok(());
        }
        self.saw(t);
        let bin = self.decimation.bin_of(t);
        let s = &mut self.series[id.0];
        debug_assert_eq!(row.len(), s.width, "{}", s.entity);
        if let Some(gap) = s.silence.as_mut().and_then(|g| g.broken_after(t)) {
            // The rows before the silence go out first, then the break.
            if let Some(env) = s.bin.take() {
                env.rows(&mut s.times, &mut s.values);
            }
            self.rows_sent += send_series(rec, s)?;
            rec.set_timestamp_nanos_since_epoch(TIMELINE, gap);
            rec.log(s.entity.as_str(), &rerun::Clear::flat())
                .map_err(rerun_error)?;
        }
        match (bin, &mut s.bin) {
            (None, _) => {
                s.times.push(t);
                s.values.extend_from_slice(row);
            }
            (Some(b), Some(env)) if env.index == b => env.add(t, row),
            (Some(b), open) => {
                if let Some(done) = open.replace(Envelope::new(b, t, row)) {
                    done.rows(&mut s.times, &mut s.values);
                }
            }
        }
        if s.times.len() >= CHUNK_ROWS {
            self.rows_sent += send_series(rec, s)?;
        }
        Ok(())
    }

    /// A point on the map at log time `t`.
    pub fn point(
        &mut self,
        rec: &RecordingStream,
        id: PointsId,
        t: i64,
        p: [f32; 2],
    ) -> Result<(), Error> {
        self.saw(t);
        let tr = &mut self.points[id.0];
        if tr.place(self.decimation, t, p) {
            self.rows_sent += send_track(rec, tr)?;
        }
        Ok(())
    }

    /// Registers map outlines over time.
    pub fn outlines(&mut self, entity: &str) -> OutlinesId {
        self.outlines.push(Track::new(entity, None));
        OutlinesId(self.outlines.len() - 1)
    }

    /// An outline on the map at log time `t`.
    pub fn outline(
        &mut self,
        rec: &RecordingStream,
        id: OutlinesId,
        t: i64,
        o: Vec<[f32; 2]>,
    ) -> Result<(), Error> {
        self.saw(t);
        let tr = &mut self.outlines[id.0];
        if tr.place(self.decimation, t, o) {
            self.rows_sent += send_track(rec, tr)?;
        }
        Ok(())
    }

    /// A segment on the map at log time `t`.
    pub fn segment(
        &mut self,
        rec: &RecordingStream,
        id: SegmentsId,
        t: i64,
        s: [[f32; 2]; 2],
    ) -> Result<(), Error> {
        self.saw(t);
        let tr = &mut self.segments[id.0];
        if tr.place(self.decimation, t, s) {
            self.rows_sent += send_track(rec, tr)?;
        }
        Ok(())
    }

    /// Sends everything still buffered (open bins included).
    pub fn flush(&mut self, rec: &RecordingStream) -> Result<(), Error> {
        for s in &mut self.series {
            if let Some(env) = s.bin.take() {
                env.rows(&mut s.times, &mut s.values);
            }
            self.rows_sent += send_series(rec, s)?;
        }
        for tr in &mut self.points {
            self.rows_sent += send_track(rec, tr)?;
        }
        for tr in &mut self.segments {
            self.rows_sent += send_track(rec, tr)?;
        }
        for tr in &mut self.outlines {
            self.rows_sent += send_track(rec, tr)?;
        }
        Ok(())
    }
}

fn rerun_error(e: impl std::fmt::Display) -> Error {
    Error::Rerun(e.to_string())
}

fn send_series(rec: &RecordingStream, s: &mut Series) -> Result<u64, Error> {
    let rows = s.times.len();
    if rows == 0 {
        return Ok(0);
    }
    let times = TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE, s.times.drain(..));
    let columns = Scalars::new(s.values.drain(..))
        .columns(std::iter::repeat_n(s.width, rows))
        .map_err(rerun_error)?;
    rec.send_columns(s.entity.as_str(), [times], columns)
        .map_err(rerun_error)?;
    Ok(rows as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 Hz hour with one spike: (times, values).
    fn hour_with_spike() -> impl Iterator<Item = (i64, f64)> {
        (0..360_000i64).map(|i| {
            let v = if i == 123_457 {
                50.0
            } else {
                (i as f64 * 0.01).sin()
            };
            (i * 10_000_000, v)
        })
    }

    #[test]
    fn a_bin_keeps_each_components_extremes_in_the_order_they_came() {
        let mut env = Envelope::new(0, 0, &[1.0, 0.0]);
        env.add(10, &[-2.0, 5.0]);
        env.add(20, &[3.0, -1.0]);
        env.add(30, &[0.5, 0.5]);
        let (mut t, mut v) = (Vec::new(), Vec::new());
        env.rows(&mut t, &mut v);
        assert_eq!(t, [0, 30]);
        // Component 0: min −2 (t 10) before max 3 (t 20); component 1: max 5 before min −1.
        assert_eq!(v, [-2.0, 5.0, 3.0, -1.0]);
    }

    #[test]
    fn decimation_bounds_the_rows_and_keeps_a_single_sample_spike() {
        let rec = RecordingStream::disabled();
        let bin_ns = 3_600_000_000_000u64.div_ceil(4096);
        let mut decimated = Columns::new(Decimation::Bins { bin_ns });
        let mut full = Columns::new(Decimation::Full);
        let (a, b) = (decimated.series("x", 1), full.series("x", 1));
        let mut kept_spike = false;
        for (t, v) in hour_with_spike() {
            decimated.push(&rec, a, t, &[v]).unwrap();
            full.push(&rec, b, t, &[v]).unwrap();
            let s = &decimated.series[a.0];
            kept_spike |=
                s.values.contains(&50.0) || s.bin.as_ref().is_some_and(|e| e.hi[0].0 == 50.0);
        }
        decimated.flush(&rec).unwrap();
        full.flush(&rec).unwrap();
        assert_eq!(full.rows_sent, 360_000);
        assert!(decimated.rows_sent <= 2 * 4097, "{}", decimated.rows_sent);
        assert!(kept_spike, "the spike was averaged away");
        assert_eq!(decimated.span(), Some((0, 359_999 * 10_000_000)));
    }

    #[test]
    fn non_finite_rows_never_reach_a_plot() {
        let rec = RecordingStream::disabled();
        let mut c = Columns::new(Decimation::Full);
        let id = c.series("x", 3);
        c.push(&rec, id, 0, &[1.0, f64::NAN, 0.0]).unwrap();
        c.push(&rec, id, 1, &[1.0, f64::INFINITY, 0.0]).unwrap();
        c.push(&rec, id, 2, &[1.0, 2.0, 0.0]).unwrap();
        c.flush(&rec).unwrap();
        assert_eq!(c.rows_sent, 1);
    }

    #[test]
    fn a_silent_sensor_breaks_its_line_once_per_silence() {
        let mut g = Silence::default();
        let s = 1_000_000_000i64;
        // 10 Hz for 10 s, silent for 150 s, 10 Hz again; then a 0.4 s hiccup (no break).
        let mut times: Vec<i64> = (0..100).map(|k| k * s / 10).collect();
        times.extend((0..100).map(|k| 160 * s + k * s / 10));
        times.push(times.last().unwrap() + 4 * s / 10);
        let breaks: Vec<i64> = times.iter().filter_map(|&t| g.broken_after(t)).collect();
        assert_eq!(breaks, [99 * s / 10 + 1]);
    }

    #[test]
    fn a_map_track_keeps_the_last_sample_of_a_bin_and_a_trail_the_first() {
        let rec = RecordingStream::disabled();
        let mut c = Columns::new(Decimation::Bins { bin_ns: 100 });
        let (last, trail) = (c.points("p", None), c.points("t", Some(100)));
        for t in [0, 50, 99, 100, 150] {
            c.point(&rec, last, t, [t as f32, 0.0]).unwrap();
            c.point(&rec, trail, t, [t as f32, 0.0]).unwrap();
        }
        assert_eq!(c.points[last.0].times, [99, 150]);
        assert_eq!(c.points[trail.0].times, [0, 100]);
    }
}
