//! Scenario presets: every parameter of a simulated run, serialisable so that each log
//! carries the exact parameters that made it (in its run metadata).

use crate::error::ScenarioError;
use railfuse_catalog::geodesy::GeodeticOrigin;
use serde::{Deserialize, Serialize};

use super::atlas::AtlasParams;
use super::driver::DriverParams;
use super::ride::RideParams;
use super::seed000::Seed000Params;
use super::sensors::{
    balise::BaliseParams, eddy_current::EddyCurrentParams, gnss::GnssParams, imu::ImuParams,
    induction_loop::LoopParams, odometer::OdometerParams, radar::RadarParams,
};
use super::site::SiteParams;
use super::track::{GradientSection, Segment, TrackParams, VerticalParams};
use super::vehicle::VehicleParams;

/// 2026-06-01T08:00:00Z: simulated runs start here, so logs are reproducible to the byte.
pub const SIMULATED_START_NS: u64 = 1_780_300_800 * 1_000_000_000;

/// A conventional line run with every sensor: what `--scenario default` simulates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineScenario {
    pub train: String,
    pub track: TrackParams,
    pub driver: DriverParams,
    /// Stations on the route (the run starts at the first and ends at the last).
    pub stations: usize,
    /// Windows (start, length) in seconds from the start without RTK correction data.
    pub correction_outages_s: Vec<(f64, f64)>,
    /// Windows (start, length) in seconds from the start in which the GNSS receiver sees no
    /// satellite at all.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gnss_outages_s: Vec<(f64, f64)>,
    pub truth_rate_hz: f64,
    pub gnss: GnssParams,
    pub imu: ImuParams,
    pub radar: RadarParams,
    pub odometers: Vec<OdometerParams>,
    /// None: the line has no cross-induction loop.
    pub induction_loop: Option<LoopParams>,
    /// None: no balise reader on the train.
    pub balise: Option<BaliseParams>,
    /// Parallel tracks, multipath and the map's survey error (source 002's line); None: an
    /// open line with an exact map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub site: Option<SiteParams>,
    /// The sleeper layout and switches in the map (source 004's atlas); None: one sleeper
    /// spacing, no switches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub atlas: Option<AtlasParams>,
    /// None: no eddy-current sensor pair on the bogie.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eddy_current: Option<EddyCurrentParams>,
    /// The odometers and the radar send on the vehicle's CAN bus (samples/vehicle.dbc), logged
    /// as frames on `/can/can0/frames`, instead of on channels of their own.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub can_bus: bool,
    /// The train with its length and each sensor where it sits (published on `/vehicle`,
    /// installed within tolerances); None: a point train, every sensor at the front end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<VehicleParams>,
    /// The body's vibration; None: a body that follows the track exactly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ride: Option<RideParams>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "preset", rename_all = "snake_case")]
pub enum Scenario {
    /// The default run on a railway in three dimensions with a train of 104 m (see
    /// [`LineScenario::default_run`]); logs of before the flat world had its own name
    /// carry it as `railway`.
    #[serde(alias = "railway")]
    Default(Box<LineScenario>),
    Seed000(Seed000Params),
    /// Source 000 with the loop's error growing with distance.
    Seed000LoopDrift(Seed000Params),
    Seed001(Box<LineScenario>),
    /// Source 002's safety experiment: curves, parallel tracks and multipath at stations,
    /// cuttings, a surveyed map.
    Seed002(Box<LineScenario>),
    /// Source 003's hardware on that line: RTK at 5 Hz, satellites falling in cuttings, a
    /// 150 s GNSS loss, a 30 Hz MEMS IMU.
    Seed003(Box<LineScenario>),
    /// Source 004's eddy-current experiment: shunting moves, hard acceleration and braking,
    /// long stops and line speed over an atlas of sleeper sections and switches.
    Seed004(Box<LineScenario>),
    /// The default run's line and drive in the plane, with a point train (see
    /// [`LineScenario::flattened`]).
    Flat(Box<LineScenario>),
    /// Source 003's experiment on the default run's railway in three dimensions with its
    /// 104 m train (see [`LineScenario::in_three_dimensions`]).
    #[serde(rename = "seed003_3d")]
    Seed003In3d(Box<LineScenario>),
    /// [`Self::Seed003In3d`]'s line and drive flattened with a point train: the flat world to
    /// compare it with, as [`Self::Flat`] is the default's.
    #[serde(rename = "seed003_3d_flat")]
    Seed003In3dFlat(Box<LineScenario>),
}

