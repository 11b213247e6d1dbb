//! Params a fit found, read from the JSON that `gbc train` writes (`run.json` or its
//! `--json` file: [`RunInfo::params`](crate::trained::artifacts::RunInfo::params), read by the
//! same serde type) or that `gbc diagnose --json` writes (`"fitted_params": {name: value}`;
//! with one effect applied, the params refitted with that effect,
//! `"effects": [{"name": NAME, "params": {..}}]`).
//!
//! Every param of the model named in the file takes the file's value as its initial (and,
//! for a model without closures, only) value; params the file does not name keep their
//! guess and names the model does not have are ignored, each said in a note.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::SimulateError;
use crate::ir::Model;
use crate::trained::artifacts::NamedValue;

/// Params by name, numbers as gbc writes them (`"inf"`, `"nan"` for the non-finite).
#[derive(Debug, Deserialize)]
struct ByName(#[serde(with = "crate::json")] BTreeMap<String, f64>);

/// The fields of a train or diagnose document that hold params; the rest is ignored.
#[derive(Debug, Deserialize)]
struct ParamsDocument {
    /// `gbc train`: the trained params (`run.json`'s own type).
    #[serde(default)]
    params: Option<Vec<NamedValue>>,
    /// `gbc diagnose`: the model's params after fitting.
    #[serde(default)]
    fitted_params: Option<ByName>,
    /// `gbc diagnose`: each effect with its params refitted.
    #[serde(default)]
    effects: Option<Vec<EffectParams>>,
}

/// One effect of a diagnosis with the params refitted with it.
#[derive(Debug, Deserialize)]
struct EffectParams {
    /// The effect.
    name: String,
    /// Its fitted params, the effect's own and the model's.
    #[serde(default)]
    params: Option<ByName>,
}

/// Sets the params of `model` from the file at `path` (`effects`: those applied to the
/// model, which pick a diagnosis's refit); returns the notes to show.
pub fn apply(
    model: &mut Model,
    path: &Path,
    effects: &[String],
) -> Result<Vec<String>, SimulateError> {
    let bad = |reason: String| SimulateError::BadParams {
        path: path.display().to_string(),
        reason,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(crate::io::describe(&e)))?;
    let document: ParamsDocument = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let values = values_of(document, effects).map_err(bad)?;
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

/// The params of a train or diagnose document, by name.
fn values_of(
    document: ParamsDocument,
    effects: &[String],
) -> Result<BTreeMap<String, f64>, String> {
    if let Some(list) = document.params {
        return Ok(list.into_iter().map(|p| (p.name, p.value)).collect());
    }
    let found = match effects {
        [] => document.fitted_params,
        [effect] => (document.effects.into_iter().flatten())
            .find(|e| &e.name == effect)
            .and_then(|e| e.params),
        _ => {
            return Err("expected at most one --effect with a diagnosis file, found several".into())
        }
    };
    found
        .map(|ByName(values)| values)
        .ok_or_else(|| match effects {
            [] => "expected `params` (gbc train) or `fitted_params` (gbc diagnose), found neither"
                .into(),
            _ => format!(
                "expected the effect `{}` among the diagnosis's `effects`, found none",
                effects[0]
            ),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn document(text: &str) -> ParamsDocument {
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn a_run_file_a_diagnosis_and_its_effects_give_their_params() {
        let run = document(r#"{"params": [{"name": "k", "value": 0.5}], "seed": 1}"#);
        assert_eq!(values_of(run, &[]).unwrap()["k"], 0.5);
        let diagnosis = r#"{"fitted_params": {"k": 0.25},
            "effects": [{"name": "decay", "params": {"k": 0.3, "d": "inf"}}]}"#;
        assert_eq!(values_of(document(diagnosis), &[]).unwrap()["k"], 0.25);
        let refit = values_of(document(diagnosis), &["decay".into()]).unwrap();
        assert_eq!((refit["k"], refit["d"]), (0.3, f64::INFINITY));
        let missing = values_of(document(diagnosis), &["lag".into()]).unwrap_err();
        assert!(missing.contains("`lag`"), "{missing}");
        assert!(values_of(document("{}"), &[]).is_err());
    }
}
