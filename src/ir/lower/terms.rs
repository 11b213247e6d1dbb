//! The additive terms of `nonnegative` states' balances, each where it is written, and the
//! check that each learned one cannot drive its state below zero (E0136,
//! [`crate::ir::nonnegative`]).
//!
//! A balance is split at its top-level `+`, `-` and unary minus, through the `let`s and
//! `output`s it names (and their `+=` patches, each a term of its own); any other
//! expression is one term. The balance patches of applied effects (`der X += e`) add
//! their terms the same way.

use super::error::{LowerError, NegativeLearnedTerm};
use super::lowerer::{Lowerer, MAX_DEPTH};
use crate::ast::{self, BinOp, PatchOp, SExpr, Span};
use crate::check::Scope;
use crate::ir::model::{uses_closure, Dynamics, Expr, Model, Var};
use crate::ir::nonnegative::{self, Signs};
use std::collections::HashMap;

/// One additive term of a balance as written.
struct Term {
    /// Subtracted: under an odd number of minus signs.
    negated: bool,
    /// Where it is written.
    span: Span,
    /// Its lowered value.
    expr: Expr,
}

type Equations<'e> = HashMap<String, (Scope, &'e ast::Equation)>;

impl Lowerer<'_> {
    /// Every term of a `nonnegative` state's balance that uses a closure output and is not
    /// proven non-negative where the state is zero (in a `next` model: wherever the states
    /// are in their declared ranges).
    pub(super) fn nonnegative_violations(
        &mut self,
        model: &Model,
        items: &Equations<'_>,
        patches: &[(Scope, &ast::Equation)],
    ) -> Result<Vec<LowerError>, LowerError> {
        let nodes = self.nodes;
        let states = (model.states.iter().enumerate()).map(|(i, s)| (Var::State(i), s));
        let hidden = (model.hidden.iter().enumerate()).map(|(i, s)| (Var::Hidden(i), s));
        let mut violations = Vec::new();
        for (var, state) in states.chain(hidden) {
            let Some(&declared) = self.nonnegative.get(&state.name) else {
                continue;
            };
            let mut terms = Vec::new();
            if let Some((scope, eq)) = items.get(&state.name) {
                self.terms(&eq.expr, *scope, false, &mut terms)?;
            }
            for (scope, eq) in patches.iter().filter(|(_, eq)| eq.name.node == state.name) {
                self.terms(&eq.expr, *scope, false, &mut terms)?;
            }
            let zero = (model.dynamics == Dynamics::Continuous).then_some(var);
            for term in terms.iter().filter(|t| uses_closure(&t.expr)) {
                let signs = nonnegative::signs(model, zero, &term.expr);
                let signs = if term.negated { signs.negate() } else { signs };
                if !signs.is_nonnegative() {
                    violations.push(violation(model, (var, zero), declared, term, signs));
                }
            }
        }
        self.nodes = nodes;
        Ok(violations)
    }

    /// Pushes the terms of `expr` (written in `scope`) onto `out`.
    fn terms(
        &mut self,
        expr: &SExpr,
        scope: Scope,
        negated: bool,
        out: &mut Vec<Term>,
    ) -> Result<(), LowerError> {
        match &expr.node {
            ast::Expr::Binary(BinOp::Add, a, b) => {
                self.terms(a, scope, negated, out)?;
                self.terms(b, scope, negated, out)
            }
            ast::Expr::Binary(BinOp::Sub, a, b) => {
                self.terms(a, scope, negated, out)?;
                self.terms(b, scope, !negated, out)
            }
            ast::Expr::Neg(inner) => self.terms(inner, scope, !negated, out),
            ast::Expr::Name(name) => self.named_terms(expr, name, scope, negated, out),
            _ => self.leaf(expr, scope, negated, out),
        }
    }

    /// The terms of a `let` or `output` named in a balance: those of its definition and of
    /// each `+=` patch (as [`Lowerer::resolve`] combines them); one term for anything else.
    fn named_terms(
        &mut self,
        expr: &SExpr,
        name: &str,
        scope: Scope,
        negated: bool,
        out: &mut Vec<Term>,
    ) -> Result<(), LowerError> {
        let key = (self.owner(scope, name), name.to_string());
        let definition = match (self.vars.get(&key), self.definitions.get(&key)) {
            (None, Some(definition)) => *definition,
            _ => return self.leaf(expr, scope, negated, out),
        };
        let patches = self.patches.get(&key).cloned().unwrap_or_default();
        let limit = self.limits.get(&key).copied().unwrap_or(patches.len());
        let added = patches
            .iter()
            .take(limit)
            .all(|(_, p)| p.op == PatchOp::Add);
        if !added || self.depth >= MAX_DEPTH {
            return self.leaf(expr, scope, negated, out);
        }
        self.depth += 1;
        let mut result = self.terms(definition, key.0, negated, out);
        for (k, (patch_scope, patch)) in patches.iter().take(limit).enumerate() {
            if result.is_err() {
                break;
            }
            let saved = self.limits.insert(key.clone(), k);
            result = self.terms(&patch.expr, *patch_scope, negated, out);
            match saved {
                Some(previous) => self.limits.insert(key.clone(), previous),
                None => self.limits.remove(&key),
            };
        }
        self.depth -= 1;
        result
    }

    fn leaf(
        &mut self,
        expr: &SExpr,
        scope: Scope,
        negated: bool,
        out: &mut Vec<Term>,
    ) -> Result<(), LowerError> {
        let value = self.expr(expr, scope)?;
        out.push(Term {
            negated,
            span: expr.span,
            expr: value,
        });
        Ok(())
    }
}

