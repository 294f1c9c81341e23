//! Loggers' CSV tables with a column mapping (TOML): any logger's table into railfuse
//! channels. The mapping says how a row's time is read, what each column's numbers are in,
//! and which column fills which field of which channel's message:
//!
//! ```toml
//! delimiter = ","            # ";" and tabs too; a BOM and CRLF line ends are read as well
//! decimal = "."              # "," for a decimal comma (with another delimiter)
//!
//! [time]                     # a GNSS logger that writes the date and time in six columns
//! columns = ["Year", "Month", "Day", "Hour", "Minute", "Second"]
//! format = "%Y %m %d %H %M %S"   # the columns joined by a space, read strftime-like
//! zone = "UTC"               # or "+02:00", or an IANA name ("Europe/Zurich", DST included)
//! spread = "rate"            # rows of one whole second: k-th at k / rate_hz (or "evenly")
//! rate_hz = 5
//!
//! [columns]                  # what a column's numbers are in: cell × scale + offset, in unit
//! Lat = { scale = 1e-7 }
//! Alt1 = { unit = "mm" }
//! speed = { unit = "mm/s" }
//!
//! [[channel]]
//! topic = "/gnss/fix"        # the type follows from standard topics, or give `type`
//! fields = { latitude_deg = "Lat", altitude_m = "Alt1", speed_mps = "speed" }
//! constants = { fix_type = "single" }
//! ```
//!
//! A number's `unit` is turned into the unit of the field it fills, which the field's name
//! states (`_m`, `_mps`, `_mps2`, `_deg`, `_rad`, `_radps`): `km/h` into `speed_mps`, `g` into
//! `specific_force_mps2[0]`. A time is one column of numbers (`column`, `unit` s/ms/us/ns since
//! the epoch, plus `offset_ns` for relative times; the short form `time_column = "t"`,
//! `time_unit`, `time_offset_ns` at the top says the same) or a civil time in one or several
//! columns read with a `format` in a `zone`. A channel may read its own `time` (a phone's fix
//! time beside the rows of its IMU).
//!
//! A GNSS fix takes two fields no message has: `horizontal_accuracy_m` and
//! `vertical_accuracy_m` (a receiver's hAcc/vAcc, a phone's accuracy) become its position
//! covariance, each read as a radius holding the position with the channel's
//! `accuracy_confidence` (by default one σ per axis; 0.68 for phones).
//!
//! A row with an empty cell for a channel's field gives no message on that channel (loggers
//! leave cells empty when a sensor had nothing new). A cell that does not read, a message
//! that does not validate, and a row not after the channel's one before (out of order, or a
//! repeat: a phone's fix repeated on every IMU row) are counted with their line, not written.

pub mod example;
pub mod mapping;
mod time;

use std::path::Path;

use serde_json::Value;

use self::mapping::{ChannelMapping, CsvMapping, MappingFile};
use self::time::{Clock, SecondSpreader};
use super::{accuracy, Converted};
use crate::error::{Error, Result};
use crate::log::{ChannelId, LogWriter, WriterOptions};
use crate::messages::MessageKind;
use crate::topics;

/// The fields of a GNSS fix that a table gives as accuracies, turned into its covariance.
const ACCURACY_FIELDS: [&str; 2] = ["horizontal_accuracy_m", "vertical_accuracy_m"];

/// Converts a CSV table to MCAP at `output`, streaming, as `mapping` says.
pub fn convert(
    input: &Path,
    output: &Path,
    mapping: &MappingFile,
    writer: &WriterOptions,
) -> Result<Converted> {
    let map = &mapping.mapping;
    let csv_error = |e: csv::Error| Error::run(input, e);
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(map.delimiter_byte())
        .flexible(true)
        .from_path(input)
        .map_err(csv_error)?;
    let headers = reader.headers().map_err(csv_error)?.clone();
    let mut writer = LogWriter::create_with(output, writer)?;
    let mut table = Table::bind(mapping, input, &headers, &mut writer)?;
    let mut report = Converted::default();
    let mut record = csv::StringRecord::new();
    loop {
        let line = reader.position().line();
        match reader.read_record(&mut record) {
            Ok(true) => table.row(line, &record, &mut writer, &mut report)?,
            Ok(false) => break,
            Err(e) => {
                report.rows += 1;
                report.skip("unreadable row", format!("line {line}: {e}"));
            }
        }
    }
    table.finish(&mut writer, &mut report)?;
    if report.messages == 0 {
        let why = match report.rows {
            0 => "no rows under the header".to_owned(),
            n => format!("none of its {n} rows made a message: {}", report.reasons()),
        };
        return Err(Error::run(input, why));
    }
    writer.finish()?;
    Ok(report)
}

