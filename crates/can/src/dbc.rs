//! The vehicle's DBC file as railfuse decodes it: messages by id, their signals with
//! everything decoding needs. The grammar is the `can-dbc` crate's; what it leaves to the
//! reader (a signal past its frame's end, two messages on one id, a multiplexed signal
//! without its multiplexor) is checked here, each fault naming its line.

use std::collections::HashMap;
use std::path::Path;

use can_dbc::{
    ByteOrder, MultiplexIndicator, SignalExtendedValueType, ValueDescription, ValueType,
};

/// Why a DBC file cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DbcError {
    #[error("{file}: {reason}")]
    Unreadable { file: String, reason: String },
    #[error("{file}:{line}: {reason}")]
    Invalid {
        file: String,
        line: usize,
        reason: String,
    },
}

/// How a signal's raw bits are a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    Unsigned,
    Signed,
    Float32,
    Float64,
}

/// One signal of a message.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    pub name: String,
    /// As the DBC gives it: the least significant bit (Intel) or the most (Motorola).
    pub start_bit: u32,
    pub size: u32,
    /// Intel (little endian, `@1`) or not (Motorola, `@0`).
    pub little_endian: bool,
    pub encoding: Encoding,
    pub factor: f64,
    pub offset: f64,
    /// The declared range; `None` where the DBC gives `[0|0]` (no range).
    pub range: Option<(f64, f64)>,
    pub unit: String,
    /// Decoded only while the message's multiplexor reads this value.
    pub multiplexed_by: Option<u64>,
    pub is_multiplexor: bool,
    /// The value table: a raw value's name.
    pub labels: HashMap<i64, String>,
}

/// One message (frame id) and its signals.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub name: String,
    pub id: u32,
    pub extended: bool,
    /// Its length in bytes.
    pub size: usize,
    pub signals: Vec<Signal>,
}

/// The DBCs of a vehicle's buses, each for its bus or (`None`) for every bus no other names:
/// a vehicle bus and an OBD-2 bus decoded side by side, each with its own.
#[derive(Debug, Clone, Default)]
pub struct BusDbcs(pub Vec<(Option<String>, std::sync::Arc<Database>)>);

impl BusDbcs {
    /// One DBC for every bus, or none.
    pub fn every_bus(db: Option<std::sync::Arc<Database>>) -> Self {
        Self(db.into_iter().map(|d| (None, d)).collect())
    }

    /// The index of the DBC that decodes `bus`: the one naming it, else one naming no bus.
    pub fn index_of(&self, bus: &str) -> Option<usize> {
        let named = self.0.iter().position(|(b, _)| b.as_deref() == Some(bus));
        named.or_else(|| self.0.iter().position(|(b, _)| b.is_none()))
    }

    /// The DBC that decodes `bus`.
    pub fn for_bus(&self, bus: &str) -> Option<&Database> {
        self.index_of(bus).map(|i| &*self.0[i].1)
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// A `--dbc` argument: `FILE` (every bus) or `BUS=FILE`.
    pub fn parse_arg(arg: &str) -> (Option<String>, std::path::PathBuf) {
        match arg.split_once('=') {
            Some((bus, file)) if !bus.is_empty() && !bus.contains('/') => {
                (Some(bus.to_owned()), file.into())
            }
            _ => (None, arg.into()),
        }
    }
}

/// A DBC's messages by (id, extended).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Database {
    pub messages: HashMap<(u32, bool), Message>,
}

impl Database {
    /// Reads and checks the DBC at `path`.
    pub fn open(path: &Path) -> Result<Self, DbcError> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| DbcError::Unreadable {
            file: file.clone(),
            reason: e.to_string(),
        })?;
        // DBC editors write Windows-1252 as often as UTF-8.
        let text = match String::from_utf8(bytes) {
            Ok(t) => t,
            Err(e) => can_dbc::decode_cp1252(e.as_bytes())
                .map(|t| t.into_owned())
                .ok_or_else(|| DbcError::Unreadable {
                    file: file.clone(),
                    reason: "neither UTF-8 nor Windows-1252 text".into(),
                })?,
        };
        Self::parse(&file, &text)
    }

    /// Parses and checks DBC `text`, `file` naming it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Self, DbcError> {
        let invalid = |at: &str, reason: String| DbcError::Invalid {
            file: file.to_owned(),
            line: line_of(text, at),
            reason,
        };
        let dbc = grammar(file, text)?;
        let mut db = Database::default();
        for m in dbc.messages() {
            let (id, extended) = match *m.id() {
                can_dbc::MessageId::Standard(id) => (u32::from(id), false),
                can_dbc::MessageId::Extended(id) => (id, true),
            };
            let at = format!("BO_ {}", m.id().raw());
            let size = *m.size() as usize;
            if size > crate::frame::MAX_FD_LEN {
                return Err(invalid(
                    &at,
                    format!("message {} is {size} bytes long, more than 64", m.name()),
                ));
            }
            let mut signals = Vec::new();
            for s in m.signals() {
                let signal = signal(&dbc, m, s);
                check_fits(&signal, size).map_err(|reason| {
                    invalid(
                        &format!("SG_ {}", s.name()),
                        format!("{} {}: {reason}", m.name(), s.name()),
                    )
                })?;
                signals.push(signal);
            }
            let muxed = signals.iter().any(|s| s.multiplexed_by.is_some());
            if muxed && !signals.iter().any(|s| s.is_multiplexor) {
                return Err(invalid(
                    &at,
                    format!(
                        "message {} has multiplexed signals and no multiplexor",
                        m.name()
                    ),
                ));
            }
            let message = Message {
                name: m.name().clone(),
                id,
                extended,
                size,
                signals,
            };
            if db.messages.insert((id, extended), message).is_some() {
                // The second of the two is the one to name.
                let start = format!("\n{at} ");
                let second = text
                    .match_indices(&start)
                    .nth(1)
                    .map_or("", |(o, _)| &text[o + 1..]);
                return Err(invalid(second, format!("a second message with id {id:#x}")));
            }
        }
        Ok(db)
    }
}