/// The error for `term` of the balance of `state` (`zero`: the state where it is zero, in
/// a `der` model).
fn violation(
    model: &Model,
    (state, zero): (Var, Option<Var>),
    declared: Span,
    term: &Term,
    signs: Signs,
) -> LowerError {
    let name = crate::ir::var_name(model, state).to_string();
    let outputs: Vec<String> = nonnegative::culprits(model, zero, &term.expr)
        .into_iter()
        .map(|var| format!("`{}`", crate::ir::var_name(model, var)))
        .collect();
    let outputs = match outputs.as_slice() {
        [] => "its learned outputs".to_string(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    };
    let subtracted = if term.negated { "subtracted, " } else { "" };
    let at = match zero {
        Some(_) => format!("at `{name} = 0`"),
        None => "for states in their declared ranges".to_string(),
    };
    let why = if signs.is_finite() {
        format!("{subtracted}this term can be negative {at}")
    } else {
        format!("{subtracted}this term may not be finite {at} (a division by zero?)")
    };
    // A consumption: subtracted, or never positive wherever the states may be.
    let everywhere = nonnegative::signs(model, None, &term.expr);
    let consumption = term.negated || everywhere.negate().is_nonnegative();
    LowerError::NegativeLearnedTerm(Box::new(NegativeLearnedTerm {
        state: name.clone(),
        applied: String::new(),
        why,
        span: term.span.into(),
        declared: declared.into(),
        help: rewrite(&name, &outputs, consumption, zero.is_some()),
    }))
}

/// The help line: the rewrites that pass.
fn rewrite(state: &str, outputs: &str, consumption: bool, continuous: bool) -> String {
    if !continuous {
        return format!(
            "in a `next` model each learned term of `next {state}` must be >= 0: declare \
             {outputs} `positive`, or make the term non-negative otherwise"
        );
    }
    if consumption {
        format!(
            "write the consumption first-order in {state}: `- k * {state} * X` with `outputs k \
             ... positive`, or give {outputs} a `*=` prior that vanishes at {state} = 0 (e.g. \
             `prior q *= {state} / (K + {state})`)"
        )
    } else {
        format!(
            "a learned term that adds to {state} must not be negative at {state} = 0: declare \
             {outputs} `positive` if it only produces {state}; write a consumption \
             first-order in {state} (`- k * {state}` with `outputs k ... positive`), or give \
             {outputs} a `*=` prior that vanishes at {state} = 0"
        )
    }
}
