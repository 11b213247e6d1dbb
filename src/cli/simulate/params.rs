//! `--params FILE`: the params a fit found, read from the JSON that `gbc train` writes
//! (`run.json` or its `--json` file: `"params": [{"name": .., "value": ..}]`) or that
//! `gbc diagnose --json` writes (`"fitted_params": {name: value}`; with `--effect NAME`,
//! the params refitted with that effect, `"effects": [{"name": NAME, "params": {..}}]`).
//!
//! Every param of the model named in the file takes the file's value as its initial (and,
//! for a model without closures, only) value; params the file does not name keep their
//! guess and names the model does not have are ignored, each said in a note.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use super::{CommandError, SimulateError};
use crate::ir::Model;

/// Sets the params of `model` from `path`; returns the notes to print.
pub fn apply(
    model: &mut Model,
    path: &Path,
    effects: &[&str],
) -> Result<Vec<String>, CommandError> {
    let bad = |reason: String| {
        CommandError::user(SimulateError::BadParams {
            path: path.display().to_string(),
            reason,
        })
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(crate::io::describe(&e)))?;
    let json: Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let values = read(&json, effects).map_err(bad)?;
    let mut notes = Vec::new();
    let mut matched = 0;
    for param in &mut model.params {
        match values.get(&param.name) {
            Some(&value) => {
                param.init = value;
                matched += 1;
            }
            None => notes.push(format!(
                "param `{}` is not in `{}`: it keeps its guess {}",
                param.name,
                path.display(),
                param.init
            )),
        }
    }
    let unknown: Vec<&str> = (values.keys())
        .filter(|name| !model.params.iter().any(|p| &p.name == *name))
        .map(String::as_str)
        .collect();
    if !unknown.is_empty() {
        notes.push(format!(
            "`{}` has params the model does not: {} (ignored)",
            path.display(),
            unknown.join(", ")
        ));
    }
    if matched == 0 && !model.params.is_empty() {
        return Err(bad(format!(
            "expected values of the model's params ({}), found none",
            (model.params.iter().map(|p| p.name.as_str()))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(notes)
}

/// The params of a train or diagnose JSON document, by name.
fn read(json: &Value, effects: &[&str]) -> Result<BTreeMap<String, f64>, String> {
    if let Some(list) = json.get("params").and_then(Value::as_array) {
        let mut values = BTreeMap::new();
        for entry in list {
            let name = entry.get("name").and_then(Value::as_str);
            let value = entry.get("value").map(number);
            match (name, value) {
                (Some(name), Some(Ok(value))) => values.insert(name.to_string(), value),
                _ => {
                    return Err(format!(
                        "expected `{{\"name\": .., \"value\": ..}}` in `params`, found `{entry}`"
                    ))
                }
            };
        }
        return Ok(values);
    }
    let map = match effects {
        [] => json.get("fitted_params"),
        [effect] => (json.get("effects").and_then(Value::as_array))
            .and_then(|list| {
                list.iter()
                    .find(|e| e.get("name").and_then(Value::as_str) == Some(effect))
            })
            .and_then(|e| e.get("params")),
        _ => {
            return Err("expected at most one --effect with a diagnosis file, found several".into())
        }
    };
    let Some(Value::Object(map)) = map else {
        return Err(match effects {
            [] => "expected `params` (gbc train) or `fitted_params` (gbc diagnose), found neither"
                .into(),
            _ => format!(
                "expected the effect `{}` among the diagnosis's `effects`, found none",
                effects[0]
            ),
        });
    };
    (map.iter())
        .map(|(name, value)| Ok((name.clone(), number(value)?)))
        .collect()
}

/// A number as gbc writes one: a JSON number, or `"inf"`, `"-inf"`, `"nan"`.
fn number(value: &Value) -> Result<f64, String> {
    match value {
        Value::Number(n) => n
            .as_f64()
            .ok_or_else(|| format!("expected a number, found `{n}`")),
        Value::String(text) => crate::json::parse_name(text)
            .ok_or_else(|| format!("expected a number, found `{text}`")),
        other => Err(format!("expected a number, found `{other}`")),
    }
}
