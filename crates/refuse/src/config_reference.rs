//! The pipeline configuration described from its own types: a JSON schema (schemars, from
//! the same structs and doc comments serde reads the file with, each registered kind's
//! settings table included) and the reference page of the book rendered from that schema, so
//! that neither can drift from the code. Editors that read JSON schemas for TOML (Taplo, Even
//! Better TOML) complete and check a configuration with [`schema`].

use schemars::generate::SchemaSettings;
use serde_json::{Map, Value};

use crate::config::PipelinesFile;
use crate::registry::Registry;

/// The JSON schema of a configuration file whose kinds are those of `registry`.
pub fn schema(registry: &Registry) -> Value {
    let mut g = SchemaSettings::draft2020_12()
        .with(|s| s.inline_subschemas = true)
        .into_generator();
    let mut root = g.root_schema_for::<PipelinesFile>().to_value();
    let kinds: Vec<(&str, Value)> = registry
        .kinds()
        .map(|k| {
            let mut table = k.settings_schema(&mut g).to_value();
            let why = format!(
                "`filter = \"{}\"`: its settings (every key has a default).",
                k.name()
            );
            let described = table.get("description").and_then(Value::as_str);
            let text = described.map_or(why.clone(), |d| format!("{why} {d}"));
            table["description"] = Value::String(text);
            (k.section(), table)
        })
        .collect();
    let pipeline = &mut root["properties"]["pipeline"]["items"]["properties"];
    for (section, table) in kinds {
        pipeline[section] = table;
    }
    root
}

/// The reference page (Markdown): one table per TOML table, each key with its type, its
/// default and its doc comment.
pub fn markdown(registry: &Registry) -> String {
    let schema = schema(registry);
    let mut out = String::from(
        "# Configuration reference\n\n\
         Generated from the configuration types by `railfuse refuse --config-schema`'s \
         schema (tests/docs.rs checks it is current; `RAILFUSE_BLESS=1 cargo test --test \
         docs` rewrites it). A key without a default must be given.\n",
    );
    table(&mut out, "the file", &schema, &mut Vec::new());
    out
}

/// One table's rows, then its sub-tables; a table of the same keys as one already written
/// (`done`) refers to it.
fn table(out: &mut String, path: &str, schema: &Value, done: &mut Vec<(Value, String)>) {
    let Some(props) = schema.get("properties").and_then(Value::as_object) else {
        return;
    };
    out.push_str(&format!("\n## {path}\n\n"));
    if let Some((_, first)) = done.iter().find(|(s, _)| s == schema) {
        out.push_str(&format!("The same keys as {first}.\n"));
        return;
    }
    done.push((schema.clone(), path.to_owned()));
    if let Some(d) = schema.get("description").and_then(Value::as_str) {
        out.push_str(&format!("{}\n\n", one_line(d)));
    }
    out.push_str("| key | type | default | meaning |\n|---|---|---|---|\n");
    let mut nested = Vec::new();
    for (key, p) in props {
        let default = p.get("default").or_else(|| {
            schema
                .get("default")
                .and_then(|d| d.get(key))
                .filter(|v| !v.is_null())
        });
        let row = [
            format!("`{key}`"),
            type_of(p),
            default.map_or(String::new(), |d| format!("`{}`", compact(d))),
            p.get("description")
                .and_then(Value::as_str)
                .map_or(String::new(), one_line),
        ];
        out.push_str(&format!("| {} |\n", row.join(" | ").replace('\n', " ")));
        let sub = match prefix(path) {
            "" => key.clone(),
            pre => format!("{pre}.{key}"),
        };
        if let Some(items) = p.get("items").filter(|i| i.get("properties").is_some()) {
            nested.push((format!("[[{sub}]]"), items.clone()));
        } else if p.get("properties").is_some() {
            nested.push((format!("[{sub}]"), p.clone()));
        }
        for v in variants(p) {
            if let Some(props) = v.get("properties") {
                let form = tag_of(props).map_or(String::new(), |t| format!(" with {t}"));
                nested.push((format!("[{sub}]{form}"), v.clone()));
            } else if let Some(items) = v.get("items").filter(|i| i.get("properties").is_some()) {
                nested.push((format!("[[{sub}]]"), items.clone()));
            }
        }
        // A map of tables by name (`[sensor."/gnss/fix"]`).
        if let Some(values) = p
            .get("additionalProperties")
            .filter(|a| a.get("properties").is_some())
        {
            nested.push((format!("[{sub}.\"<name>\"]"), values.clone()));
        }
    }
    for (path, s) in nested {
        table(out, &path, &s, done);
    }
}

/// `[[pipeline.sensor]]` → `pipeline.sensor`; the top → "".
fn prefix(path: &str) -> &str {
    match path.trim_start_matches('[').split(']').next() {
        Some(p) if path.starts_with('[') => p,
        _ => "",
    }
}

/// The forms of a union, a union's own unions flattened (an optional untagged enum).
fn variants(p: &Value) -> Vec<Value> {
    ["oneOf", "anyOf"]
        .iter()
        .filter_map(|k| p.get(*k).and_then(Value::as_array))
        .flatten()
        .flat_map(|v| match v.get("oneOf").or(v.get("anyOf")) {
            Some(_) => variants(v),
            None => vec![v.clone()],
        })
        .collect()
}

/// What the key takes: a type, the values of an enumeration, or the forms of a union.
fn type_of(p: &Value) -> String {
    if let Some(values) = p.get("enum").and_then(Value::as_array) {
        return values.iter().map(compact).collect::<Vec<_>>().join(" \\| ");
    }
    if let Some(c) = p.get("const") {
        return compact(c);
    }
    let forms = variants(p);
    if !forms.is_empty() {
        let names: Vec<String> = forms
            .iter()
            .filter(|v| v.get("type") != Some(&Value::String("null".into())))
            .map(|v| match v.get("properties") {
                Some(props) => tag_of(props).unwrap_or_else(|| "table".into()),
                None => type_of(v),
            })
            .collect();
        return names.join(" \\| ");
    }
    let types: Vec<&str> = match p.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    let types: Vec<String> = types
        .into_iter()
        .filter(|t| *t != "null")
        .map(|t| match (t, p.get("items")) {
            ("array", Some(items)) => format!("array of {}", type_of(items)),
            ("object", _) if p.get("properties").is_some() => "table".into(),
            _ => t.to_owned(),
        })
        .collect();
    if types.is_empty() {
        "any".into()
    } else {
        types.join(" or ")
    }
}

/// A tagged form's tag (`model = "singer"`), if it has one.
fn tag_of(props: &Value) -> Option<String> {
    let props: &Map<String, Value> = props.as_object()?;
    props.iter().find_map(|(k, v)| {
        let c = v
            .get("const")
            .or_else(|| v.get("enum").and_then(|e| e.get(0)))?;
        Some(format!("{k} = {}", compact(c)))
    })
}

fn compact(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        other => other.to_string(),
    }
}

/// A doc comment as one table cell: its paragraphs on one line.
fn one_line(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}