/// The DBC's grammar (the `can-dbc` crate's), a failure placed at its line.
fn grammar(file: &str, text: &str) -> Result<can_dbc::Dbc, DbcError> {
    let invalid = |at: &str, reason: String| DbcError::Invalid {
        file: file.to_owned(),
        line: line_of(text, at),
        reason,
    };
    match can_dbc::Dbc::try_from(text) {
        Ok(d) => Ok(d),
        Err(can_dbc::Error::Incomplete(_, rest)) => {
            let what = rest.lines().next().unwrap_or("").trim();
            Err(invalid(rest, format!("does not parse from here: '{what}'")))
        }
        Err(can_dbc::Error::Nom(e)) => {
            let at = match &e {
                nom::Err::Error(e) | nom::Err::Failure(e) => e.input,
                nom::Err::Incomplete(_) => "",
            };
            Err(invalid(at, "does not parse".into()))
        }
        Err(e) => Err(invalid("", format!("{e:?}"))),
    }
}

/// The 1-based line of `at`, a slice of `text` (or a string found in it); 0 where neither.
fn line_of(text: &str, at: &str) -> usize {
    if at.is_empty() {
        return 0;
    }
    let offset = match (at.as_ptr() as usize).checked_sub(text.as_ptr() as usize) {
        Some(o) if o <= text.len() && !at.is_empty() => Some(o),
        _ => text.find(at),
    };
    offset.map_or(0, |o| text[..o].matches('\n').count() + 1)
}

fn signal(dbc: &can_dbc::Dbc, m: &can_dbc::Message, s: &can_dbc::Signal) -> Signal {
    let encoding = match (
        dbc.extended_value_type_for_signal(*m.id(), s.name()),
        s.value_type(),
    ) {
        (Some(SignalExtendedValueType::IEEEfloat32Bit), _) => Encoding::Float32,
        (Some(SignalExtendedValueType::IEEEdouble64bit), _) => Encoding::Float64,
        (_, ValueType::Signed) => Encoding::Signed,
        (_, ValueType::Unsigned) => Encoding::Unsigned,
    };
    let labels = dbc
        .value_descriptions()
        .iter()
        .filter_map(|v| match v {
            ValueDescription::Signal {
                message_id,
                name,
                value_descriptions,
            } if message_id == m.id() && name == s.name() => Some(value_descriptions),
            _ => None,
        })
        .flatten()
        .map(|d| (*d.id() as i64, d.description().clone()))
        .collect();
    let (multiplexed_by, is_multiplexor) = match *s.multiplexer_indicator() {
        MultiplexIndicator::Multiplexor => (None, true),
        MultiplexIndicator::MultiplexedSignal(v) => (Some(v), false),
        MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => (Some(v), true),
        MultiplexIndicator::Plain => (None, false),
    };
    Signal {
        name: s.name().clone(),
        start_bit: s.start_bit as u32,
        size: s.size as u32,
        little_endian: *s.byte_order() == ByteOrder::LittleEndian,
        encoding,
        factor: s.factor,
        offset: s.offset,
        range: (s.min != s.max).then_some((s.min, s.max)),
        unit: s.unit().clone(),
        multiplexed_by,
        is_multiplexor,
        labels,
    }
}

/// A signal's bits lie inside its message's `size` bytes and its size suits its encoding.
fn check_fits(s: &Signal, size: usize) -> Result<(), String> {
    let bits = size as u32 * 8;
    match s.encoding {
        Encoding::Float32 if s.size != 32 => return Err("an IEEE float is 32 bits".into()),
        Encoding::Float64 if s.size != 64 => return Err("an IEEE double is 64 bits".into()),
        _ if s.size == 0 || s.size > 64 => return Err(format!("{} bits: 1 to 64", s.size)),
        _ => {}
    }
    let positions = bit_positions(s.start_bit, s.size, s.little_endian);
    match positions.iter().find(|&&p| p >= bits) {
        Some(_) => Err(format!(
            "its {} bits from bit {} run past the message's {size} bytes",
            s.size, s.start_bit
        )),
        None => Ok(()),
    }
}

/// The frame bit positions of a signal, in the order its bits are read.
///
/// Bit `i` of byte `b` is `8b + i`, `i` from the least significant. An Intel (`@1`) signal
/// starts at its least significant bit and runs up; a Motorola (`@0`) one starts at its most
/// significant bit and runs down through the byte, then on to the next byte's most
/// significant bit (the "sawtooth").
pub fn bit_positions(start_bit: u32, size: u32, little_endian: bool) -> Vec<u32> {
    let mut out = Vec::with_capacity(size as usize);
    let mut p = start_bit;
    for _ in 0..size {
        out.push(p);
        p = match little_endian {
            true => p + 1,
            false if p.is_multiple_of(8) => p + 15,
            false => p - 1,
        };
    }
    out
}