impl Scenario {
    pub const NAMES: &'static [&'static str] = &[
        "default",
        "flat",
        "seed000",
        "seed000_loop_drift",
        "seed001",
        "seed002",
        "seed003",
        "seed003_3d",
        "seed003_3d_flat",
        "seed004",
    ];

    /// What each preset of [`Self::NAMES`] is, in a line, for help texts.
    pub fn describe(name: &str) -> &'static str {
        match name {
            "default" => {
                "a mixed line run near Modena with every sensor, on a railway as it is: \
                 gradients, cant, vibration, a 104 m train with each sensor where it sits"
            }
            "flat" => {
                "the default run's line and drive flattened: no gradient or cant, a point \
                 train (every sensor at the front end, a level IMU), no vibration"
            }
            "seed003_3d" => {
                "source 003's hardware and GNSS loss on the default run's railway in three \
                 dimensions, with its 104 m train"
            }
            "seed003_3d_flat" => {
                "seed003_3d's line and drive flattened, a point train: the flat world to \
                 compare seed003_3d with"
            }
            "seed000" => "source 000's maglev simulation, its parameters exactly as stated",
            "seed000_loop_drift" => "seed000 with the loop's error growing with distance",
            "seed001" => "source 001's: INS, BeiDou and Doppler radar, 500 s",
            "seed002" => {
                "source 002's: curves, parallel tracks and multipath at four stations, \
                 cuttings, a surveyed map with its own error"
            }
            "seed003" => {
                "source 003's: RTK at 5 Hz, satellites lost in cuttings, a 150 s GNSS \
                 outage, a 30 Hz MEMS IMU"
            }
            "seed004" => {
                "source 004's: shunting, hard acceleration and braking, long stops and line \
                 speed over sleeper sections and switches, with the eddy-current sensor pair"
            }
            _ => "",
        }
    }

    pub fn preset(name: &str) -> Option<Scenario> {
        match name {
            "default" => Some(Scenario::Default(Box::new(LineScenario::default_run()))),
            "seed000" => Some(Scenario::Seed000(Seed000Params::source())),
            "seed000_loop_drift" => Some(Scenario::Seed000LoopDrift(Seed000Params::loop_drift())),
            "seed001" => Some(Scenario::Seed001(Box::new(LineScenario::seed001()))),
            "seed002" => Some(Scenario::Seed002(Box::new(LineScenario::seed002()))),
            "seed003" => Some(Scenario::Seed003(Box::new(LineScenario::seed003()))),
            "seed004" => Some(Scenario::Seed004(Box::new(LineScenario::seed004()))),
            "flat" => Some(Scenario::Flat(Box::new(
                LineScenario::default_run().flattened(),
            ))),
            "seed003_3d" => Some(Scenario::Seed003In3d(Box::new(
                LineScenario::seed003().in_three_dimensions(),
            ))),
            "seed003_3d_flat" => Some(Scenario::Seed003In3dFlat(Box::new(
                LineScenario::seed003().in_three_dimensions().flattened(),
            ))),
            _ => None,
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Scenario::Default(_) => "default",
            Scenario::Seed000(_) => "seed000",
            Scenario::Seed000LoopDrift(_) => "seed000_loop_drift",
            Scenario::Seed001(_) => "seed001",
            Scenario::Seed002(_) => "seed002",
            Scenario::Seed003(_) => "seed003",
            Scenario::Seed004(_) => "seed004",
            Scenario::Flat(_) => "flat",
            Scenario::Seed003In3d(_) => "seed003_3d",
            Scenario::Seed003In3dFlat(_) => "seed003_3d_flat",
        }
    }

    /// The line-run parameters, for the presets that are line runs.
    pub fn line_mut(&mut self) -> Option<&mut LineScenario> {
        match self {
            Scenario::Default(p)
            | Scenario::Seed001(p)
            | Scenario::Seed002(p)
            | Scenario::Seed003(p)
            | Scenario::Seed004(p)
            | Scenario::Flat(p)
            | Scenario::Seed003In3d(p)
            | Scenario::Seed003In3dFlat(p) => Some(p),
            Scenario::Seed000(_) | Scenario::Seed000LoopDrift(_) => None,
        }
    }

    pub fn line(&self) -> Option<&LineScenario> {
        match self {
            Scenario::Default(p)
            | Scenario::Seed001(p)
            | Scenario::Seed002(p)
            | Scenario::Seed003(p)
            | Scenario::Seed004(p)
            | Scenario::Flat(p)
            | Scenario::Seed003In3d(p)
            | Scenario::Seed003In3dFlat(p) => Some(p),
            Scenario::Seed000(_) | Scenario::Seed000LoopDrift(_) => None,
        }
    }

    /// Whether a run of `duration_s` (the preset's own when `None`) with `faults` can be
    /// simulated: a positive duration, and every failed device one the scenario has.
    pub fn check(
        &self,
        duration_s: Option<f64>,
        faults: &[super::FaultSpec],
    ) -> Result<(), ScenarioError> {
        if let Some(d) = duration_s.filter(|d| !(d.is_finite() && *d > 0.0)) {
            return Err(ScenarioError::Duration(d));
        }
        if let Some(duration_s) = duration_s {
            Self::faults_within(duration_s, faults)?;
        }
        let name = self.name();
        let Some(line) = self.line() else {
            return match faults.is_empty() {
                true => Ok(()),
                false => Err(ScenarioError::NoDevices(name.to_owned())),
            };
        };
        for f in faults {
            let has = match f.device.as_str() {
                "loop" => line.induction_loop.is_some(),
                "balise" => line.balise.is_some(),
                "odometer1" => !line.odometers.is_empty(),
                "odometer2" => line.odometers.len() > 1,
                "eddy_current" => line.eddy_current.is_some(),
                _ => true,
            };
            if !has {
                return Err(ScenarioError::NoSuchDevice {
                    scenario: name.to_owned(),
                    device: f.device.clone(),
                });
            }
        }
        Ok(())
    }
}

