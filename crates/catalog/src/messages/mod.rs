//! One module per sensor kind, plus the static track map, ground truth, events, the fused
//! channels and tuning traces. Each type implements [`ChannelMessage`], which ties it to its schema name.

mod balise;
mod can;
mod eddy_current;
mod events;
mod examples;
pub mod fused;
mod gnss;
mod ground_truth;
mod imu;
mod imu_error_model;
mod induction_loop;
mod odometer;
mod radar;
mod recorder;
mod registry;
mod safety;
mod time_reference;
mod track_map;
mod train_position;
mod tuning;
mod vehicle;

pub use balise::BalisePassage;
pub use can::{CanData, CanFrame, CanSignal, CanSignals};
pub use eddy_current::EddyCurrentBlock;
pub use events::{Event, EventKind, Severity};
pub use fused::{
    DeviceShare, EddyCurrentDiagnostics, FusedDiagnostics, FusedGeodetic, FusedState, GateDecision,
    PlanePosition, SensorStateEstimate,
};
pub use gnss::{FixType, GnssFix};
pub use ground_truth::GroundTruth;
pub use imu::Imu;
pub use imu_error_model::ImuErrorModel;
pub use induction_loop::LoopPosition;
pub use odometer::Odometer;
pub use radar::RadarSpeed;
pub use recorder::{RecorderDiagnostics, SourceStats};
pub use registry::{AnyMessage, MessageKind, StampClock};
pub use safety::{SafeInterval, SafetyCheck, SafetyStatus};
pub use time_reference::TimeReference;
pub use track_map::{
    SleeperSection, Station, TrackBalise, TrackLine, TrackMap, TrackSwitch, TrackVertex, Tunnel,
};
pub use train_position::{two_sided_quantile, TrainEnd, TrainPosition};
pub use tuning::{TuneEvaluation, TunedValue};
pub use vehicle::{SensorMount, Vehicle};

use serde::{de::DeserializeOwned, Serialize};

/// A message type that travels on a railfuse channel.
pub trait ChannelMessage:
    Serialize
    + DeserializeOwned
    + Clone
    + schemars::JsonSchema
    + crate::protobuf::ProtobufForm
    + 'static
{
    /// The MCAP schema name, `railfuse.<Type>`.
    const SCHEMA_NAME: &'static str;
    /// Its entry in the registry.
    const KIND: MessageKind;

    /// The sensor's own timestamp, ns since the Unix epoch.
    fn stamp_ns(&self) -> u64;
    fn stamp_ns_mut(&mut self) -> &mut u64;

    /// The JSON schema of this type (draft 2020-12), as stored in the MCAP schema record.
    fn schema_bytes() -> Vec<u8> {
        let schema = schemars::schema_for!(Self);
        serde_json::to_vec_pretty(&schema).expect("a generated schema always serialises")
    }
}

/// Every schema of the catalogue, by name: what a validator or a new recorder source needs.
pub fn all_schemas() -> Vec<(&'static str, Vec<u8>)> {
    MessageKind::ALL
        .iter()
        .map(|k| (k.schema_name(), k.schema_bytes()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_an_object_schema_with_the_stamp() {
        for (name, bytes) in all_schemas() {
            let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
            assert_eq!(v["type"], "object", "{name}");
            if name != TrackMap::SCHEMA_NAME {
                assert!(
                    v["properties"]["stamp_ns"].is_object(),
                    "{name} lacks stamp_ns"
                );
            }
        }
    }
}
