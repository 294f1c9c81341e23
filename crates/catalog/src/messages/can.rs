use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::protobuf::protobuf_form;

/// One frame as the vehicle's CAN bus carried it (`/can/<bus>/frames`): kept whole, whether
/// or not a DBC says what it means. The message's log time is when the recorder received it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct CanFrame {
    /// Bus time: the adapter's or the kernel's stamp of the frame (the log's, when imported),
    /// ns since the Unix epoch.
    pub stamp_ns: u64,
    /// When the recorder received it, ns since the Unix epoch (on the recorder's clock).
    pub receive_ns: u64,
    /// The interface or bus (`can0`, `slcan0`, a log's channel).
    pub bus: String,
    /// The identifier: 11 bits, or 29 with `extended`; an error frame's error class bits.
    pub id: u32,
    pub extended: bool,
    /// A remote transmission request (no data).
    pub remote: bool,
    /// An error frame.
    pub error: bool,
    /// CAN FD, with its bit-rate switch and error-state indicator.
    pub fd: bool,
    pub brs: bool,
    pub esi: bool,
    /// The payload (0–8 bytes, FD up to 64).
    pub data: CanData,
}

protobuf_form!(CanFrame {
    stamp_ns,
    receive_ns,
    bus,
    id,
    extended,
    remote,
    error,
    fd,
    brs,
    esi,
    data
});

/// A frame's payload: hex digits in JSON (`"DEADBEEF"`, as candump writes it, readable in
/// Foxglove's raw view), bytes in protobuf.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CanData(pub Vec<u8>);

impl Serialize for CanData {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use std::fmt::Write;
        let mut hex = String::with_capacity(2 * self.0.len());
        for b in &self.0 {
            let _ = write!(hex, "{b:02X}");
        }
        s.serialize_str(&hex)
    }
}

impl<'de> Deserialize<'de> for CanData {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let hex = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        parse_hex(&hex)
            .map(CanData)
            .map_err(serde::de::Error::custom)
    }
}

/// The bytes of an even number of hex digits, at most 64 bytes.
fn parse_hex(hex: &str) -> Result<Vec<u8>, String> {
    if !hex.len().is_multiple_of(2) || hex.len() > 128 {
        return Err(format!(
            "'{hex}' is not 0 to 64 bytes in hex (an even number of digits)"
        ));
    }
    (0..hex.len())
        .step_by(2)
        .map(|i| {
            u8::from_str_radix(&hex[i..i + 2], 16).map_err(|_| format!("'{hex}' is not hex digits"))
        })
        .collect()
}

impl JsonSchema for CanData {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "CanData".into()
    }
    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "type": "string",
            "pattern": "^([0-9A-Fa-f]{2}){0,64}$",
            "description": "The payload in hex, two digits a byte"
        })
    }
}

impl crate::protobuf::Wire for CanData {
    type W = Vec<u8>;
    fn to_wire(&self) -> Vec<u8> {
        self.0.clone()
    }
    fn from_wire(w: Vec<u8>, field: &str) -> Result<Self, String> {
        match w.len() {
            0..=64 => Ok(CanData(w)),
            n => Err(format!("{field} has {n} bytes, above 64")),
        }
    }
}

/// One DBC message's signals decoded from a frame (`/can/<bus>/<Message>`), each in its unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct CanSignals {
    /// The frame's bus time, ns since the Unix epoch.
    pub stamp_ns: u64,
    pub bus: String,
    /// The frame's identifier and the message's name in the DBC.
    pub id: u32,
    pub message: String,
    pub signals: Vec<CanSignal>,
}

protobuf_form!(CanSignals {
    stamp_ns,
    bus,
    id,
    message,
    signals
});

/// One signal: `raw · factor + offset`, in the DBC's unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct CanSignal {
    pub name: String,
    pub value: f64,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
    /// The value table's name for the raw value (`"forward"`), where it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// Outside the range the DBC declares: kept as it came, and flagged.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub out_of_range: bool,
}

protobuf_form!(CanSignal {
    name,
    value,
    unit,
    label,
    out_of_range
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_payload_is_hex_in_json_and_refused_when_it_is_not() {
        let d = CanData(vec![0xDE, 0xAD, 0x00, 0x0F]);
        assert_eq!(serde_json::to_string(&d).unwrap(), "\"DEAD000F\"");
        let back: CanData = serde_json::from_str("\"dead000f\"").unwrap();
        assert_eq!(back, d);
        assert!(serde_json::from_str::<CanData>("\"ABC\"").is_err());
        assert!(serde_json::from_str::<CanData>("\"ZZ\"").is_err());
        let long = format!("\"{}\"", "00".repeat(65));
        assert!(serde_json::from_str::<CanData>(&long).is_err());
    }
}