impl Scenario {
    /// Every fault window starts before the run ends (`duration_s`, s).
    pub fn faults_within(
        duration_s: f64,
        faults: &[super::FaultSpec],
    ) -> Result<(), ScenarioError> {
        match faults.iter().find(|f| f.start_s >= duration_s) {
            Some(f) => Err(ScenarioError::AfterTheRun {
                device: f.device.clone(),
                start_s: f.start_s,
                duration_s,
            }),
            None => Ok(()),
        }
    }
}

impl LineScenario {
    /// A mixed run near Modena: three stations 5.7 km apart, curves, a tunnel, a correction
    /// link outage, every sensor at a realistic rate, on a flat line with a point train (every
    /// sensor at the front end, an IMU level and aligned): the world of railfuse's figures
    /// before its vehicle model, and the base the sources' scenarios keep.
    pub fn flat_run() -> Self {
        LineScenario {
            train: "simulated EMU, 4 cars".into(),
            track: Self::default_track(),
            driver: DriverParams {
                max_speed_mps: 33.3,
                acceleration_mps2: 0.8,
                power_limit_speed_mps: 15.0,
                braking_mps2: 0.7,
                jerk_mps3: 0.6,
                dwell_s: 30.0,
                initial_dwell_s: 10.0,
            },
            stations: 3,
            correction_outages_s: vec![(120.0, 45.0)],
            gnss_outages_s: vec![],
            truth_rate_hz: 100.0,
            gnss: Self::default_gnss(),
            imu: Self::default_imu(),
            radar: RadarParams {
                rate_hz: 20.0,
                latency_s: 0.015,
                scale_error: 0.004,
                sigma_base_mps: 0.02,
                sigma_per_mps: 0.002,
                min_speed_mps: 0.3,
                dropout_probability: 0.002,
                dropout_s: (0.5, 2.0),
            },
            odometers: vec![
                Self::default_odometer("axle1", 0.846, true),
                Self::default_odometer("axle2", 0.852, false),
            ],
            induction_loop: Some(LoopParams {
                crossing_spacing_m: 25.0,
                latency_s: 0.02,
                installation_sigma_m: 0.03,
                scale_error: 2e-5,
                timing_sigma_s: 0.003,
                reported_variance_m2: 0.01,
            }),
            balise: Some(BaliseParams {
                latency_s: 0.03,
                detection_sigma_m: 0.15,
                miss_probability: 0.01,
                reported_variance_m2: 0.04,
            }),
            site: None,
            atlas: Some(AtlasParams {
                section_m: (800.0, 2500.0),
                spacing_m: (0.60, 0.65),
                switch_offset_m: 250.0,
                switch_length_m: 35.0,
                extra_switches_m: vec![],
            }),
            eddy_current: Some(Self::default_eddy_current()),
            can_bus: false,
            vehicle: None,
            ride: None,
        }
    }

