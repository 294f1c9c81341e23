//! The vehicle's CAN bus as the simulator puts the odometers and the radar on it, with the
//! DBC railfuse ships (samples/vehicle.dbc): the traction control unit sends both axles'
//! speeds in one `WheelSpeed` frame and their pulse counts in `AxlePulses` at each sample, the
//! radar its `RadarSpeed` frame. A frame's bus time is when it was on the bus (the sensor's
//! own sample time does not travel), so a re-fusion of the bus sees each sensor's latency.
//!
//! An axle with no reading at a sample (its odometer failed) is sent as all ones, the value
//! CAN uses for "not available": it decodes outside its range and is not made into a sensor.

use railfuse_can::dbc::{Database, Message};
use railfuse_can::frame::Frame;
use railfuse_catalog::messages::{Odometer, RadarSpeed};

/// The DBC the simulator sends with, as shipped in samples/.
pub const VEHICLE_DBC: &str = include_str!("../../../../samples/vehicle.dbc");

/// The bus's name in the log (`/can/can0/frames`).
pub const BUS: &str = "can0";

/// One axle's reading: its speed, m/s, and its pulse count.
type Axle = (f64, u64);

/// The bus: its messages, and the axle readings of the sample being gathered.
pub struct CanBus {
    wheel_speed: Message,
    axle_pulses: Message,
    radar: Message,
    axles: usize,
    /// The sample's stamp, and each axle's reading so far.
    pending: Option<(u64, Vec<Option<Axle>>)>,
    counter: u64,
}

fn message(db: &Database, name: &str) -> Message {
    db.messages
        .values()
        .find(|m| m.name == name)
        .unwrap_or_else(|| panic!("samples/vehicle.dbc has {name}"))
        .clone()
}

impl CanBus {
    /// The bus of a train with `axles` odometers (one or two).
    pub fn new(axles: usize) -> Self {
        let db = Database::parse("samples/vehicle.dbc", VEHICLE_DBC)
            .expect("samples/vehicle.dbc is checked by the tests");
        Self {
            wheel_speed: message(&db, "WheelSpeed"),
            axle_pulses: message(&db, "AxlePulses"),
            radar: message(&db, "RadarSpeed"),
            axles: axles.clamp(1, 2),
            pending: None,
            counter: 0,
        }
    }

    fn frame(m: &Message, bus_ns: u64, data: Vec<u8>) -> Frame {
        Frame {
            stamp_ns: bus_ns,
            bus: BUS.into(),
            id: m.id,
            extended: m.extended,
            rtr: false,
            error: false,
            fd: false,
            brs: false,
            esi: false,
            data,
        }
    }

    /// The radar's frame, on the bus at `bus_ns`.
    pub fn radar(&self, m: &RadarSpeed, bus_ns: u64) -> Frame {
        let data = self.radar.encode(&[
            ("GroundSpeed", m.speed_mps),
            ("Quality", 100.0 * m.quality),
            ("Valid", f64::from(u8::from(m.valid))),
        ]);
        Self::frame(&self.radar, bus_ns, data)
    }

    /// Axle `index`'s reading, received at `bus_ns`: the sample's frames once every axle has
    /// read it (or a later sample begins), into `out`.
    pub fn odometer(&mut self, index: usize, m: &Odometer, bus_ns: u64, out: &mut Vec<Frame>) {
        if self.pending.as_ref().is_some_and(|(t, _)| *t != m.stamp_ns) {
            self.flush(bus_ns, out);
        }
        let (_, axles) = self
            .pending
            .get_or_insert_with(|| (m.stamp_ns, vec![None; self.axles]));
        if let Some(slot) = axles.get_mut(index) {
            *slot = Some((m.speed_mps, m.pulse_count.unwrap_or(0)));
        }
        if axles.iter().all(Option::is_some) {
            self.flush(bus_ns, out);
        }
    }

    /// The sample gathered so far, as its two frames.
    pub fn flush(&mut self, bus_ns: u64, out: &mut Vec<Frame>) {
        let Some((_, axles)) = self.pending.take() else {
            return;
        };
        // All ones: "not available".
        let speed = |i: usize| axles.get(i).copied().flatten().map_or(655.35, |a| a.0);
        let pulses = |i: usize| {
            axles
                .get(i)
                .copied()
                .flatten()
                .map_or(u32::MAX as f64, |a| (a.1 % (1 << 32)) as f64)
        };
        self.counter += 1;
        let speeds = self.wheel_speed.encode(&[
            ("AxleSpeed1", speed(0)),
            ("AxleSpeed2", speed(1)),
            ("Direction", 1.0),
            ("Counter", (self.counter % 16) as f64),
        ]);
        out.push(Self::frame(&self.wheel_speed, bus_ns, speeds));
        let counts = self
            .axle_pulses
            .encode(&[("PulseCount1", pulses(0)), ("PulseCount2", pulses(1))]);
        out.push(Self::frame(&self.axle_pulses, bus_ns, counts));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use railfuse_can::decode::Decoded;

    fn odometer(stamp_ns: u64, speed_mps: f64, pulses: u64) -> Odometer {
        Odometer {
            stamp_ns,
            sensor_id: "axle".into(),
            pulse_count: Some(pulses),
            pulses_per_revolution: Some(200),
            wheel_diameter_m: Some(0.85),
            distance_increment_m: None,
            speed_mps,
        }
    }

    #[test]
    fn both_axles_of_a_sample_share_a_frame_and_a_missing_one_is_not_available() {
        let db = Database::parse("vehicle.dbc", VEHICLE_DBC).unwrap();
        let mut bus = CanBus::new(2);
        let mut out = Vec::new();
        bus.odometer(0, &odometer(10, 12.345, 100), 12, &mut out);
        assert!(out.is_empty(), "waits for the second axle");
        bus.odometer(1, &odometer(10, 12.5, 101), 13, &mut out);
        assert_eq!(out.len(), 2);
        // The next sample's axle 1 only: sent when the one after begins.
        bus.odometer(0, &odometer(20, 13.0, 150), 22, &mut out);
        bus.odometer(0, &odometer(30, 14.0, 200), 32, &mut out);
        assert_eq!(out.len(), 4);
        let signals = |f: &Frame| match db.decode(f) {
            Decoded::Signals { values, .. } => values,
            other => panic!("{other:?}"),
        };
        let v = signals(&out[0]);
        assert_eq!(out[0].stamp_ns, 13);
        assert!((v[0].value - 12.35).abs() < 1e-9 && (v[1].value - 12.5).abs() < 1e-9);
        let v = signals(&out[2]);
        assert!((v[0].value - 13.0).abs() < 1e-9);
        assert!(v[1].out_of_range, "axle 2 had no reading: {:?}", v[1]);
        let p = signals(&out[3]);
        assert_eq!((p[0].value, p[1].value), (150.0, u32::MAX as f64));
        let radar = bus.radar(
            &RadarSpeed {
                stamp_ns: 1,
                speed_mps: 22.4,
                quality: 0.93,
                valid: true,
                speed_variance_m2ps2: None,
            },
            5,
        );
        let v = signals(&radar);
        assert!((v[0].value - 22.4).abs() < 1e-9 && (v[1].value - 93.0).abs() < 1e-9);
        assert_eq!(v[2].value, 1.0);
    }
}
