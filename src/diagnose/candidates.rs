//! What a diagnosis may credit for a gap: an unmodelled effect the model declares, or a
//! constant the modeller held that the data contradict (a literature value, a guessed
//! inoculum), refitted as a param. Both compete in one ranking and one selection: a gap a
//! wrong constant causes is not pinned on a look-alike effect, and a missing effect is not
//! absorbed by a constant unless the constant explains the data better.

use super::context::Context;
use super::error::DiagnoseError;
use crate::ir::{self, Model};
use crate::solve::fit::FitError;

/// How a refitted constant is named among the candidates: `refit Y_X`.
pub const REFIT: &str = "refit ";

/// One thing the diagnosis may credit.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Its name: the effect's, or [`REFIT`] and the constant's.
    pub name: String,
    /// What it says, in words.
    pub description: Option<String>,
}

/// The candidates of `model`: its effects in declaration order, then (when `refits`) each
/// constant a free run reads ([`ir::releasable`]).
pub fn candidates(model: &Model, refits: bool) -> Vec<Candidate> {
    let effects = model.effects.iter().map(|effect| Candidate {
        name: effect.name.clone(),
        description: effect.description.clone(),
    });
    let released = if refits {
        ir::releasable(model)
    } else {
        Vec::new()
    };
    let constants = released.into_iter().map(|name| {
        let value = (model.consts.iter())
            .find(|c| c.name == name)
            .map(|c| c.value);
        Candidate {
            description: Some(format!(
                "the held constant `{name}` ({}) is not what the data say",
                value.map_or(String::new(), super::render::num)
            )),
            name: format!("{REFIT}{name}"),
        }
    });
    effects.chain(constants).collect()
}

/// What refitting one held constant costs in the selection's criterion, in BIC units: the
/// modeller declared the value, and that declaration is knowledge with prior odds of
/// exp(6 / 2) = 20 to 1 against the data's first look (the same strong evidence,
/// [`super::selection::EVIDENCE`], an effect needs over the model). A refit is credited over
/// a look-alike effect only when the data favour it that strongly.
pub const REFIT_PRIOR: f64 = 6.0;

/// The prior penalty of a set of candidates: [`REFIT_PRIOR`] per constant it refits.
pub fn prior_penalty(names: &[String]) -> f64 {
    REFIT_PRIOR * names.iter().filter(|n| refitted(n).is_some()).count() as f64
}

/// The constant a candidate refits (`None`: the candidate is an effect).
pub fn refitted(name: &str) -> Option<&str> {
    name.strip_prefix(REFIT)
}

/// The model with the named candidates applied: its effects lowered, then its constants
/// made params.
pub fn lower(context: &Context, names: &[&str]) -> Result<Model, DiagnoseError> {
    let effects: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| refitted(n).is_none())
        .collect();
    let unsimulable = |reason: String| DiagnoseError::Fit(FitError::Unsimulable { reason });
    let mut model = ir::lower(context.problem.checked, &effects)
        .map_err(|error| unsimulable(format!("effect {}: {error}", names.join(" + "))))?;
    for constant in names.iter().filter_map(|n| refitted(n)) {
        model = ir::release(&model, constant)
            .ok_or_else(|| unsimulable(format!("the constant `{constant}` cannot be refitted")))?;
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_come_first_then_the_constants_a_run_reads() {
        let source = "model m\nstate X = 1\nconst mu = 0.2\nconst spare = 3\n\
            der X = mu * X\neffect death \"cells die\" {\n  param k = 0.1 positive\n  der X += -k * X\n}\n";
        let model = crate::driver::compile("m.gbm", source, &[]).unwrap().model;
        let names: Vec<String> = candidates(&model, true)
            .into_iter()
            .map(|c| c.name)
            .collect();
        assert_eq!(names, ["death", "refit mu"]);
        assert_eq!(candidates(&model, false).len(), 1);
        assert_eq!(refitted("refit mu"), Some("mu"));
        assert_eq!(refitted("death"), None);
    }
}