    /// The default run: [`Self::flat_run`] on a railway as it is: gradients to 35 ‰ (one
    /// stretch at 40 ‰) on vertical curves of 2 500 m, canted curves with transitions (cant
    /// ramps of 1:400, up to 150 mm, deficiency up to 129 mm on a 900 m curve), the body's
    /// lean and vibration, and a 104 m train with its sensors where they sit, installed
    /// within tolerances.
    pub fn default_run() -> Self {
        Self::flat_run().in_three_dimensions()
    }

    /// This run on the default run's railway in three dimensions: its line's curves with
    /// transitions and cant, its gradients and vertical curves, the body's lean and
    /// vibration, and the 104 m EMU with every sensor where it sits (its stations, sites and
    /// sensors as they are).
    pub fn in_three_dimensions(self) -> Self {
        let curve = |radius_m, angle_deg, transition_m, cant_mm| Segment::Curve {
            radius_m,
            angle_deg,
            transition_m,
            cant_mm,
        };
        let pattern = vec![
            Segment::Straight { length_m: 1800.0 },
            curve(1500.0, 35.0, 60.0, 110.0),
            Segment::Straight { length_m: 2600.0 },
            curve(2000.0, -30.0, 40.0, 60.0),
            Segment::Straight { length_m: 2200.0 },
            curve(1200.0, 25.0, 80.0, 150.0),
            Segment::Straight { length_m: 1500.0 },
            curve(900.0, -30.0, 70.0, 60.0),
        ];
        let g = |length_m, permille| GradientSection { length_m, permille };
        let vertical = VerticalParams {
            // Climbs 32 m and comes back down: the pattern repeats at the same height.
            sections: vec![
                g(1500.0, 0.0),
                g(2000.0, 12.0),
                g(1200.0, 35.0),
                g(1000.0, 0.0),
                g(600.0, 40.0),
                g(1400.0, -20.0),
                g(2500.0, -12.0),
                g(1600.0, -20.0),
            ],
            curve_radius_m: 2500.0,
        };
        LineScenario {
            train: format!("{}, 104 m", self.train),
            track: TrackParams {
                name: format!("{} in three dimensions", self.track.name),
                // Room behind the start for the train's 104 m.
                lead_in_m: 200.0,
                pattern,
                vertical: Some(vertical),
                ..self.track
            },
            vehicle: Some(VehicleParams::emu()),
            ride: Some(RideParams::coach()),
            ..self
        }
    }

    /// The same run in the world railfuse assumed before: the same line in the plane, flat and
    /// without cant, a body that follows it exactly, a point train.
    pub fn flattened(&self) -> Self {
        let mut p = self.clone();
        for seg in &mut p.track.pattern {
            if let Segment::Curve { cant_mm, .. } = seg {
                *cant_mm = 0.0;
            }
        }
        p.track.vertical = None;
        p.vehicle = None;
        p.ride = None;
        p
    }

    /// The default run's receiver: 10 Hz, RTK fixed to 2 cm, float to 25 cm, DGPS 0.7 m,
    /// single point 1.8 m, with a slowly wandering (τ 60 s) bias.
    pub fn default_gnss() -> GnssParams {
        GnssParams {
            rate_hz: 10.0,
            latency_s: 0.04,
            sigma_single_m: 1.8,
            sigma_dgps_m: 0.7,
            sigma_rtk_float_m: 0.25,
            sigma_rtk_fixed_m: 0.02,
            bias_tau_s: 60.0,
            bias_scale: 1.0,
            speed_sigma_mps: 0.05,
            reacquire_none_s: 3.0,
            reacquire_single_s: 6.0,
            reacquire_float_s: 12.0,
            rtk_rate_hz: None,
        }
    }

