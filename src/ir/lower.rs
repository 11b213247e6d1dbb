//! Lowering: a [`Checked`] model (plus the effects to apply) becomes an [`ir::Model`](Model).
//!
//! Names are resolved to [`Var`]s; `let`s and `output`s are inlined; an applied effect adds
//! its params and hidden states and its patches are folded into every use of the patched
//! name (`NAME *= e`, `+=`, `:=`) or into the patched balance (`der X += e`). Inside a patch
//! expression the patched name means its value before that patch.

use crate::ast::{self, ItemKind};
use crate::check::Checked;
use crate::ir::model::Model;
use lowerer::Lowerer;

mod error;
mod items;
mod lowerer;
mod terms;

pub use error::LowerError;

/// Lowers `checked` with the named effects applied (in the order given); the first error.
pub fn lower(checked: &Checked, effects: &[&str]) -> Result<Model, LowerError> {
    lower_reporting(checked, effects).map_err(|mut errors| errors.swap_remove(0))
}

/// [`lower`], with every error found: every term of a `nonnegative` state's balance that
/// is not proven (E0136) is reported, in source order (other errors stop lowering).
pub fn lower_reporting(checked: &Checked, effects: &[&str]) -> Result<Model, Vec<LowerError>> {
    let (model, errors) = lower_with_violations(checked, effects)?;
    if errors.is_empty() {
        Ok(model)
    } else {
        Err(errors)
    }
}

/// [`lower`] without the guard of `nonnegative` states: the model even where a learned
/// term is not proven to keep such a state at or above zero (E0136). For probes that are
/// fitted and thrown away, never trained or saved: the diagnosis's free corrections at a
/// locus (a correction of `mu` in `der S = -mu * X / Y` is not proven, and its fit simply
/// fails where a run leaves the model's range).
pub fn lower_unguarded(checked: &Checked, effects: &[&str]) -> Result<Model, Vec<LowerError>> {
    lower_with_violations(checked, effects).map(|(model, _)| model)
}

/// The lowered model and its E0136 violations, in source order (other errors stop
/// lowering).
fn lower_with_violations(
    checked: &Checked,
    effects: &[&str],
) -> Result<(Model, Vec<LowerError>), Vec<LowerError>> {
    let effect_decls: Vec<&ast::EffectDecl> =
        crate::check::symbols::effect_items(&checked.ast).collect();
    let mut applied = Vec::new();
    for name in effects {
        match effect_decls.iter().position(|e| e.name.node == *name) {
            Some(index) => applied.push(index),
            None => {
                let names = effect_decls.iter().map(|e| e.name.node.as_str());
                let help = match crate::suggest::closest(name, names.clone()) {
                    Some(best) => format!("did you mean `{best}`?"),
                    None => format!(
                        "the model's effects are: {}",
                        names.collect::<Vec<_>>().join(", ")
                    ),
                };
                return Err(vec![LowerError::UnknownEffect {
                    name: name.to_string(),
                    help,
                }]);
            }
        }
    }
    let mut lowerer = Lowerer::new(checked, &effect_decls, &applied);
    let model = lowerer.build().map_err(|error| vec![error])?;
    let mut errors = lowerer.violations;
    errors.sort_by_key(|error| match error {
        LowerError::NegativeLearnedTerm(term) => term.span.offset(),
        _ => 0,
    });
    if !effects.is_empty() {
        let names: Vec<String> = effects.iter().map(|e| format!("`{e}`")).collect();
        let plural = if names.len() > 1 { "s" } else { "" };
        for error in &mut errors {
            if let LowerError::NegativeLearnedTerm(term) = error {
                term.applied = format!(" (with effect{plural} {} applied)", names.join(", "));
            }
        }
    }
    Ok((model, errors))
}

/// The E0136 errors of each effect applied alone, for a model that lowers cleanly without
/// effects: `gbc check` reports a patch that adds a learned term a `nonnegative` state
/// cannot take, though nothing applies it yet (other errors of an effect show where it is
/// applied).
pub fn effect_violations(checked: &Checked) -> Vec<LowerError> {
    let effects: Vec<&ast::EffectDecl> =
        crate::check::symbols::effect_items(&checked.ast).collect();
    let items = (checked.ast.items.iter()).chain(effects.iter().flat_map(|e| &e.items));
    let declared = items
        .filter_map(|item| match &item.kind {
            ItemKind::State(list) | ItemKind::Hidden(list) => Some(list),
            _ => None,
        })
        .flatten()
        .any(|binding| binding.nonnegative.is_some());
    if !declared || !checked.is_trainable() {
        return Vec::new();
    }
    let mut found: Vec<LowerError> = Vec::new();
    for effect in effects {
        let Err(errors) = lower_reporting(checked, &[effect.name.node.as_str()]) else {
            continue;
        };
        let violations = errors
            .into_iter()
            .filter(|e| matches!(e, LowerError::NegativeLearnedTerm(_)));
        found.extend(violations);
    }
    found
}
