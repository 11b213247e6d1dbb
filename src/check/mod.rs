//! Checks (spec section 6): turns a parsed [`ast::Model`] into a [`Checked`] model or the
//! complete list of its errors. Checks collect, they don't stop: each check family pushes
//! into one [`Sink`] and every error of a file is reported in one run.
//!
//! Families: [`symbols`] (declarations, duplicates), [`exprs`] (names, functions, constant
//! expressions, cycles), [`structure`] (balances, closures, params, effects), [`units`]
//! (units of measure: inference and agreement), [`noise`] (measurement noise).

mod error;
pub mod exprs;
pub mod noise;
mod sink;
mod structure;
pub mod symbols;
pub mod units;

pub use error::CheckError;
pub use sink::Sink;
pub use symbols::{Kind, Scope, Symbols};

use crate::ast;
use std::collections::HashMap;

/// A model that passed every check, with what the checks computed.
#[derive(Debug, Clone)]
pub struct Checked {
    /// The syntax tree.
    pub ast: ast::Model,
    /// Every declared name.
    pub symbols: Symbols,
    /// Values of consts and initial values of params, by scope and name.
    pub values: HashMap<(Scope, String), f64>,
    /// Units of measure, declared and inferred (empty for a model without units).
    pub units: units::UnitTable,
    /// The declared measurement noise, one level per quantity, in declaration order.
    pub noise: Vec<noise::NoiseLevel>,
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
    let units = units::check_units(&model, &symbols, &values, &mut sink);
    let noise = noise::check_noise(&model, &symbols, &units, &mut sink);
    if sink.errors.is_empty() {
        Ok(Checked {
            ast: model,
            symbols,
            values,
            units,
            noise,
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
