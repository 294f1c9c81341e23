//! The train-run simulator: truth, sensors and the writing of a simulated run as a railfuse
//! log. Deterministic for a seed: the same scenario, seed and duration give the same file.

pub mod atlas;
pub mod can_bus;
mod driver;
pub mod faults;
pub mod kinematics;
mod recorders;
pub mod ride;
mod scenario;
pub mod seed000;
pub mod sensors;
pub mod site;
mod track;
mod vehicle;
mod world;

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_catalog::foreign::can::frames_topic;
use railfuse_catalog::geodesy::GeodeticOrigin;
use railfuse_catalog::log::{ChannelId, LogWriter};
use railfuse_catalog::messages::StampClock;
use railfuse_catalog::messages::*;
use railfuse_catalog::topics;

pub use driver::DriverParams;
pub use faults::{FaultMode, FaultSpec};
pub use recorders::{SimRecorder, MAX_RECORDERS};
pub use ride::RideParams;
pub use scenario::{LineScenario, Scenario, SIMULATED_START_NS};
pub use track::{GradientSection, Segment, TrackParams, VerticalParams};
pub use vehicle::VehicleParams;

use driver::{Driver, DriverEvent, Phase};
use faults::FaultInjector;
use recorders::SimClock;
use ride::{Ride, RideSample};
use sensors::{
    balise::BaliseReader, eddy_current::EddyCurrentSensor, gnss::Gnss, imu::ImuSensor,
    induction_loop::InductionLoop, odometer::OdometerSensor, radar::Radar, rng_stream,
};
use track::Track;
use world::{seconds, Emit, Outbox, Schedule, SimSensor, World};

/// What a simulation wrote.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SimulationReport {
    pub scenario: String,
    pub seed: u64,
    pub duration_s: f64,
    pub messages: u64,
    pub per_topic: BTreeMap<String, u64>,
    pub track_length_m: f64,
    /// The recorders' files, for a run written by several.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<String>,
}

/// One file of a simulated run: its writer and, for a run of several recorders, the
/// recorder's clock and the jitter of its PPS readings.
struct RecorderLog {
    writer: LogWriter,
    recorder: Option<(SimRecorder, SimClock, rand_chacha::ChaCha8Rng)>,
}

/// The channels of a simulated log and the writers behind them.
struct SimLog {
    logs: Vec<RecorderLog>,
    /// Topic → (which log, its channel there).
    channels: BTreeMap<String, (usize, ChannelId)>,
    report: SimulationReport,
    faults: FaultInjector,
    fault_specs: Vec<FaultSpec>,
    fault_events: Vec<Event>,
    /// The odometers and radar on the vehicle's CAN bus, where the scenario puts them there.
    can: Option<can_bus::CanBus>,
    frames: Vec<railfuse_can::frame::Frame>,
    /// The train as installed (JSON), for the run's metadata: the truth a calibration is
    /// checked against.
    installed: Option<String>,
}

impl SimLog {
    /// One log at `path`, or with `recorders` one per recorder in the folder `path`.
    fn create(
        path: &Path,
        recorders: &[SimRecorder],
        scenario: &Scenario,
        seed: u64,
        faults: &[FaultSpec],
    ) -> railfuse_catalog::Result<Self> {
        let mut logs = Vec::new();
        if recorders.is_empty() {
            logs.push(RecorderLog {
                writer: LogWriter::create(path)?,
                recorder: None,
            });
        }
        for (i, r) in recorders.iter().enumerate() {
            logs.push(RecorderLog {
                writer: LogWriter::create(path.join(format!("{}.mcap", r.name)))?,
                recorder: Some((
                    r.clone(),
                    r.clock(SIMULATED_START_NS),
                    recorders::pps_jitter(seed, i),
                )),
            });
        }
        let channels = Self::channels(&mut logs, recorders, scenario)?;
        let report = SimulationReport {
            scenario: scenario.name().into(),
            seed,
            ..Default::default()
        };
        let faults = FaultInjector::new(faults, SIMULATED_START_NS);
        let can = scenario
            .line()
            .filter(|p| p.can_bus)
            .map(|p| can_bus::CanBus::new(p.odometers.len()));
        Ok(Self {
            logs,
            channels,
            report,
            faults,
            fault_specs: Vec::new(),
            fault_events: Vec::new(),
            can,
            frames: Vec::new(),
            installed: None,
        })
    }

