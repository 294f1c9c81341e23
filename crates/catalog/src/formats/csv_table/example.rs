//! A mapping with a channel of every message type a table row can carry, and a CSV it reads:
//! a start for a logger's own mapping (`railfuse import --example-map DIR`).

use serde_json::Value;

use crate::messages::MessageKind;

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
    use crate::topics;
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
