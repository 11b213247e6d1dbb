//! Unit annotations (`[g/L]`, `[g L^-1]`, `[-]`) from the `unit` rule into [`UnitExpr`] trees.

use super::{Rule, SyntaxError};
use crate::ast::{SUnit, Spanned, UnitExpr};
use pest::iterators::Pair;

type Result<T> = std::result::Result<T, SyntaxError>;

/// The largest exponent magnitude a unit may carry.
const MAX_EXPONENT: i32 = 99;

use super::span::span_of;

fn shape_error(pair: &Pair<Rule>) -> SyntaxError {
    SyntaxError::internal(pair.as_span().start(), "unexpected unit parse tree shape")
}

/// The `unit` rule: `[ ... ]`. The top node's span covers the brackets.
pub fn unit(pair: &Pair<Rule>) -> Result<SUnit> {
    let span = span_of(pair);
    let inner = pair
        .clone()
        .into_inner()
        .next()
        .ok_or_else(|| shape_error(pair))?;
    let node = match inner.as_rule() {
        Rule::unit_none => UnitExpr::Dimensionless,
        Rule::unit_product => product(&inner)?.node,
        _ => return Err(shape_error(&inner)),
    };
    Ok(Spanned::new(node, span))
}

/// `factor (op factor)*`, folded left to right.
fn product(pair: &Pair<Rule>) -> Result<SUnit> {
    let mut children = pair.clone().into_inner();
    let first = children.next().ok_or_else(|| shape_error(pair))?;
    let mut acc = factor(&first)?;
    for step in children {
        let operand = step
            .clone()
            .into_inner()
            .next()
            .ok_or_else(|| shape_error(&step))?;
        let rhs = factor(&operand)?;
        let span = acc.span.join(rhs.span);
        let node = match step.as_rule() {
            Rule::unit_div => UnitExpr::Div(Box::new(acc), Box::new(rhs)),
            _ => UnitExpr::Mul(Box::new(acc), Box::new(rhs)),
        };
        acc = Spanned::new(node, span);
    }
    Ok(acc)
}

/// A symbol, `1` or a group, with an optional exponent.
fn factor(pair: &Pair<Rule>) -> Result<SUnit> {
    let mut children = pair.clone().into_inner();
    let atom = children.next().ok_or_else(|| shape_error(pair))?;
    let base = match atom.as_rule() {
        Rule::unit_one => Spanned::new(UnitExpr::One, span_of(&atom)),
        Rule::unit_symbol => {
            Spanned::new(UnitExpr::Symbol(atom.as_str().to_string()), span_of(&atom))
        }
        Rule::unit_group => {
            let inner = atom
                .clone()
                .into_inner()
                .next()
                .ok_or_else(|| shape_error(&atom))?;
            let grouped = product(&inner)?;
            Spanned::new(grouped.node, span_of(&atom))
        }
        _ => return Err(shape_error(&atom)),
    };
    let Some(exponent) = children.next() else {
        return Ok(base);
    };
    let text = exponent.as_str();
    let value = match text.parse::<i32>() {
        Ok(value) if value.abs() <= MAX_EXPONENT => value,
        _ => {
            return Err(SyntaxError::BadNumber {
                span: span_of(&exponent).into(),
                text: text.to_string(),
            })
        }
    };
    Ok(Spanned::new(
        UnitExpr::Pow(Box::new(base), value),
        span_of(pair),
    ))
}