/// A mapping bound to a file's header: every column found, every channel opened.
pub(crate) struct Table {
    clock: Option<Clock>,
    spreader: Option<SecondSpreader>,
    decimal_comma: bool,
    channels: Vec<Channel>,
    /// The first row that went back in time on a channel: (line, topic).
    first_backwards: Option<(u64, String)>,
}

/// One mapped channel.
struct Channel {
    topic: String,
    kind: MessageKind,
    id: ChannelId,
    clock: Option<Clock>,
    fields: Vec<Field>,
    constants: Vec<(String, Value)>,
    accuracy_confidence: Option<f64>,
    last_ns: Option<u64>,
}

/// A field, its column, and the factor and offset that bring the column's numbers to the
/// field's unit (`None`: the cell as it is, text or number).
struct Field {
    name: String,
    column: usize,
    linear: Option<(f64, f64)>,
}

impl Table {
    pub(crate) fn bind(
        mapping: &MappingFile,
        input: &Path,
        headers: &csv::StringRecord,
        writer: &mut LogWriter,
    ) -> Result<Self> {
        let map = &mapping.mapping;
        let fault = |cause: String| {
            Error::run(
                &mapping.path,
                format!("{cause} (mapping for {})", input.display()),
            )
        };
        let column = |name: &str| {
            headers
                .iter()
                .position(|h| h.trim() == name)
                .ok_or_else(|| {
                    let have: Vec<&str> = headers.iter().map(str::trim).take(40).collect();
                    format!("no column '{name}' in the header ({})", have.join(", "))
                })
        };
        let clock = map
            .time
            .as_ref()
            .map(|t| Clock::new(t, column))
            .transpose()
            .map_err(fault)?;
        let spreader = map
            .time
            .as_ref()
            .and_then(|t| t.spread.map(|s| SecondSpreader::new(s, t.rate_hz)))
            .transpose()
            .map_err(fault)?;
        let mut channels: Vec<Channel> = Vec::new();
        for c in &map.channel {
            if c.time.is_none() && clock.is_none() {
                return Err(fault(format!(
                    "channel {}: no time (give `[time]` or the channel's own `time`)",
                    c.topic
                )));
            }
            if channels.iter().any(|b| b.topic == c.topic) {
                return Err(fault(format!("channel {} is mapped twice", c.topic)));
            }
            let bound = Channel::bind(c, map, &column, writer)
                .map_err(|e| fault(format!("channel {}: {e}", c.topic)))?;
            channels.push(bound);
        }
        Ok(Self {
            clock,
            spreader,
            decimal_comma: map.decimal == ",",
            channels,
            first_backwards: None,
        })
    }

    /// One row read: written at once, or held until its whole second is complete.
    pub(crate) fn row(
        &mut self,
        line: u64,
        record: &csv::StringRecord,
        writer: &mut LogWriter,
        report: &mut Converted,
    ) -> Result<()> {
        report.rows += 1;
        let stamp = self
            .clock
            .as_ref()
            .map(|c| c.stamp(record, self.decimal_comma));
        let (Some(spreader), Some(stamp)) = (self.spreader.as_mut(), stamp.clone()) else {
            return self.write_row(stamp, line, record, writer, report);
        };
        match stamp {
            Ok(t) => {
                let second = t.div_euclid(1_000_000_000) * 1_000_000_000;
                for (t, line, r) in spreader.push(second, line, record.clone()) {
                    self.write_row(Some(Ok(t)), line, &r, writer, report)?;
                }
            }
            Err(e) => report.skip("bad time", format!("line {line}: {e}")),
        }
        Ok(())
    }

    pub(crate) fn finish(&mut self, writer: &mut LogWriter, report: &mut Converted) -> Result<()> {
        let held = self
            .spreader
            .as_mut()
            .map(|s| s.flush())
            .unwrap_or_default();
        for (t, line, r) in held {
            self.write_row(Some(Ok(t)), line, &r, writer, report)?;
        }
        if let Some((line, topic)) = &self.first_backwards {
            let n: u64 = report
                .skipped
                .iter()
                .filter(|(k, _)| k.starts_with("a row earlier"))
                .map(|(_, n)| n)
                .sum();
            report.warnings.push(format!(
                "time goes backwards on {topic} at line {line}: {n} rows out of order were not written (is the time column the right one, the file sorted?)"
            ));
        }
        Ok(())
    }

