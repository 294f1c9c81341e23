//! The vehicle's CAN bus read as railfuse's own sensors.
//!
//! A frame travels as a [`CanFrame`] (`/can/<bus>/frames`), whole, whatever the DBC knows;
//! the DBC's messages decode to [`CanSignals`] (`/can/<bus>/<Message>`); and a
//! configuration maps a decoded signal onto a railfuse sensor, so a recording of the bus
//! alone re-fuses with no bridge:
//!
//! ```toml
//! [can]
//! dbc = "vehicle.dbc"
//!
//! [sensor."/odometer/1"]
//! from = "can:WheelSpeed.AxleSpeed1"
//!
//! [sensor."/radar/speed"]
//! from = "can:RadarSpeed.GroundSpeed"
//! valid = "can:RadarSpeed.Valid"        # optional: 0 is "no measurement"
//! quality = "can:RadarSpeed.Quality"    # optional: a fraction, or % by its unit
//! ```
//!
//! [`SensorBridge`] does the mapping: a speed signal in m/s, km/h or mph becomes an
//! [`Odometer`]'s or a [`RadarSpeed`]'s speed (its magnitude: direction is a signal of its
//! own on a train's bus), stamped with the frame's bus time; a GNSS fix and an IMU sample are
//! made of several signals, possibly of several messages (`latitude`, `longitude`, `fix_type`,
//! …; `acceleration`, `angular_rate`: see `mapping.rs` and `assembled.rs`); and `[[can]]`
//! gives each bus its own DBC.

mod assembled;
mod bridge;
mod mapping;
mod pulse_counter;
mod sensor;
mod settings;

use railfuse_can::decode::Value;
use railfuse_can::frame::Frame;

use crate::messages::{CanData, CanFrame, CanSignal, CanSignals};

pub use bridge::{BridgeCounts, CanBuses, CanSettings, MappingError, SensorBridge, SensorSource};

/// `/can/<bus>/frames`: every frame of one bus.
pub fn frames_topic(bus: &str) -> String {
    format!("/can/{bus}/frames")
}

/// `/can/<bus>/<Message>`: one DBC message's decoded signals.
pub fn signals_topic(bus: &str, message: &str) -> String {
    format!("/can/{bus}/{message}")
}

impl CanFrame {
    /// The catalogue's form of `frame`, received at `receive_ns`.
    pub fn from_frame(frame: &Frame, receive_ns: u64) -> Self {
        CanFrame {
            stamp_ns: frame.stamp_ns,
            receive_ns,
            bus: frame.bus.clone(),
            id: frame.id,
            extended: frame.extended,
            remote: frame.rtr,
            error: frame.error,
            fd: frame.fd,
            brs: frame.brs,
            esi: frame.esi,
            data: CanData(frame.data.clone()),
        }
    }

    /// The frame it carries.
    pub fn to_frame(&self) -> Frame {
        Frame {
            stamp_ns: self.stamp_ns,
            bus: self.bus.clone(),
            id: self.id,
            extended: self.extended,
            rtr: self.remote,
            error: self.error,
            fd: self.fd,
            brs: self.brs,
            esi: self.esi,
            data: self.data.0.clone(),
        }
    }
}

impl CanSignals {
    /// The message `name`'s signals decoded from `frame`.
    pub fn new(frame: &Frame, name: &str, values: Vec<Value>) -> Self {
        CanSignals {
            stamp_ns: frame.stamp_ns,
            bus: frame.bus.clone(),
            id: frame.id,
            message: name.to_owned(),
            signals: values
                .into_iter()
                .map(|v| CanSignal {
                    name: v.name,
                    value: v.value,
                    unit: v.unit,
                    label: v.label,
                    out_of_range: v.out_of_range,
                })
                .collect(),
        }
    }
}
