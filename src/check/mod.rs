//! Checks (spec section 6): turns a parsed [`ast::Model`] into a [`Checked`] model or the
//! complete list of its errors. Checks collect, they don't stop: each check family pushes
//! into one [`Sink`] and every error of a file is reported in one run.
//!
//! Families: [`symbols`] (declarations, duplicates), [`exprs`] (names, functions, constant
//! expressions, cycles), [`structure`] (balances, closures, params, effects).

mod error;
pub mod exprs;
mod structure;
pub mod symbols;

pub use error::CheckError;
pub use symbols::{Kind, Scope, Symbol, Symbols};

use crate::ast;
use std::collections::HashMap;

/// Where check errors are collected.
#[derive(Debug, Default)]
pub struct Sink {
    /// The errors so far, in the order found.
    pub errors: Vec<CheckError>,
}

impl Sink {
    /// Records an error.
    pub fn push(&mut self, error: CheckError) {
        self.errors.push(error);
    }
}

/// A model that passed every check, with what the checks computed.
#[derive(Debug, Clone)]
pub struct Checked {
    /// The syntax tree.
    pub ast: ast::Model,
    /// Every declared name.
    pub symbols: Symbols,
    /// Values of consts and initial values of params, by scope and name.
    pub values: HashMap<(Scope, String), f64>,
}

impl Checked {
    /// The value of a constant expression written in `scope` (consts and param initial
    /// values), or `None` if it is not constant.
    pub fn constant(&self, expr: &ast::SExpr, scope: Scope) -> Option<f64> {
        let definitions = HashMap::new();
        let mut evaluator = exprs::Evaluator::new(&self.symbols, &definitions, self.values.clone());
        evaluator.eval(expr, scope)
    }

    /// Whether the model has anything to train (closures or params).
    pub fn is_trainable(&self) -> bool {
        self.symbols
            .model
            .values()
            .any(|s| matches!(s.kind, Kind::Param | Kind::ClosureOutput(_)))
    }
}

/// Runs every check on `model`.
pub fn check(model: ast::Model) -> Result<Checked, Vec<CheckError>> {
    let mut sink = Sink::default();
    let symbols = symbols::collect(&model, &mut sink);
    exprs::check_names(&model, &symbols, &mut sink);
    exprs::check_cycles(&model, &symbols, &mut sink);
    let values = exprs::evaluate_constants(&model, &symbols, &mut sink);
    structure::check_all(&model, &symbols, &values, &mut sink);
    if sink.errors.is_empty() {
        Ok(Checked {
            ast: model,
            symbols,
            values,
        })
    } else {
        sink.errors.sort_by_key(first_offset);
        Err(sink.errors)
    }
}

/// The first labelled byte offset of an error (errors are reported in source order).
fn first_offset(error: &CheckError) -> usize {
    use miette::Diagnostic;
    error
        .labels()
        .and_then(|mut labels| labels.next())
        .map_or(0, |label| label.offset())
}

/// A "did you mean" help line for `name` among `candidates`, or a generic hint.
pub fn suggest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    what: &str,
) -> String {
    match closest(name, candidates) {
        Some(best) => format!("did you mean `{best}`?"),
        None => format!("declare it first, or check the spelling of the {what}"),
    }
}

/// The candidate nearest to `name` by edit distance, if near enough to be a likely typo.
/// Ties go to the candidate of the most similar length (`SO` suggests `S0`, not `S`).
pub fn closest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let length = name.chars().count();
    let limit = (length / 3).max(1);
    candidates
        .into_iter()
        .filter(|c| *c != name)
        .map(|c| {
            let distance = if c.eq_ignore_ascii_case(name) {
                0
            } else {
                edit_distance(name, c)
            };
            (distance, c.chars().count().abs_diff(length), c)
        })
        .filter(|(d, _, _)| *d <= limit)
        .min()
        .map(|(_, _, c)| c)
}

/// Edit distance between two strings, by characters: insertions, deletions, substitutions
/// and transpositions of neighbours each count one (optimal string alignment).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let width = b.len() + 1;
    let mut table = vec![0usize; (a.len() + 1) * width];
    for (i, row) in table.chunks_mut(width).enumerate() {
        row[0] = i;
    }
    for (j, cell) in table.iter_mut().take(width).enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (table[(i - 1) * width + j] + 1)
                .min(table[i * width + j - 1] + 1)
                .min(table[(i - 1) * width + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(table[(i - 2) * width + j - 2] + 1);
            }
            table[i * width + j] = best;
        }
    }
    table[a.len() * width + b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_distance_counts_single_edits() {
        assert_eq!(edit_distance("S0", "S0"), 0);
        assert_eq!(edit_distance("SO", "S0"), 1);
        assert_eq!(edit_distance("kcat", "kact"), 1);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
    }

    #[test]
    fn closest_prefers_near_names_and_ignores_far_ones() {
        let names = ["S0", "theta", "kcat"];
        assert_eq!(closest("SO", names), Some("S0"));
        assert_eq!(closest("thetta", names), Some("theta"));
        assert_eq!(closest("zzz", names), None);
        assert_eq!(closest("KCAT", names), Some("kcat"));
        assert_eq!(closest("SO", ["S", "S0"]), Some("S0"));
    }
}