    /// A row's message on every channel whose cells it has. `table_ns` is the row's time by
    /// the table's clock (None where the table has none).
    fn write_row(
        &mut self,
        table_ns: Option<std::result::Result<i128, String>>,
        line: u64,
        record: &csv::StringRecord,
        writer: &mut LogWriter,
        report: &mut Converted,
    ) -> Result<()> {
        let mut bad_time_said = false;
        for c in &mut self.channels {
            if !c.has_cells(record) {
                continue;
            }
            let stamp = match &c.clock {
                Some(own) => own.stamp(record, self.decimal_comma),
                None => table_ns.clone().unwrap_or(Err("no time".into())),
            };
            let stamp = stamp.and_then(|t| {
                u64::try_from(t).map_err(|_| format!("{t} ns is before 1970 or too late"))
            });
            let stamp = match stamp {
                Ok(t) => t,
                Err(e) => {
                    if !std::mem::replace(&mut bad_time_said, true) || c.clock.is_some() {
                        report.skip("bad time", format!("line {line}: {e}"));
                    }
                    continue;
                }
            };
            let written = c.write(stamp, line, record, self.decimal_comma, writer, report)?;
            if written == Some(false) && self.first_backwards.is_none() {
                self.first_backwards = Some((line, c.topic.clone()));
            }
        }
        Ok(())
    }
}

impl Channel {
    fn bind(
        c: &ChannelMapping,
        map: &CsvMapping,
        column: &impl Fn(&str) -> std::result::Result<usize, String>,
        writer: &mut LogWriter,
    ) -> std::result::Result<Self, String> {
        let kind = match &c.type_name {
            Some(t) => {
                MessageKind::from_type_name(t).ok_or_else(|| format!("unknown type '{t}'"))?
            }
            None => topics::standard_kind(&c.topic)
                .ok_or_else(|| format!("{} is not a standard topic: give its `type`", c.topic))?,
        };
        let mut fields = Vec::new();
        for (name, col) in &c.fields {
            if ACCURACY_FIELDS.contains(&name.as_str()) && kind != MessageKind::GnssFix {
                return Err(format!("`{name}` is a GNSS fix's field"));
            }
            fields.push(Field {
                name: name.clone(),
                column: column(col)?,
                linear: linear(map, col, name)?,
            });
        }
        let constants = c
            .constants
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::to_value(v).unwrap_or(Value::Null)))
            .collect();
        let clock = c.time.as_ref().map(|t| Clock::new(t, column)).transpose()?;
        let id = writer
            .add_channel_of(kind, &c.topic)
            .map_err(|e| e.to_string())?;
        Ok(Self {
            topic: c.topic.clone(),
            kind,
            id,
            clock,
            fields,
            constants,
            accuracy_confidence: c.accuracy_confidence,
            last_ns: None,
        })
    }

    fn has_cells(&self, record: &csv::StringRecord) -> bool {
        self.fields
            .iter()
            .all(|f| record.get(f.column).is_some_and(|v| !v.trim().is_empty()))
    }

    /// Writes the row's message at `stamp`: `Some(true)` written, `Some(false)` not after
    /// the one before, `None` not a message.
    fn write(
        &mut self,
        stamp: u64,
        line: u64,
        record: &csv::StringRecord,
        decimal_comma: bool,
        writer: &mut LogWriter,
        report: &mut Converted,
    ) -> Result<Option<bool>> {
        let message = match self.message(stamp, record, decimal_comma) {
            Ok(m) => m,
            Err(e) => {
                report.skip(
                    "row does not make a valid message",
                    format!("line {line}: {}: {e}", self.topic),
                );
                return Ok(None);
            }
        };
        match self.last_ns {
            Some(last) if stamp == last => {
                report.skip(
                    "a row at the time of the one before",
                    format!("line {line}: {}", self.topic),
                );
                return Ok(None);
            }
            Some(last) if stamp < last => {
                report.skip(
                    "a row earlier than the one before",
                    format!("line {line}: {}", self.topic),
                );
                return Ok(Some(false));
            }
            _ => {}
        }
        self.last_ns = Some(stamp);
        writer.write_any(self.id, stamp, &message)?;
        report.count(&self.topic);
        Ok(Some(true))
    }

    fn message(
        &self,
        stamp: u64,
        record: &csv::StringRecord,
        decimal_comma: bool,
    ) -> std::result::Result<crate::messages::AnyMessage, String> {
        let mut obj = serde_json::Map::new();
        obj.insert("stamp_ns".into(), Value::from(stamp));
        let mut accuracies = [None, None];
        for f in &self.fields {
            let text = record.get(f.column).unwrap_or("").trim();
            let value = f.value(text, decimal_comma)?;
            match ACCURACY_FIELDS.iter().position(|a| *a == f.name) {
                Some(i) => accuracies[i] = value.as_f64(),
                None => put(&mut obj, &f.name, value),
            }
        }
        for (k, v) in &self.constants {
            obj.insert(k.clone(), v.clone());
        }
        if let Some(h) = accuracies[0].filter(|h| *h > 0.0) {
            let v = accuracies[1].filter(|v| *v > 0.0);
            let c = accuracy::covariance_enu(h, v, self.accuracy_confidence);
            obj.insert("position_covariance_enu_m2".into(), Value::from(c.to_vec()));
        }
        self.kind
            .from_value(Value::Object(obj))
            .map_err(|e| e.to_string())
    }
}