    /// Every channel of the scenario, each in the log of the recorder that logs it, and
    /// each recorder's time reference.
    fn channels(
        logs: &mut [RecorderLog],
        recorders: &[SimRecorder],
        scenario: &Scenario,
    ) -> railfuse_catalog::Result<BTreeMap<String, (usize, ChannelId)>> {
        let n = recorders.len();
        let mut channels = BTreeMap::new();
        macro_rules! channel {
            ($ty:ty, $topic:expr) => {{
                let log = recorders::recorder_of($topic, n);
                let id = logs[log].writer.add_channel::<$ty>($topic)?;
                channels.insert($topic.to_string(), (log, id));
            }};
        }
        channel!(TrackMap, topics::TRACK_MAP);
        if scenario.line().is_some_and(|p| p.vehicle.is_some()) {
            channel!(Vehicle, topics::VEHICLE);
        }
        channel!(GroundTruth, topics::GROUND_TRUTH);
        channel!(Event, topics::EVENTS);
        match scenario.line() {
            None => {
                channel!(LoopPosition, topics::LOOP_POSITION);
                channel!(RadarSpeed, topics::RADAR_SPEED);
                channel!(BalisePassage, topics::BALISE);
            }
            Some(p) => {
                if p.induction_loop.is_some() {
                    channel!(LoopPosition, topics::LOOP_POSITION);
                }
                if p.can_bus {
                    // On the odometry rack, which has the bus's interface.
                    let topic = frames_topic(can_bus::BUS);
                    let log = recorders::recorder_of(topics::ODOMETER_1, n);
                    let id = logs[log].writer.add_channel::<CanFrame>(&topic)?;
                    channels.insert(topic, (log, id));
                } else {
                    channel!(RadarSpeed, topics::RADAR_SPEED);
                }
                if p.balise.is_some() {
                    channel!(BalisePassage, topics::BALISE);
                }
                if p.eddy_current.is_some() {
                    channel!(EddyCurrentBlock, topics::EDDY_CURRENT);
                }
                channel!(GnssFix, topics::GNSS_FIX);
                channel!(Imu, topics::IMU);
                for topic in [topics::ODOMETER_1, topics::ODOMETER_2]
                    .into_iter()
                    .take(p.odometers.len())
                    .filter(|_| !p.can_bus)
                {
                    channel!(Odometer, topic);
                }
            }
        }
        for (i, r) in recorders.iter().enumerate() {
            let topic = topics::time_reference(&r.name);
            let id = logs[i].writer.add_channel::<TimeReference>(&topic)?;
            channels.insert(topic, (i, id));
        }
        Ok(channels)
    }

