use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::{protobuf_enum, protobuf_form};

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

/// How much an event matters to whoever reads the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Severity {
    Info,
    Warning,
    Error,
}

impl EventKind {
    /// The event in words, as a log line starts, and how much it matters.
    pub fn describe(self) -> (&'static str, Severity) {
        use Severity::*;
        match self {
            EventKind::StationArrival => ("Station arrival", Info),
            EventKind::StationDeparture => ("Station departure", Info),
            EventKind::CorrectionLinkUp => ("RTK correction link up", Info),
            EventKind::CorrectionLinkDown => ("RTK correction link down", Warning),
            EventKind::TunnelEntry => ("Tunnel entry", Info),
            EventKind::TunnelExit => ("Tunnel exit", Info),
            EventKind::OperatorNote => ("Note", Info),
            EventKind::FaultInjected => ("Fault injected", Warning),
            EventKind::FaultCleared => ("Fault cleared", Info),
            EventKind::DeviceFault => ("Device reports a fault", Error),
            EventKind::DeviceRecovered => ("Device recovered", Info),
        }
    }
}

impl Event {
    /// One readable line: what happened and to what.
    pub fn line(&self) -> String {
        let (what, _) = self.kind.describe();
        if self.text.is_empty() {
            what.to_owned()
        } else {
            format!("{what}: {}", self.text)
        }
    }
}

protobuf_enum!(EventKind {
    StationArrival,
    StationDeparture,
    CorrectionLinkUp,
    CorrectionLinkDown,
    TunnelEntry,
    TunnelExit,
    OperatorNote,
    FaultInjected,
    FaultCleared,
    DeviceFault,
    DeviceRecovered,
});

protobuf_form!(Event {
    stamp_ns,
    kind,
    text
});
