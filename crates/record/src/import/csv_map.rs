//! CSV logs with a column mapping: any logger's table into railfuse channels. The mapping
//! (TOML) names the time column and, per channel, which column fills which message field:
//!
//! ```toml
//! time_column = "t"          # the sensor time of each row
//! time_unit = "s"            # s, ms, us or ns
//! time_offset_ns = 1780300800000000000   # added to it (the run's start, for relative times)
//! delimiter = ","            # default ","
//!
//! [[channel]]
//! topic = "/radar/speed"     # the type follows from standard topics, or give `type`
//! fields = { speed_mps = "v_radar" }
//! constants = { quality = 1.0, valid = true }
//! ```
//!
//! A row with an empty cell for a channel's field gives no message on that channel (loggers
//! leave cells empty when a sensor had nothing new); a cell that does not parse, or a message
//! that does not validate, is counted with its line.

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_catalog::log::LogWriter;
use serde::Deserialize;
use serde_json::Value;

use super::ImportReport;
use crate::error::{MappingError, Result};
use crate::recorder::message::{from_object, ItemWriter};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CsvMapping {
    pub time_column: String,
    #[serde(default = "default_unit")]
    pub time_unit: String,
    #[serde(default)]
    pub time_offset_ns: u64,
    #[serde(default = "default_delimiter")]
    pub delimiter: String,
    pub channel: Vec<ChannelMapping>,
}

fn default_unit() -> String {
    "s".into()
}
fn default_delimiter() -> String {
    ",".into()
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelMapping {
    pub topic: String,
    #[serde(default, rename = "type")]
    pub type_name: Option<String>,
    /// Message field → column name.
    pub fields: BTreeMap<String, String>,
    #[serde(default)]
    pub constants: BTreeMap<String, toml::Value>,
}

/// A cell as JSON: a number when it parses as one, a boolean for true/false, else text.
fn cell(text: &str) -> Value {
    let t = text.trim();
    if let Ok(x) = t.parse::<f64>() {
        return serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number);
    }
    match t {
        "true" | "TRUE" => Value::Bool(true),
        "false" | "FALSE" => Value::Bool(false),
        _ => Value::String(t.to_owned()),
    }
}

pub fn import(input: &Path, mapping_path: &Path, output: &Path) -> Result<ImportReport> {
    let text = std::fs::read_to_string(mapping_path).map_err(|source| MappingError::Read {
        path: mapping_path.to_owned(),
        source,
    })?;
    let map: CsvMapping = toml::from_str(&text).map_err(|source| MappingError::Toml {
        path: mapping_path.to_owned(),
        source,
    })?;
    let scale: f64 = match map.time_unit.as_str() {
        "s" => 1e9,
        "ms" => 1e6,
        "us" => 1e3,
        "ns" => 1.0,
        u => {
            return Err(MappingError::TimeUnit {
                path: mapping_path.to_owned(),
                unit: u.to_owned(),
            }
            .into())
        }
    };
    let delimiter = match map.delimiter.as_bytes() {
        [d] => *d,
        _ => {
            return Err(MappingError::Delimiter {
                path: mapping_path.to_owned(),
                delimiter: map.delimiter.clone(),
            }
            .into())
        }
    };
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .flexible(true)
        .from_path(input)
        .map_err(|source| MappingError::Csv {
            path: input.to_owned(),
            source,
        })?;
    let headers = reader
        .headers()
        .map_err(|source| MappingError::Csv {
            path: input.to_owned(),
            source,
        })?
        .clone();
    let column = |what: String, name: &str| {
        headers
            .iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| MappingError::NoColumn {
                mapping: mapping_path.to_owned(),
                input: input.to_owned(),
                what,
                column: name.to_owned(),
            })
    };
    let time_col = column("time_column".into(), &map.time_column)?;
    let mut channels = Vec::new();
    for c in &map.channel {
        let mut cols = Vec::new();
        for (field, col) in &c.fields {
            let i = column(format!("channel {}: column", c.topic), col)?;
            cols.push((field.clone(), i));
        }
        let constants: Vec<(String, Value)> = c
            .constants
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::to_value(v).unwrap_or(Value::Null)))
            .collect();
        channels.push((c, cols, constants));
    }
    let mut report = ImportReport {
        input: input.to_owned(),
        output: output.to_owned(),
        format: "csv".into(),
        time_base: format!(
            "column '{}' in {} + {} ns",
            map.time_column, map.time_unit, map.time_offset_ns
        ),
        ..Default::default()
    };
    let mut writer = ItemWriter::new(LogWriter::create(output)?);
    for (row, record) in reader.records().enumerate() {
        let line = row as u64 + 2;
        report.lines += 1;
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                report.skip(line, "unreadable row", e);
                continue;
            }
        };
        let t = record.get(time_col).unwrap_or("").trim();
        let Some(stamp) = t
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && *x >= 0.0)
            .map(|x| (x * scale) as u64 + map.time_offset_ns)
        else {
            report.skip(line, "bad time", t);
            continue;
        };
        for (c, cols, constants) in &channels {
            if cols
                .iter()
                .any(|(_, i)| record.get(*i).is_none_or(|v| v.trim().is_empty()))
            {
                continue;
            }
            let mut obj = serde_json::Map::new();
            obj.insert("topic".into(), Value::from(c.topic.clone()));
            if let Some(ty) = &c.type_name {
                obj.insert("type".into(), Value::from(ty.clone()));
            }
            obj.insert("stamp_ns".into(), Value::from(stamp));
            for (field, i) in cols {
                obj.insert(field.clone(), cell(record.get(*i).unwrap_or("")));
            }
            for (k, v) in constants {
                obj.insert(k.clone(), v.clone());
            }
            match from_object(obj, stamp) {
                Ok(item) => {
                    writer.write(&item)?;
                    report.messages += 1;
                    *report.per_topic.entry(item.topic).or_insert(0) += 1;
                }
                Err(e) => report.skip(line, "row does not make a valid message", e),
            }
        }
    }
    writer.writer.finish()?;
    Ok(report)
}