    /// Writes `msg` into its recorder's log: on that recorder's clock, its log time and
    /// (where the recorder stamped it) its stamp.
    fn write<M: ChannelMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &M,
    ) -> railfuse_catalog::Result<()> {
        let (log, channel) = self.channels[topic];
        let log = &mut self.logs[log];
        match &log.recorder {
            None => log.writer.write(channel, log_time_ns, msg)?,
            Some((_, clock, _)) => {
                let mut local = msg.clone();
                if M::KIND.stamp_clock() == StampClock::Recorder {
                    let stamp = local.stamp_ns_mut();
                    *stamp = clock.local(*stamp);
                }
                log.writer
                    .write(channel, clock.local(log_time_ns), &local)?;
            }
        }
        self.report.messages += 1;
        *self.report.per_topic.entry(topic.to_owned()).or_insert(0) += 1;
        Ok(())
    }

    fn write_emit(&mut self, log_time_ns: u64, emit: Emit) -> railfuse_catalog::Result<()> {
        let emit = self.faults.apply(log_time_ns, emit, &mut self.fault_events);
        for e in std::mem::take(&mut self.fault_events) {
            self.write(topics::EVENTS, log_time_ns, &e)?;
        }
        let Some(emit) = emit else { return Ok(()) };
        if let Some(bus) = &mut self.can {
            match &emit {
                Emit::Radar(m) => self.frames.push(bus.radar(m, log_time_ns)),
                Emit::Odometer(i, m) => bus.odometer(*i, m, log_time_ns, &mut self.frames),
                _ => {}
            }
            if matches!(emit, Emit::Radar(_) | Emit::Odometer(..)) {
                return self.write_frames();
            }
        }
        match emit {
            Emit::Gnss(m) => self.write(topics::GNSS_FIX, log_time_ns, &m),
            Emit::Imu(m) => self.write(topics::IMU, log_time_ns, &m),
            Emit::Radar(m) => self.write(topics::RADAR_SPEED, log_time_ns, &m),
            Emit::Odometer(0, m) => self.write(topics::ODOMETER_1, log_time_ns, &m),
            Emit::Odometer(_, m) => self.write(topics::ODOMETER_2, log_time_ns, &m),
            Emit::Loop(m) => self.write(topics::LOOP_POSITION, log_time_ns, &m),
            Emit::Balise(m) => self.write(topics::BALISE, log_time_ns, &m),
            Emit::EddyCurrent(m) => self.write(topics::EDDY_CURRENT, log_time_ns, &m),
            Emit::Truth(m) => self.write(topics::GROUND_TRUTH, log_time_ns, &m),
            Emit::Event(m) => self.write(topics::EVENTS, log_time_ns, &m),
            Emit::TimeReference(i, mut m) => {
                let Some((r, clock, jitter)) = &mut self.logs[i].recorder else {
                    return Ok(());
                };
                // The edge read on the recorder's clock; its log time is moved by `write`.
                m.local_ns = recorders::read_pps(clock, m.local_ns, jitter);
                let topic = topics::time_reference(&r.name);
                self.write(&topic, log_time_ns, &m)
            }
        }
    }

    /// The CAN frames gathered, each at its bus time on the bus's recorder's clock.
    fn write_frames(&mut self) -> railfuse_catalog::Result<()> {
        let topic = frames_topic(can_bus::BUS);
        let (log, channel) = self.channels[&topic];
        let log = &mut self.logs[log];
        for mut frame in self.frames.drain(..) {
            if let Some((_, clock, _)) = &log.recorder {
                frame.stamp_ns = clock.local(frame.stamp_ns);
            }
            let m = CanFrame::from_frame(&frame, frame.stamp_ns);
            log.writer.write(channel, frame.stamp_ns, &m)?;
            self.report.messages += 1;
            *self.report.per_topic.entry(topic.clone()).or_insert(0) += 1;
        }
        Ok(())
    }

    fn finish(
        mut self,
        scenario: &Scenario,
        track: &TrackMap,
        duration_s: f64,
    ) -> railfuse_catalog::Result<SimulationReport> {
        let train = match scenario {
            Scenario::Default(p)
            | Scenario::Seed001(p)
            | Scenario::Seed002(p)
            | Scenario::Seed003(p)
            | Scenario::Seed004(p)
            | Scenario::Flat(p)
            | Scenario::Seed003In3d(p)
            | Scenario::Seed003In3dFlat(p) => p.train.clone(),
            Scenario::Seed000(_) => "maglev (source 000 simulation)".into(),
            Scenario::Seed000LoopDrift(_) => {
                "maglev (source 000 simulation, loop error growing with distance)".into()
            }
        };
        let run = BTreeMap::from([
            (
                "run_id".into(),
                format!("sim-{}-seed{}", scenario.name(), self.report.seed),
            ),
            ("train".into(), train),
            ("route".into(), track.name.clone()),
            ("scenario".into(), scenario.name().into()),
            ("seed".into(), self.report.seed.to_string()),
            ("duration_s".into(), format!("{duration_s:.3}")),
            ("start_time_ns".into(), SIMULATED_START_NS.to_string()),
            (
                "scenario_parameters".into(),
                serde_json::to_string(scenario).expect("parameters serialise"),
            ),
            (
                "faults".into(),
                serde_json::to_string(&self.fault_specs).expect("faults serialise"),
            ),
            ("tool_version".into(), crate::TOOL_VERSION.into()),
            ("source".into(), "simulated".into()),
        ]);
        let mut run = run;
        if let Some(installed) = &self.installed {
            run.insert("vehicle_installed".into(), installed.clone());
        }
        for log in self.logs {
            let mut run = run.clone();
            if let Some((r, clock, _)) = &log.recorder {
                // The simulator's truth about the recorder's clock, to check an estimate by.
                let truth = clock.as_clock_map();
                run.insert("recorder".into(), r.name.clone());
                run.insert(
                    "recorder_clock_offset_ns".into(),
                    truth.offset_ns.to_string(),
                );
                run.insert(
                    "recorder_clock_drift_ppm".into(),
                    truth.drift_ppm.to_string(),
                );
                run.insert(
                    "recorder_clock_origin_ns".into(),
                    truth.origin_ns.to_string(),
                );
                self.report
                    .files
                    .push(log.writer.path().display().to_string());
            }
            let mut writer = log.writer;
            writer.write_metadata(topics::metadata::RUN, run)?;
            writer.finish()?;
        }
        self.report.duration_s = duration_s;
        self.report.track_length_m = track.length_m();
        Ok(self.report)
    }
}

