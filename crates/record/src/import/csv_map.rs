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
//! A field that is an array takes one column per element, `name[i]` (an IMU's
//! `specific_force_mps2[0]` … `[2]`). The fields each message type needs are its JSON schema's
//! required properties: [`example`] writes a mapping with a channel of every type that fits a
//! table row, and a CSV it imports (`railfuse import --example-map DIR`).
//!
//! A row with an empty cell for a channel's field gives no message on that channel (loggers
//! leave cells empty when a sensor had nothing new); a cell that does not parse, or a message
//! that does not validate, is counted with its line.

use std::collections::BTreeMap;
use std::path::Path;

use railfuse_catalog::log::LogWriter;
use railfuse_catalog::messages::MessageKind;
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
    // Whole numbers stay integers: a count or an id must not arrive as 1.0.
    if let Ok(n) = t.parse::<i64>() {
        return Value::from(n);
    }
    if let Ok(x) = t.parse::<f64>() {
        return serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number);
    }
    match t {
        "true" | "TRUE" => Value::Bool(true),
        "false" | "FALSE" => Value::Bool(false),
        _ => Value::String(t.to_owned()),
    }
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

/// The message types a table row can carry (an eddy-current block is a window of samples,
/// a track map a whole line: neither is a row).
pub const EXAMPLE_KINDS: &[MessageKind] = &[
    MessageKind::RadarSpeed,
    MessageKind::Odometer,
    MessageKind::GnssFix,
    MessageKind::Imu,
    MessageKind::LoopPosition,
    MessageKind::BalisePassage,
    MessageKind::GroundTruth,
    MessageKind::Event,
];

/// A mapping with one channel of every type in [`EXAMPLE_KINDS`], each field its schema
/// requires mapped to a column (the optional ones named in a comment), and a CSV of one row
/// that it imports: `(mapping TOML, CSV)`. Made from the types' own JSON schemas, so it names
/// exactly the fields the import validates against.
pub fn example() -> (String, String) {
    let mut toml = String::from(
        "# Every message type a CSV row can carry: each channel maps the fields its type\n\
         # requires to columns; the optional ones are listed under it. Keep the channels you\n\
         # have, rename the columns to your logger's, and delete the rest.\n\
         time_column = \"t\"          # the sensor time of each row\n\
         time_unit = \"s\"            # s, ms, us or ns\n\
         time_offset_ns = 1780300800000000000   # added to each time (the run's start)\n\
         delimiter = \",\"\n",
    );
    let (mut header, mut row) = (vec!["t".to_owned()], vec!["0.5".to_owned()]);
    for &kind in EXAMPLE_KINDS {
        let schema: Value = serde_json::from_slice(&kind.schema_bytes()).unwrap_or_default();
        let required: Vec<&str> = schema["required"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(Value::as_str)
            .filter(|f| *f != "stamp_ns")
            .collect();
        let properties = schema["properties"].as_object();
        let optional: Vec<&str> = properties
            .into_iter()
            .flatten()
            .map(|(k, _)| k.as_str())
            .filter(|k| *k != "stamp_ns" && !required.contains(k))
            .collect();
        let prefix = kind.type_name().to_ascii_lowercase();
        let mut fields = Vec::new();
        for f in &required {
            let property = &schema["properties"][*f];
            let n = property["minItems"]
                .as_u64()
                .filter(|_| property["type"] == "array");
            let names: Vec<String> = match n {
                Some(n) => (0..n).map(|i| format!("{f}[{i}]")).collect(),
                None => vec![(*f).to_owned()],
            };
            for name in names {
                let column = format!("{prefix}_{}", name.replace(['[', ']'], "_"));
                let column = column.trim_end_matches('_').to_owned();
                fields.push(format!("\"{name}\" = \"{column}\""));
                header.push(column);
                row.push(example_value(&schema, property));
            }
        }
        let topic = standard_topic(kind);
        toml += &format!(
            "\n[[channel]]\ntopic = \"{topic}\"\ntype = \"{}\"\nfields = {{ {} }}\n",
            kind.type_name(),
            fields.join(", ")
        );
        if !optional.is_empty() {
            toml += &format!("# optional fields: {}\n", optional.join(", "));
        }
    }
    (toml, format!("{}\n{}\n", header.join(","), row.join(",")))
}

/// The topic a kind travels on in a railfuse log.
fn standard_topic(kind: MessageKind) -> &'static str {
    use railfuse_catalog::topics;
    match kind {
        MessageKind::RadarSpeed => topics::RADAR_SPEED,
        MessageKind::Odometer => topics::ODOMETER_1,
        MessageKind::GnssFix => topics::GNSS_FIX,
        MessageKind::Imu => topics::IMU,
        MessageKind::LoopPosition => topics::LOOP_POSITION,
        MessageKind::BalisePassage => topics::BALISE,
        MessageKind::GroundTruth => topics::GROUND_TRUTH,
        _ => topics::EVENTS,
    }
}

