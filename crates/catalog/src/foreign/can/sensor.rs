//! A sensor mapped from CAN signals: which message makes it, what it reads, and the signals
//! of `"can:Message.Signal"` found in the buses' DBCs.

use railfuse_can::dbc::{BusDbcs, Signal};

use super::assembled::{GnssSignals, ImuSignals, Latest, MessageKey, SignalAt};
use super::pulse_counter::PulseCounter;
use super::settings::MappingError;
use crate::messages::MessageKind;

/// A signal of the mapped message, by name.
#[derive(Debug, Clone)]
pub(super) struct SignalRef {
    pub name: String,
    /// To SI units.
    pub scale: f64,
}

pub(super) struct Mapped {
    pub topic: String,
    pub kind: MessageKind,
    /// The message whose frame makes the sensor's message.
    pub message: MessageKey,
    pub reading: Reading,
    pub valid: Option<SignalRef>,
    pub quality: Option<SignalRef>,
    /// Signals of several messages (a fix, an IMU): their latest values.
    pub latest: Latest,
}

/// What the sensor's main signal is.
pub(super) enum Reading {
    Speed(SignalRef),
    Pulses {
        signal: SignalRef,
        counter: PulseCounter,
        per_revolution: u32,
        diameter_m: f64,
    },
    Gnss(Box<GnssSignals>),
    Imu(Box<ImuSignals>),
}

impl Reading {
    pub fn signal(&self) -> Option<&SignalRef> {
        match self {
            Reading::Speed(s) | Reading::Pulses { signal: s, .. } => Some(s),
            Reading::Gnss(_) | Reading::Imu(_) => None,
        }
    }

    /// The signals of several messages it reads.
    pub fn assembled(&self) -> Box<dyn Iterator<Item = &SignalAt> + '_> {
        match self {
            Reading::Gnss(g) => Box::new(g.signals()),
            Reading::Imu(i) => Box::new(i.signals()),
            _ => Box::new(std::iter::empty()),
        }
    }
}

/// The message key and the signal of `"can:Message.Signal"` (or `"can:BUS/Message.Signal"`
/// where two buses' DBCs have that message).
pub(super) fn find_signal<'a>(
    dbs: &'a BusDbcs,
    topic: &str,
    key: &'static str,
    given: &str,
) -> Result<(MessageKey, &'a Signal), MappingError> {
    let err = |cause: String| MappingError::Signal {
        topic: topic.into(),
        key,
        given: given.into(),
        cause,
    };
    let path = given
        .strip_prefix("can:")
        .ok_or_else(|| err("write it as \"can:Message.Signal\"".into()))?;
    let (bus, path) = match path.split_once('/') {
        Some((bus, rest)) => (Some(bus), rest),
        None => (None, path),
    };
    let (message, signal) = path
        .split_once('.')
        .ok_or_else(|| err("write it as \"can:Message.Signal\"".into()))?;
    let found: Vec<(usize, &railfuse_can::dbc::Message)> = dbs
        .0
        .iter()
        .enumerate()
        .filter(|(_, (b, _))| bus.is_none() || b.as_deref() == bus)
        .filter_map(|(i, (_, db))| Some((i, db.messages.values().find(|m| m.name == message)?)))
        .collect();
    let (dbi, m) = match found[..] {
        [] => return Err(err(format!("no DBC has a message {message}"))),
        [one] => one,
        _ => {
            return Err(err(format!(
                "two buses' DBCs have a message {message}: write \"can:BUS/{message}.{signal}\""
            )))
        }
    };
    let s = m
        .signals
        .iter()
        .find(|s| s.name == signal)
        .ok_or_else(|| err(format!("message {message} has no signal {signal}")))?;
    Ok(((dbi, m.id, m.extended), s))
}