/// Simulates a run and writes it to `out`. `duration_s` cuts the run short or, for the line
/// scenario, makes the route long enough (more stations) to fill it.
///
/// `faults` make devices fail for windows of the run (line scenarios only: source 000's
/// simulation has no device models to break; the caller checks).
pub fn simulate(
    scenario: &Scenario,
    seed: u64,
    duration_s: Option<f64>,
    faults: &[FaultSpec],
    out: &Path,
) -> railfuse_catalog::Result<SimulationReport> {
    match scenario {
        Scenario::Default(p)
        | Scenario::Seed001(p)
        | Scenario::Seed002(p)
        | Scenario::Seed003(p)
        | Scenario::Seed004(p)
        | Scenario::Flat(p)
        | Scenario::Seed003In3d(p)
        | Scenario::Seed003In3dFlat(p) => {
            simulate_line(scenario, p, seed, duration_s, faults, &[], out)
        }
        Scenario::Seed000(p) | Scenario::Seed000LoopDrift(p) => {
            seed000::simulate(scenario, p, seed, duration_s, out)
        }
    }
}

/// Simulates a run as the recorders on a train write it: one file per recorder in the
/// folder `dir` (`<name>.mcap`), each on its own clock with its PPS time reference (see
/// [`SimRecorder`]). The same seed gives the same sensor readings as [`simulate`].
pub fn simulate_recorders(
    scenario: &Scenario,
    seed: u64,
    duration_s: Option<f64>,
    faults: &[FaultSpec],
    recorders: &[SimRecorder],
    dir: &Path,
) -> railfuse_catalog::Result<SimulationReport> {
    let fail = |cause: &str| railfuse_catalog::Error::Run {
        path: dir.to_owned(),
        cause: cause.to_owned(),
    };
    let Some(p) = scenario.line() else {
        return Err(fail(
            "several recorders are simulated on the line scenarios only",
        ));
    };
    if recorders.is_empty() || recorders.len() > MAX_RECORDERS {
        return Err(fail("give one to three recorders"));
    }
    for (i, r) in recorders.iter().enumerate() {
        if recorders[..i].iter().any(|o| o.name == r.name) {
            return Err(fail(&format!("recorder '{}' named twice", r.name)));
        }
    }
    std::fs::create_dir_all(dir).map_err(|source| railfuse_catalog::Error::Io {
        path: dir.to_owned(),
        source,
    })?;
    simulate_line(scenario, p, seed, duration_s, faults, recorders, dir)
}