    /// The default run's MEMS IMU at 200 Hz, with quantisation (16-bit, ±2 g, ±125 °/s).
    pub fn default_imu() -> ImuParams {
        ImuParams {
            sensor_id: "imu0".into(),
            rate_hz: 200.0,
            latency_s: 0.001,
            accel_noise_mps2: 0.012,
            accel_bias_mps2: 0.02,
            accel_bias_walk: 2e-4,
            accel_lsb_mps2: 0.061e-3 * 9.80665,
            gyro_noise_radps: 0.0012,
            gyro_bias_radps: 5e-4,
            gyro_bias_walk: 2e-5,
            gyro_lsb_radps: 4.37e-3_f64.to_radians(),
        }
    }

    /// The default line: about 8 km of straights and curves near Modena, a tunnel, a balise
    /// every km and a loop crossing every 25 m.
    fn default_track() -> TrackParams {
        TrackParams {
            name: "Modena test line (simulated)".into(),
            origin: GeodeticOrigin {
                latitude_deg: 44.6551,
                longitude_deg: 10.9297,
                altitude_m: 40.0,
            },
            heading_deg: 60.0,
            pattern: vec![
                Segment::Straight { length_m: 1800.0 },
                Segment::curve(1500.0, 35.0),
                Segment::Straight { length_m: 2600.0 },
                Segment::curve(2000.0, -30.0),
                Segment::Straight { length_m: 2200.0 },
                Segment::curve(1200.0, 25.0),
                Segment::Straight { length_m: 1500.0 },
                Segment::curve(1800.0, -30.0),
            ],
            station_spacing_m: 5700.0,
            balise_spacing_m: 1000.0,
            balise_jitter_m: 60.0,
            tunnels: vec![(7000.0, 7800.0)],
            sleeper_spacing_m: 0.6,
            loop_crossing_spacing_m: Some(25.0),
            vertex_spacing_m: 10.0,
            station_chainages_m: vec![],
            vertical: None,
            lead_in_m: 0.0,
        }
    }

    /// A wheel odometer of the default train (`powered`: a driven axle, which slips).
    fn default_odometer(id: &str, true_diameter_m: f64, powered: bool) -> OdometerParams {
        OdometerParams {
            sensor_id: id.into(),
            rate_hz: 25.0,
            latency_s: 0.002,
            pulses_per_revolution: 200,
            configured_diameter_m: 0.85,
            true_diameter_m,
            speed_window_s: 0.2,
            slip_rate_per_s: if powered { 0.04 } else { 0.0 },
            slide_rate_per_s: 0.04,
            slip_range: (0.03, 0.10),
            slide_range: (0.05, 0.15),
            episode_s: (1.0, 4.0),
        }
    }

    /// The default train's eddy-current sensor pair.
    fn default_eddy_current() -> EddyCurrentParams {
        EddyCurrentParams {
            rate_hz: 10_000.0,
            block_s: 0.1,
            latency_s: 0.005,
            spacing_m: 0.25,
            sleeper_jitter_m: 0.008,
            pulse_width_m: 0.04,
            sleeper_amplitude_v: 0.8,
            amplitude_spread: 0.1,
            switch_amplitude_v: 1.0,
            cable_spacing_m: 300.0,
            cable_amplitude_v: 1.2,
            defects_per_km: 20.0,
            defect_amplitude_v: 0.3,
            height_m: 0.10,
            vibration_m: 0.002,
            vibration_s: 0.05,
            noise_v: 0.05,
            range_v: 5.0,
            lsb_v: 0.0005,
            gain_b: 0.97,
        }
    }