impl Field {
    /// A cell as JSON: a number through the column's scale, offset and unit; else a whole
    /// number stays an integer (a count must not arrive as 1.0), a flag a boolean, the rest
    /// text.
    fn value(&self, text: &str, decimal_comma: bool) -> std::result::Result<Value, String> {
        let number = |t: &str| -> Option<f64> {
            let t = if decimal_comma {
                t.replace(',', ".")
            } else {
                t.to_owned()
            };
            t.parse::<f64>().ok().filter(|x| x.is_finite())
        };
        if let Some((factor, offset)) = self.linear {
            let x =
                number(text).ok_or_else(|| format!("{}: '{text}' is not a number", self.name))?;
            return Ok(json_number(x * factor + offset));
        }
        if let Ok(n) = text.parse::<i64>() {
            return Ok(Value::from(n));
        }
        if let Some(x) = number(text) {
            return Ok(json_number(x));
        }
        Ok(match text {
            "true" | "TRUE" | "True" => Value::Bool(true),
            "false" | "FALSE" | "False" => Value::Bool(false),
            _ => Value::String(text.to_owned()),
        })
    }
}

/// A number as JSON: whole values as integers (a satellite count scaled by 1 is still one).
fn json_number(x: f64) -> Value {
    if x.fract() == 0.0 && x.abs() < 9.0e15 {
        Value::from(x as i64)
    } else {
        serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number)
    }
}

/// The factor and offset that take column `col`'s numbers into `field`'s unit, where the
/// mapping states what the column is in.
fn linear(
    map: &CsvMapping,
    col: &str,
    field: &str,
) -> std::result::Result<Option<(f64, f64)>, String> {
    let Some(spec) = map.columns.get(col) else {
        return Ok(None);
    };
    let to_field = match &spec.unit {
        None => 1.0,
        Some(unit) => {
            let (units, what) = crate::units::of_field(field).ok_or_else(|| {
                format!(
                    "column {col} is in '{unit}', but field {field} states no unit to turn it into"
                )
            })?;
            crate::units::factor(units, unit, what).map_err(|e| format!("column {col} {e}"))?
        }
    };
    Ok(Some((spec.scale * to_field, spec.offset * to_field)))
}

/// Sets `field` of `obj` to `value`; `name[i]` sets element i of the array `name` (holes
/// stay null, which the message's validation refuses).
fn put(obj: &mut serde_json::Map<String, Value>, field: &str, value: Value) {
    let indexed = field
        .strip_suffix(']')
        .and_then(|f| f.split_once('['))
        .and_then(|(name, i)| Some((name, i.parse::<usize>().ok().filter(|i| *i < 64)?)));
    let Some((name, i)) = indexed else {
        obj.insert(field.to_owned(), value);
        return;
    };
    let slot = obj
        .entry(name.to_owned())
        .or_insert_with(|| Value::Array(Vec::new()));
    if let Value::Array(items) = slot {
        if items.len() <= i {
            items.resize(i + 1, Value::Null);
        }
        items[i] = value;
    }
}

#[cfg(test)]
mod tests;