fn simulate_line(
    scenario: &Scenario,
    p: &LineScenario,
    seed: u64,
    duration_s: Option<f64>,
    faults: &[FaultSpec],
    recorders: &[SimRecorder],
    out: &Path,
) -> railfuse_catalog::Result<SimulationReport> {
    let start = SIMULATED_START_NS;
    // About 260 s per 5.7 km leg with its dwell: add stations until the duration is covered.
    let stations = match duration_s {
        Some(d) => p.stations.max((d / 200.0).ceil() as usize + 2),
        None => p.stations,
    };
    let with_link_faults = correction_link_faults(p, faults);
    let p = &with_link_faults;
    let mut track = Track::build(&p.track, stations, start, &mut rng_stream(seed, 0));
    if let Some(a) = &p.atlas {
        track.map = atlas::with_atlas(track.map, a, &mut rng_stream(seed, 30));
    }
    let map = &track.map;
    let mut log = SimLog::create(out, recorders, scenario, seed, faults)?;
    log.fault_specs = faults.to_vec();
    let published = published_map(p, map, faults, seed);
    log.write(topics::TRACK_MAP, start, published.as_ref().unwrap_or(map))?;
    let installed = publish_vehicle(p, &mut log, start, seed)?;
    let mut ride = p.ride.clone().map(|r| Ride::new(r, rng_stream(seed, 40)));
    let mut driver = Driver::new(
        p.driver.clone(),
        map.stations.iter().map(|s| s.chainage_m).collect(),
    );
    let mut sensors = line_sensors(p, map, &installed, seed, start);
    sensors.extend((0..recorders.len()).map(|i| recorders::pps(i, start)));
    let mut surroundings = Surroundings::new(p, map);
    let mut truth_schedule = Schedule::new(start, p.truth_rate_hz);
    let mut outbox = Outbox::default();
    let step_ns: u64 = 1_000_000;
    let dt = step_ns as f64 / 1e9;
    let limit_ns = duration_s.map(|d| start + seconds(d));
    let mut t_ns = start;
    // Each pass measures the world as it is at `t_ns`, then moves the train on to the next
    // step: every stamp is the time of the state it was taken from.
    loop {
        let t = (t_ns - start) as f64 / 1e9;
        let ride = ride
            .as_mut()
            .map_or_else(RideSample::default, |r| r.step(driver.v, dt));
        let moving = Moving {
            track: &track,
            vehicle: &installed,
            driver: &driver,
            ride,
        };
        let world = surroundings.world(moving, t_ns, t, dt, &mut outbox);
        for s in &mut sensors {
            s.step(&world, &mut outbox);
        }
        if truth_schedule.due(t_ns) {
            outbox.push(t_ns, Emit::Truth(truth(&world, &map.origin)));
        }
        while let Some((log_time, emit)) = outbox.pop_due(t_ns) {
            log.write_emit(log_time, emit)?;
        }
        let finished = driver.phase == Phase::Finished;
        if finished || limit_ns.is_some_and(|l| t_ns >= l) {
            break;
        }
        t_ns += step_ns;
        drive(&mut driver, map, t, dt, t_ns, &mut outbox);
    }
    while let Some((log_time, emit)) = outbox.pop_due(u64::MAX) {
        log.write_emit(log_time, emit)?;
    }
    if let Some(bus) = &mut log.can {
        bus.flush(t_ns, &mut log.frames);
        log.write_frames()?;
    }
    log.finish(scenario, map, (t_ns - start) as f64 / 1e9)
}

/// Moves the train on by one step, to `next_ns`, with an event for a station it arrives at or
/// leaves.
fn drive(driver: &mut Driver, map: &TrackMap, t: f64, dt: f64, next_ns: u64, outbox: &mut Outbox) {
    let stop = match driver.step(t, dt) {
        Some(DriverEvent::Arrived(i)) => Some((EventKind::StationArrival, i)),
        Some(DriverEvent::Departed(i)) => Some((EventKind::StationDeparture, i)),
        None => None,
    };
    if let Some((kind, i)) = stop {
        let text = map.stations[i].name.clone();
        outbox.push(next_ns, event(next_ns, kind, text));
    }
}

/// The train as installed, its drawing written on `/vehicle` and the installed truth kept for
/// the run's metadata; a point train where the scenario has no vehicle.
fn publish_vehicle(
    p: &LineScenario,
    log: &mut SimLog,
    start: u64,
    seed: u64,
) -> railfuse_catalog::Result<Vehicle> {
    let Some(v) = &p.vehicle else {
        return Ok(Vehicle::point());
    };
    let drawing = Vehicle {
        stamp_ns: start,
        ..v.drawing.clone()
    };
    log.write(topics::VEHICLE, start, &drawing)?;
    let installed = v.installed(&mut rng_stream(seed, 41));
    log.installed = Some(serde_json::to_string(&installed).expect("a vehicle serialises"));
    Ok(installed)
}