    /// Source 004's experiment: the default train over a line with a yard at its start.
    /// Stops 40 m and 60 m apart (shunting moves at walking to 7 m/s), a 4 km run to
    /// 40 m/s, another 60 m shunt and a 4.3 km run; hard acceleration (1.1 m/s²) and
    /// braking (1.0 m/s²), 45 s stops. Sleeper sections of 0.60–0.65 m, a switch 150 m
    /// either side of each stop and two more out on the line. The eddy-current pair is the
    /// default run's (D = 0.25 m, 10 kHz).
    pub fn seed004() -> Self {
        let base = Self::flat_run();
        LineScenario {
            train: "simulated EMU, 4 cars (source 004 eddy-current experiment)".into(),
            track: TrackParams {
                name: "Modena test line with a yard (source 004 simulation)".into(),
                station_chainages_m: vec![0.0, 40.0, 100.0, 4100.0, 4160.0, 8500.0],
                tunnels: vec![],
                ..base.track.clone()
            },
            driver: DriverParams {
                max_speed_mps: 40.0,
                acceleration_mps2: 1.1,
                power_limit_speed_mps: 20.0,
                braking_mps2: 1.0,
                jerk_mps3: 1.0,
                dwell_s: 45.0,
                initial_dwell_s: 10.0,
            },
            stations: 6,
            correction_outages_s: vec![],
            atlas: base.atlas.clone().map(|a| AtlasParams {
                switch_offset_m: 150.0,
                switch_length_m: 30.0,
                extra_switches_m: vec![2000.0, 6500.0],
                ..a
            }),
            ..base
        }
    }

    /// Source 001's experiment: a maglev with a strapdown INS, a BeiDou receiver (no
    /// corrections: single-point fixes) and a Doppler radar, on a straight guideway, about
    /// 500 s from standstill through all three β speed bands (to 432 km/h) and back to a stop.
    ///
    /// The source gives no noise figures ("several noise standard deviations"); these are
    /// typical of the devices it names: BeiDou single point 2.5 m σ with a slow bias, speed
    /// 0.1 m/s; radar 50 Hz, 0.05 m/s + 0.2 % of speed, 0.3 % scale error; a navigation-grade
    /// MEMS INS at 100 Hz, 0.02 m/s² noise, 5 mm/s² turn-on bias.
    pub fn seed001() -> Self {
        let base = Self::flat_run();
        LineScenario {
            train: "maglev (source 001 simulation)".into(),
            track: TrackParams {
                name: "maglev guideway (source 001 simulation)".into(),
                origin: GeodeticOrigin {
                    latitude_deg: 31.19,
                    longitude_deg: 121.34,
                    altitude_m: 5.0,
                },
                heading_deg: 90.0,
                pattern: vec![Segment::Straight { length_m: 60_000.0 }],
                station_spacing_m: 43_000.0,
                balise_spacing_m: 1000.0,
                balise_jitter_m: 0.0,
                tunnels: vec![],
                sleeper_spacing_m: 1.032,
                loop_crossing_spacing_m: None,
                vertex_spacing_m: 10.0,
                station_chainages_m: vec![],
                vertical: None,
                lead_in_m: 0.0,
            },
            driver: DriverParams {
                max_speed_mps: 120.0,
                acceleration_mps2: 1.0,
                power_limit_speed_mps: 60.0,
                braking_mps2: 0.9,
                jerk_mps3: 0.5,
                dwell_s: 10.0,
                initial_dwell_s: 5.0,
            },
            stations: 2,
            // No differential corrections at all: BeiDou single-point fixes.
            correction_outages_s: vec![(0.0, 1e9)],
            gnss_outages_s: vec![],
            truth_rate_hz: 100.0,
            gnss: GnssParams {
                sigma_single_m: 2.5,
                speed_sigma_mps: 0.1,
                ..base.gnss
            },
            imu: ImuParams {
                sensor_id: "ins0".into(),
                rate_hz: 100.0,
                accel_noise_mps2: 0.02,
                accel_bias_mps2: 0.005,
                accel_bias_walk: 2e-5,
                ..base.imu
            },
            radar: RadarParams {
                rate_hz: 50.0,
                latency_s: 0.01,
                scale_error: 0.003,
                sigma_base_mps: 0.05,
                sigma_per_mps: 0.002,
                min_speed_mps: 0.3,
                dropout_probability: 0.0,
                dropout_s: (0.5, 2.0),
            },
            odometers: vec![],
            induction_loop: None,
            balise: None,
            site: None,
            atlas: None,
            eddy_current: None,
            can_bus: false,
            vehicle: None,
            ride: None,
        }
    }

