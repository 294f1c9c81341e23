//! Field-by-field conversion between a catalogue type and its prost message. A catalogue
//! type's protobuf fields carry its JSON field names, so its [`ProtobufForm`] is the list of
//! those names: [`protobuf_form!`] writes it, and [`Wire`] converts each field by its type
//! (a fixed-size array travels as a repeated field that must have its length, a required
//! nested message must be present). [`protobuf_enum!`] maps an enum name for name.

use std::collections::BTreeMap;

use super::{fixed, optional_fixed, ProtobufForm};

/// One field's value as prost holds it, and back; `field` names it in an error.
pub trait Wire: Sized {
    type W;
    fn to_wire(&self) -> Self::W;
    fn from_wire(w: Self::W, field: &str) -> Result<Self, String>;
}

/// Types prost holds as they are.
macro_rules! same_on_the_wire {
    ($($t:ty),* $(,)?) => {
        $(
            impl Wire for $t {
                type W = $t;
                fn to_wire(&self) -> $t {
                    self.clone()
                }
                fn from_wire(w: $t, _: &str) -> Result<$t, String> {
                    Ok(w)
                }
            }
        )*
    };
}

same_on_the_wire!(
    u32,
    u64,
    f64,
    bool,
    String,
    Option<u32>,
    Option<u64>,
    Option<f64>,
    Option<bool>,
    Option<String>,
    Vec<String>,
    BTreeMap<String, u64>,
);

/// Protobuf has no 8-bit integer: a `uint32` that must fit.
impl Wire for u8 {
    type W = u32;
    fn to_wire(&self) -> u32 {
        u32::from(*self)
    }
    fn from_wire(w: u32, field: &str) -> Result<u8, String> {
        u8::try_from(w).map_err(|_| format!("{field} is {w}, above 255"))
    }
}

impl<const N: usize> Wire for [f64; N] {
    type W = Vec<f64>;
    fn to_wire(&self) -> Vec<f64> {
        self.to_vec()
    }
    fn from_wire(w: Vec<f64>, field: &str) -> Result<Self, String> {
        fixed(w, field)
    }
}

/// An optional array: no values at all is "absent".
impl<const N: usize> Wire for Option<[f64; N]> {
    type W = Vec<f64>;
    fn to_wire(&self) -> Vec<f64> {
        self.map_or_else(Vec::new, |v| v.to_vec())
    }
    fn from_wire(w: Vec<f64>, field: &str) -> Result<Self, String> {
        optional_fixed(w, field)
    }
}

/// A nested message the type always has (prost holds every message field as an `Option`).
impl<T: ProtobufForm> Wire for T {
    type W = Option<T::Message>;
    fn to_wire(&self) -> Self::W {
        Some(self.to_protobuf())
    }
    fn from_wire(w: Self::W, field: &str) -> Result<Self, String> {
        let m = w.ok_or_else(|| format!("{field} is missing"))?;
        T::from_protobuf(m).map_err(|e| format!("{field}: {e}"))
    }
}

impl<T: ProtobufForm> Wire for Option<T> {
    type W = Option<T::Message>;
    fn to_wire(&self) -> Self::W {
        self.as_ref().map(T::to_protobuf)
    }
    fn from_wire(w: Self::W, field: &str) -> Result<Self, String> {
        w.map(|m| T::from_protobuf(m).map_err(|e| format!("{field}: {e}")))
            .transpose()
    }
}

impl<T: ProtobufForm> Wire for Vec<T> {
    type W = Vec<T::Message>;
    fn to_wire(&self) -> Self::W {
        self.iter().map(T::to_protobuf).collect()
    }
    fn from_wire(w: Self::W, field: &str) -> Result<Self, String> {
        w.into_iter()
            .enumerate()
            .map(|(i, m)| T::from_protobuf(m).map_err(|e| format!("{field}[{i}]: {e}")))
            .collect()
    }
}

/// The [`ProtobufForm`] of a catalogue struct whose protobuf message (of the same name in
/// `railfuse.`) has the same fields: every field is listed, so one left out of either side
/// does not compile.
macro_rules! protobuf_form {
    ($ty:ident { $($field:ident),* $(,)? }) => {
        impl $crate::protobuf::ProtobufForm for $ty {
            type Message = $crate::protobuf::types::$ty;

            fn to_protobuf(&self) -> Self::Message {
                Self::Message {
                    $($field: $crate::protobuf::Wire::to_wire(&self.$field),)*
                }
            }

            fn from_protobuf(m: Self::Message) -> Result<Self, String> {
                Ok($ty {
                    $($field: $crate::protobuf::Wire::from_wire(m.$field, stringify!($field))?,)*
                })
            }
        }
    };
}

/// A catalogue enum and the protobuf enum of the same name, variant for variant (an `int32`
/// on the wire; a value the schema does not know is an error, not a default).
macro_rules! protobuf_enum {
    ($ty:ident { $($name:ident),* $(,)? }) => {
        impl $crate::protobuf::Wire for $ty {
            type W = i32;

            fn to_wire(&self) -> i32 {
                match self {
                    $($ty::$name => $crate::protobuf::types::$ty::$name as i32,)*
                }
            }

            fn from_wire(w: i32, field: &str) -> Result<Self, String> {
                match $crate::protobuf::types::$ty::try_from(w) {
                    $(Ok($crate::protobuf::types::$ty::$name) => Ok($ty::$name),)*
                    Err(_) => Err(format!("{field} is {w}, not a {}", stringify!($ty))),
                }
            }
        }
    };
}

pub(crate) use {protobuf_enum, protobuf_form};