/// The scenario with each `corrections:dropout` fault's window among its correction-link
/// outages.
fn correction_link_faults(p: &LineScenario, faults: &[FaultSpec]) -> LineScenario {
    let mut p = p.clone();
    p.correction_outages_s.extend(
        faults
            .iter()
            .filter(|f| f.device == "corrections")
            .map(|f| (f.start_s, f.end_s - f.start_s)),
    );
    p
}

fn event(stamp_ns: u64, kind: EventKind, text: String) -> Emit {
    Emit::Event(Event {
        stamp_ns,
        kind,
        text,
    })
}

/// The map the log publishes: the true one, or as a site's surveyors drew it, with any
/// stretch a `map:offset` fault shifts. `None`: the true one.
fn published_map(
    p: &LineScenario,
    map: &TrackMap,
    faults: &[FaultSpec],
    seed: u64,
) -> Option<TrackMap> {
    let mut published = p
        .site
        .as_ref()
        .map(|site| site.surveyed(map, &mut rng_stream(seed, 20)));
    let offsets = map_offsets(p, map, faults);
    if !offsets.is_empty() {
        let base = published.as_ref().unwrap_or(map);
        published = Some(site::with_offsets(base, &offsets, 10.0));
    }
    published
}

/// Every sensor the line scenario has, each with its own random stream, each where the
/// installed train has it.
fn line_sensors(
    p: &LineScenario,
    map: &TrackMap,
    installed: &Vehicle,
    seed: u64,
    start: u64,
) -> Vec<Box<dyn SimSensor>> {
    let along = |topic: &str| installed.mount_or_front(topic).lever_arm_m[0];
    let mut sensors: Vec<Box<dyn SimSensor>> = vec![
        Box::new(Gnss::new(
            p.gnss.clone(),
            installed.mount_or_front(topics::GNSS_FIX),
            map.origin,
            start,
            rng_stream(seed, 1),
        )),
        Box::new(ImuSensor::new(
            p.imu.clone(),
            installed.mount_or_front(topics::IMU),
            start,
            rng_stream(seed, 2),
        )),
        Box::new(Radar::new(
            p.radar.clone(),
            along(topics::RADAR_SPEED),
            start,
            rng_stream(seed, 3),
        )),
    ];
    if let Some(l) = &p.induction_loop {
        sensors.push(Box::new(InductionLoop::new(
            l.clone(),
            along(topics::LOOP_POSITION),
            rng_stream(seed, 4),
        )));
    }
    if let Some(b) = &p.balise {
        sensors.push(Box::new(BaliseReader::new(
            b.clone(),
            along(topics::BALISE),
            map.balises.clone(),
            rng_stream(seed, 5),
        )));
    }
    if let Some(e) = &p.eddy_current {
        sensors.push(Box::new(EddyCurrentSensor::new(
            e.clone(),
            along(topics::EDDY_CURRENT),
            map,
            start,
            rng_stream(seed, 31),
            rng_stream(seed, 32),
        )));
    }
    let odometers = [topics::ODOMETER_1, topics::ODOMETER_2];
    for (i, o) in p.odometers.iter().take(2).enumerate() {
        sensors.push(Box::new(OdometerSensor::new(
            o.clone(),
            i,
            along(odometers[i]),
            start,
            rng_stream(seed, 10 + i as u64),
        )));
    }
    sensors
}

/// The train moving along its track at one step: what a [`World`] is made of besides its
/// surroundings.
struct Moving<'a> {
    track: &'a Track,
    vehicle: &'a Vehicle,
    driver: &'a Driver,
    ride: RideSample,
}

/// What the train passes through (tunnels, cuttings, multipath, correction outages): the
/// world the sensors see at each step, and the events of entering and leaving it.
struct Surroundings<'a> {
    p: &'a LineScenario,
    station_chainages: Vec<f64>,
    tunnel: Option<String>,
    corrections: bool,
}

impl<'a> Surroundings<'a> {
    fn new(p: &'a LineScenario, map: &TrackMap) -> Self {
        Self {
            p,
            station_chainages: map.stations.iter().map(|s| s.chainage_m).collect(),
            tunnel: None,
            corrections: true,
        }
    }

