use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    StationArrival,
    StationDeparture,
    CorrectionLinkUp,
    CorrectionLinkDown,
    TunnelEntry,
    TunnelExit,
    OperatorNote,
    /// The simulator made a device fail (a marker for evaluation; filters do not see it).
    FaultInjected,
    FaultCleared,
    /// A device reported its own failure (text: device name); federated detectors honour it.
    DeviceFault,
    DeviceRecovered,
}

/// Something that happened during the run, worth a mark on the timeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Event {
    pub stamp_ns: u64,
    pub kind: EventKind,
    /// Station name, device name or free text.
    pub text: String,
}