/// A value of a property's type that its schema accepts: the first of an enumeration, else
/// a plain number, integer, flag or word.
fn example_value(schema: &Value, property: &Value) -> String {
    let property = match property["$ref"].as_str() {
        Some(r) => &schema["$defs"][r.rsplit('/').next().unwrap_or("")],
        None => property,
    };
    // An enumeration as schemars writes one: `enum`, or `oneOf` of `enum`s and `const`s.
    fn first(v: &Value) -> Option<&str> {
        v["enum"].get(0).or(v.get("const")).and_then(Value::as_str)
    }
    let first_of = first(property).or_else(|| property["oneOf"].get(0).and_then(first));
    if let Some(v) = first_of {
        return v.to_owned();
    }
    let ty = match &property["type"] {
        Value::Array(types) => types.first().and_then(Value::as_str).unwrap_or(""),
        t => t.as_str().unwrap_or(""),
    };
    match ty {
        "integer" => "1",
        "boolean" => "true",
        "string" => "a",
        _ => "0.5",
    }
    .to_owned()
}

pub fn import(input: &Path, mapping_path: &Path, output: &Path) -> Result<ImportReport> {
    let (map, scale, delimiter) = read_mapping(mapping_path)?;
    let csv_error = |source| MappingError::Csv {
        path: input.to_owned(),
        source,
    };
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .flexible(true)
        .from_path(input)
        .map_err(csv_error)?;
    let headers = reader.headers().map_err(csv_error)?.clone();
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
        let mut columns = Vec::new();
        for (field, col) in &c.fields {
            let i = column(format!("channel {}: column", c.topic), col)?;
            columns.push((field.clone(), i));
        }
        let constants: Vec<(String, Value)> = c
            .constants
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::to_value(v).unwrap_or(Value::Null)))
            .collect();
        channels.push(Bound {
            channel: c,
            columns,
            constants,
        });
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
        for b in &channels {
            b.write_row(&record, stamp, line, &mut writer, &mut report)?;
        }
    }
    writer.writer.finish()?;
    Ok(report)
}

/// The mapping file read and checked: the mapping, the time unit's scale to ns, the delimiter.
fn read_mapping(path: &Path) -> Result<(CsvMapping, f64, u8)> {
    let text = std::fs::read_to_string(path).map_err(|source| MappingError::Read {
        path: path.to_owned(),
        source,
    })?;
    let map: CsvMapping = toml::from_str(&text).map_err(|source| MappingError::Toml {
        path: path.to_owned(),
        source,
    })?;
    let scale: f64 = match map.time_unit.as_str() {
        "s" => 1e9,
        "ms" => 1e6,
        "us" => 1e3,
        "ns" => 1.0,
        u => {
            return Err(MappingError::TimeUnit {
                path: path.to_owned(),
                unit: u.to_owned(),
            }
            .into())
        }
    };
    let delimiter = match map.delimiter.as_bytes() {
        [d] => *d,
        _ => {
            return Err(MappingError::Delimiter {
                path: path.to_owned(),
                delimiter: map.delimiter.clone(),
            }
            .into())
        }
    };
    Ok((map, scale, delimiter))
}

/// A mapped channel with its columns found in the file's header.
struct Bound<'a> {
    channel: &'a ChannelMapping,
    /// Each field and its column.
    columns: Vec<(String, usize)>,
    constants: Vec<(String, Value)>,
}

impl Bound<'_> {
    /// The channel's message of one row, when the row has every one of its columns.
    fn write_row(
        &self,
        record: &csv::StringRecord,
        stamp: u64,
        line: u64,
        writer: &mut ItemWriter,
        report: &mut ImportReport,
    ) -> Result<()> {
        let c = self.channel;
        if self
            .columns
            .iter()
            .any(|(_, i)| record.get(*i).is_none_or(|v| v.trim().is_empty()))
        {
            return Ok(());
        }
        let mut obj = serde_json::Map::new();
        obj.insert("topic".into(), Value::from(c.topic.clone()));
        if let Some(ty) = &c.type_name {
            obj.insert("type".into(), Value::from(ty.clone()));
        }
        obj.insert("stamp_ns".into(), Value::from(stamp));
        for (field, i) in &self.columns {
            put(&mut obj, field, cell(record.get(*i).unwrap_or("")));
        }
        for (k, v) in &self.constants {
            obj.insert(k.clone(), v.clone());
        }
        match from_object(obj, stamp) {
            Ok(item) => {
                let item = writer.write(item)?;
                report.messages += 1;
                *report.per_topic.entry(item.topic.clone()).or_insert(0) += 1;
            }
            Err(e) => report.skip(line, "row does not make a valid message", e),
        }
        Ok(())
    }
}