    fn world<'t>(
        &mut self,
        moving: Moving<'t>,
        t_ns: u64,
        t: f64,
        dt: f64,
        outbox: &mut Outbox,
    ) -> World<'t> {
        let (track, driver) = (moving.track, moving.driver);
        let (p, map) = (self.p, &track.map);
        let (east_m, north_m, heading_rad) =
            map.locate(driver.s).expect("a built track has vertices");
        match (map.in_tunnel(driver.s), &self.tunnel) {
            (Some(tunnel), None) => {
                outbox.push(
                    t_ns,
                    event(t_ns, EventKind::TunnelEntry, tunnel.name.clone()),
                );
                self.tunnel = Some(tunnel.name.clone());
            }
            (None, Some(name)) => {
                outbox.push(t_ns, event(t_ns, EventKind::TunnelExit, name.clone()));
                self.tunnel = None;
            }
            _ => {}
        }
        let site = p
            .site
            .as_ref()
            .map(|site| site.at(driver.s, &self.station_chainages))
            .unwrap_or_default();
        let within = |spans: &[(f64, f64)]| spans.iter().any(|&(a, len)| t >= a && t < a + len);
        let corrections = !site.in_cutting && !within(&p.correction_outages_s);
        if corrections != self.corrections {
            let kind = match corrections {
                true => EventKind::CorrectionLinkUp,
                false => EventKind::CorrectionLinkDown,
            };
            outbox.push(t_ns, event(t_ns, kind, "RTCM corrections".into()));
            self.corrections = corrections;
        }
        World {
            t_ns,
            dt,
            chainage_m: driver.s,
            speed_mps: driver.v,
            acceleration_mps2: driver.a,
            east_m,
            north_m,
            heading_rad,
            curvature: track.curvature(driver.s),
            in_tunnel: self.tunnel.is_some(),
            corrections,
            gnss_outage: within(&p.gnss_outages_s),
            sky_view: site.sky_view,
            // Left of heading h (clockwise from north) is (−cos h, sin h).
            gnss_multipath: (
                -site.multipath_left_m * heading_rad.cos(),
                site.multipath_left_m * heading_rad.sin(),
            ),
            track,
            vehicle: moving.vehicle,
            ride: moving.ride,
        }
    }
}

/// The chainage stretches `map:offset` faults shift, with their offsets: where the train is
/// at each fault's start and end, from a dry run of the driver (deterministic: the same
/// stations, the same steps).
fn map_offsets(p: &LineScenario, map: &TrackMap, faults: &[FaultSpec]) -> Vec<(f64, f64, f64)> {
    let wanted: Vec<(f64, f64, f64)> = faults
        .iter()
        .filter_map(|f| match f.mode {
            faults::FaultMode::Offset(d) if f.device == "map" => Some((f.start_s, f.end_s, d)),
            _ => None,
        })
        .collect();
    if wanted.is_empty() {
        return Vec::new();
    }
    let last = wanted.iter().map(|w| w.1).fold(0.0, f64::max);
    let mut driver = Driver::new(
        p.driver.clone(),
        map.stations.iter().map(|s| s.chainage_m).collect(),
    );
    let dt = 1e-3;
    let mut at = Vec::new();
    let mut t = 0.0;
    while t <= last && driver.phase != Phase::Finished {
        at.push(driver.s);
        driver.step(t, dt);
        t += dt;
    }
    let s_at = |t: f64| {
        at.get((t / dt) as usize)
            .or(at.last())
            .copied()
            .unwrap_or(0.0)
    };
    wanted
        .iter()
        .map(|&(a, b, d)| (s_at(a), s_at(b), d))
        .filter(|(a, b, _)| b > a)
        .collect()
}

fn truth(w: &World, origin: &GeodeticOrigin) -> GroundTruth {
    let (lat, lon, _) = origin.to_geodetic(w.east_m, w.north_m, 0.0);
    GroundTruth {
        stamp_ns: w.t_ns,
        chainage_m: w.chainage_m,
        speed_mps: w.speed_mps,
        acceleration_mps2: w.acceleration_mps2,
        east_m: w.east_m,
        north_m: w.north_m,
        latitude_deg: lat,
        longitude_deg: lon,
        heading_rad: w.heading_rad,
    }
}
