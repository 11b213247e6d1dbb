//! The structure of a model: what the trained weights mean, and nothing else.
//!
//! Weights are matched to a model by its structure, not its text: the names and order of
//! inputs, states, hidden states and params (with their constraints), the dynamics, and
//! each closure's outputs (names, prior kind, constraint), what it observes, its embedding
//! and its network shape. Comments, consts, initial guesses, balances and prior expressions
//! are not part of it: changing them is a what-if on the physics the weights still fit,
//! and [`differences`] says what changed (given the model trained on, from the copy in the
//! run directory).

use std::collections::BTreeMap;

use sha2::{Digest, Sha256};

use crate::ast::format_number;
use crate::ir::{self, Constraint, PriorKind};

/// A model's structure: one entry per part, `part -> description`.
pub type Structure = BTreeMap<String, String>;

/// One part of the structure that differs.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// The part (`closure kinetics network`, `params`, ...).
    pub part: String,
    /// As trained (`none` when the trained model had no such part).
    pub expected: String,
    /// As given now (`none` when the model has no such part).
    pub found: String,
}

impl std::fmt::Display for Change {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            formatter,
            "{}: expected `{}`, found `{}`",
            self.part, self.expected, self.found
        )
    }
}

/// The structure of `model`.
pub fn structure(model: &ir::Model) -> Structure {
    let names = |list: &mut dyn Iterator<Item = &str>| list.collect::<Vec<_>>().join(", ");
    let mut parts = Structure::new();
    let dynamics = match model.dynamics {
        ir::Dynamics::Continuous => "der",
        ir::Dynamics::Discrete => "next",
    };
    parts.insert("dynamics".into(), dynamics.into());
    parts.insert(
        "inputs".into(),
        names(&mut model.inputs.iter().map(|i| i.name.as_str())),
    );
    parts.insert(
        "states".into(),
        names(&mut model.states.iter().map(|s| s.name.as_str())),
    );
    parts.insert(
        "hidden states".into(),
        names(&mut model.hidden.iter().map(|s| s.name.as_str())),
    );
    let params = (model.params.iter())
        .map(|p| format!("{}{}", p.name, constraint_text(p.constraint)))
        .collect::<Vec<_>>();
    parts.insert("params".into(), params.join(", "));
    parts.insert(
        "closures".into(),
        names(&mut model.closures.iter().map(|c| c.name.as_str())),
    );
    for closure in &model.closures {
        let part = |what: &str| format!("closure {} {what}", closure.name);
        let outputs = (closure.outputs.iter())
            .map(|o| {
                let prior = match o.prior.as_ref().map(|p| p.kind) {
                    None => "",
                    Some(PriorKind::Mul) => " prior *=",
                    Some(PriorKind::Add) => " prior +=",
                };
                format!("{}{prior}{}", o.name, constraint_text(o.constraint))
            })
            .collect::<Vec<_>>();
        parts.insert(part("outputs"), outputs.join(", "));
        let observed = (closure.embedding.observe.iter())
            .map(|&v| ir::var_name(model, v))
            .collect::<Vec<_>>();
        parts.insert(part("observe"), observed.join(", "));
        parts.insert(
            part("embedding"),
            format!(
                "delay {} dim {}",
                format_number(closure.embedding.delay),
                closure.embedding.dim
            ),
        );
        let widths = (closure.network.hidden.iter())
            .map(ToString::to_string)
            .collect::<Vec<_>>();
        parts.insert(
            part("network"),
            format!(
                "hidden [{}] {}",
                widths.join(", "),
                closure.network.activation.name()
            ),
        );
    }
    parts
}

/// sha256 of a structure's canonical text (one `part: description` line each, sorted).
pub fn fingerprint(structure: &Structure) -> String {
    let text: String = (structure.iter())
        .map(|(part, value)| format!("{part}: {value}\n"))
        .collect();
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|byte| format!("{byte:02x}"))
        .collect()
}

/// The parts whose descriptions differ, in part order.
pub fn compare(expected: &Structure, found: &Structure) -> Vec<Change> {
    let mut parts: Vec<&String> = expected.keys().chain(found.keys()).collect();
    parts.sort();
    parts.dedup();
    let none = String::from("none");
    (parts.into_iter())
        .filter_map(|part| {
            let (was, is) = (
                expected.get(part).unwrap_or(&none),
                found.get(part).unwrap_or(&none),
            );
            (was != is).then(|| Change {
                part: part.clone(),
                expected: was.clone(),
                found: is.clone(),
            })
        })
        .collect()
}