    /// Source 002's experiment: the default line with what its safety checks are for. Four
    /// stations, each with a parallel track 4.5 m to the left for 400 m either side and
    /// station buildings whose multipath pulls fixes up to 3 m towards it within 300 m; two
    /// cuttings (no RTK corrections, up to 2 m of multipath); the published map surveyed every
    /// 20 m with a lateral error of 0.1 m σ wandering over 200 m. The tunnel, the correction
    /// outage, both axles' slip, slide and distinct wheel wear are the default run's.
    pub fn seed002() -> Self {
        let base = Self::flat_run();
        LineScenario {
            train: "simulated EMU, 4 cars (source 002 line)".into(),
            track: TrackParams {
                name: "Modena test line with stations and cuttings (source 002 simulation)".into(),
                ..base.track.clone()
            },
            stations: 4,
            site: Some(SiteParams {
                station_track_half_length_m: 400.0,
                station_track_offset_m: 4.5,
                station_multipath_m: 300.0,
                station_multipath_bias_m: 3.0,
                cuttings: vec![(3000.0, 3600.0), (9500.0, 10_200.0), (14_000.0, 14_500.0)],
                cutting_multipath_bias_m: 2.0,
                map_survey_std_m: 0.1,
                map_survey_correlation_m: 200.0,
                map_survey_spacing_m: 20.0,
                cutting_sky_view: 1.0,
            }),
            // Source 002's experiment has no eddy-current sensors.
            atlas: None,
            eddy_current: None,
            ..base
        }
    }

    /// Source 003's experiment, on a train: its hardware on source 002's line. A
    /// single-frequency RTK receiver (single point at 10 Hz, RTK at 5 Hz; 2.5 m single-point
    /// σ, 2 cm fixed, 0.3 m float; Doppler speed 0.1 m/s) whose satellites fall to about a
    /// third in the cuttings (HDOP up, RTK lost, multipath); a 150 s loss of every satellite
    /// from 330 s; a MEMS IMU at 30 Hz with the source's table 1: bias stability 0.2 mg and
    /// 0.007 °/s, velocity random walk 0.2 m/s/√h, angle random walk 2.4 °/√h (its white
    /// noise at 30 Hz: 0.018 m/s² and 0.22 °/s per sample), the biases wandering over the
    /// hour by as much again.
    pub fn seed003() -> Self {
        let base = Self::seed002();
        let per_sample = |density: f64, rate_hz: f64| density * rate_hz.sqrt();
        let rate = 30.0;
        LineScenario {
            train: "simulated EMU, 4 cars (source 003 hardware)".into(),
            track: TrackParams {
                name: "Modena test line with cuttings (source 003 simulation)".into(),
                ..base.track.clone()
            },
            gnss_outages_s: vec![(330.0, 150.0)],
            gnss: GnssParams {
                sigma_single_m: 2.5,
                sigma_rtk_float_m: 0.3,
                speed_sigma_mps: 0.1,
                rtk_rate_hz: Some(5.0),
                ..base.gnss
            },
            imu: ImuParams {
                sensor_id: "mems0".into(),
                rate_hz: rate,
                accel_noise_mps2: per_sample(0.2 / 60.0, rate),
                accel_bias_mps2: 0.2e-3 * 9.80665,
                accel_bias_walk: 0.2e-3 * 9.80665 / 60.0,
                gyro_noise_radps: per_sample((2.4f64 / 60.0).to_radians(), rate),
                gyro_bias_radps: 0.007f64.to_radians(),
                gyro_bias_walk: 0.007f64.to_radians() / 60.0,
                ..base.imu
            },
            site: base.site.map(|s| SiteParams {
                cutting_sky_view: 0.35,
                ..s
            }),
            ..base
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_is_logged_under_the_name_it_is_asked_by_and_reads_back() {
        for name in Scenario::NAMES {
            let preset = Scenario::preset(name).expect("a listed preset");
            assert_eq!(preset.name(), *name);
            assert!(!Scenario::describe(name).is_empty(), "{name}");
            let json = serde_json::to_value(&preset).unwrap();
            assert_eq!(json["preset"], *name, "{name}");
            let back: Scenario = serde_json::from_value(json).unwrap();
            assert_eq!(back, preset, "{name}");
        }
        // A log of the railway before it was the default scenario reads as the default.
        let mut old = serde_json::to_value(Scenario::preset("default").unwrap()).unwrap();
        old["preset"] = "railway".into();
        let read: Scenario = serde_json::from_value(old).unwrap();
        assert_eq!(read.name(), "default");
    }
}