/// What differs between the model trained on and the one given, outside the structure:
/// consts, input bounds, balances, priors, outputs and initial values, one line each.
pub fn differences(trained: &ir::Model, given: &ir::Model) -> Vec<String> {
    let mut lines = Vec::new();
    let before: BTreeMap<&str, f64> = (trained.consts.iter())
        .map(|c| (c.name.as_str(), c.value))
        .collect();
    for constant in &given.consts {
        match before.get(constant.name.as_str()) {
            Some(&old) if old.to_bits() == constant.value.to_bits() => {}
            Some(&old) => lines.push(format!(
                "const {} = {} (trained with {})",
                constant.name,
                format_number(constant.value),
                format_number(old)
            )),
            None => lines.push(format!(
                "const {} = {} (new)",
                constant.name,
                format_number(constant.value)
            )),
        }
    }
    let texts = |model: &ir::Model| -> BTreeMap<String, String> {
        let mut texts = BTreeMap::new();
        for input in &model.inputs {
            if let Some((lo, hi)) = input.bounds {
                texts.insert(
                    format!("bounds of input {}", input.name),
                    format!("[{}, {}]", format_number(lo), format_number(hi)),
                );
            }
        }
        for balance in &model.balances {
            let name = ir::var_name(model, balance.state);
            texts.insert(
                format!("balance of {name}"),
                ir::expr_text(model, &balance.expr),
            );
        }
        for (closure, output) in
            (model.closures.iter()).flat_map(|c| c.outputs.iter().map(move |o| (c, o)))
        {
            if let Some(prior) = &output.prior {
                texts.insert(
                    format!("prior of {}.{}", closure.name, output.name),
                    ir::expr_text(model, &prior.expr),
                );
            }
        }
        for definition in &model.outputs {
            texts.insert(
                format!("output {}", definition.name),
                ir::expr_text(model, &definition.expr),
            );
        }
        for state in model.states.iter().chain(&model.hidden) {
            if let Some(init) = &state.init {
                texts.insert(
                    format!("initial value of {}", state.name),
                    ir::expr_text(model, init),
                );
            }
        }
        texts
    };
    let (old, new) = (texts(trained), texts(given));
    for (part, text) in &new {
        if old.get(part) != Some(text) {
            lines.push(format!("{part}: {text}"));
        }
    }
    lines.extend(
        (old.keys())
            .filter(|part| !new.contains_key(*part))
            .map(|part| format!("{part}: removed")),
    );
    lines
}

fn constraint_text(constraint: Constraint) -> String {
    match constraint {
        Constraint::Free => String::new(),
        Constraint::Positive => " positive".into(),
        Constraint::Bounds(lo, hi) => format!(" in [{}, {}]", format_number(lo), format_number(hi)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gb1(edit: (&str, &str)) -> ir::Model {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/bioreactor/gb1.gbm");
        let text = std::fs::read_to_string(path).unwrap();
        assert!(text.contains(edit.0), "{}", edit.0);
        let text = text.replacen(edit.0, edit.1, 1);
        crate::driver::compile("gb1.gbm", &text, &[]).unwrap().model
    }

    /// Edits GB1 by `edit` and checks the changed parts of the structure and the notes.
    fn check(edit: (&str, &str), parts: &[&str], notes: &[&str]) {
        let (trained, given) = (gb1(("", "")), gb1(edit));
        let changes = compare(&structure(&trained), &structure(&given));
        let changed: Vec<&str> = changes.iter().map(|c| c.part.as_str()).collect();
        assert_eq!(changed, parts, "{edit:?}");
        assert_eq!(differences(&trained, &given), notes, "{edit:?}");
        assert_eq!(
            fingerprint(&structure(&trained)) == fingerprint(&structure(&given)),
            parts.is_empty()
        );
    }

    #[test]
    fn what_changes_the_structure_and_what_is_only_noted() {
        check(
            ("## Biomass balance", "# again\n## Biomass balance"),
            &[],
            &[],
        );
        check(
            ("const D = 0.05", "const D = 0.06"),
            &[],
            &["const D = 0.06 (trained with 0.05)"],
        );
        check(
            ("in [0, 1]", "in [0, 2]"),
            &[],
            &["bounds of input u: [0, 2]"],
        );
        check(
            ("der X = (mu - D) * X", "der X = mu * X"),
            &[],
            &["balance of X: mu * X"],
        );
        check(("param Y_X = 0.5", "param Y_X = 0.4"), &[], &[]);
        check(
            ("hidden [20, 20, 20]", "hidden [20, 20]"),
            &["closure kinetics network"],
            &[],
        );
        check(("] softplus", "] tanh"), &["closure kinetics network"], &[]);
        check(
            ("delay 5 dim 10", "delay 5 dim 9"),
            &["closure kinetics embedding"],
            &[],
        );
        check(
            ("observe X, A, B, S, u", "observe X, A, B, S"),
            &["closure kinetics observe"],
            &[],
        );
        check(
            // (Dropping `positive` altogether fails the check: `B` is `nonnegative`.)
            ("mu_B [1/h] ~ 0.2 positive", "mu_B [1/h] ~ 0.2 in [0, 2]"),
            &["closure kinetics outputs"],
            &[],
        );
        check(
            ("mu_B [1/h] ~ 0.2 positive", "mu_B [1/h] ~ 0.3 positive"),
            &[],
            &[],
        );
        check(
            (
                "[g/g] positive\n## Yield of product A",
                "[g/g]\n## Yield of product A",
            ),
            &["params"],
            &[],
        );
    }
}
