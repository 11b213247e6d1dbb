//! Measurement noise: `noise X = 4 % + 0.01 [g/L]` declares the standard deviation of a
//! measurement of `X`, `sigma(y) = sqrt(absolute^2 + (relative * y)^2)`.
//!
//! Rules (docs/language.md, "`noise`"): the names are measured `state`s or `output`s, each
//! with one declaration; a declaration has at most one relative term (`%`) and one absolute
//! term; no term is negative; not every term is zero. An absolute term written with a unit
//! is converted to the quantity's unit when the two differ by a scale (`10 [mg/L]` for a
//! `g/L` state is 0.01) and refused when their dimensions differ; without a unit, or where
//! the quantity has none, the number is taken in the quantity's own unit. A relative term
//! above 100 % is allowed (the checks have no warnings).

use super::error::CheckError;
use super::sink::Sink;
use super::symbols::{Kind, Scope, Symbols};
use super::units::{shown, unknown_unit, UnitTable};
use crate::ast::{self, ItemKind, NoiseKind, NoiseTerm, Span};
use crate::units::{resolve, Comparison, Unit};
use std::collections::HashMap;

/// One quantity's noise after the checks: the relative term as a fraction (`4 %` is 0.04)
/// and the absolute term in the quantity's unit.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseLevel {
    /// The measured state or output.
    pub name: String,
    /// Relative standard deviation, a fraction of the value.
    pub relative: f64,
    /// Absolute standard deviation, in the quantity's unit.
    pub absolute: f64,
}

/// Checks every noise declaration and returns the levels of those that passed, in
/// declaration order (one per named quantity).
pub fn check_noise(
    model: &ast::Model,
    symbols: &Symbols,
    units: &UnitTable,
    sink: &mut Sink,
) -> Vec<NoiseLevel> {
    let mut levels = Vec::new();
    let mut first: HashMap<&str, Span> = HashMap::new();
    for item in &model.items {
        let ItemKind::Noise(declaration) = &item.kind else {
            continue;
        };
        let terms = check_terms(declaration, sink);
        for target in &declaration.targets {
            if !check_target(target, symbols, sink) {
                continue;
            }
            if let Some(span) = first.get(target.node.as_str()) {
                sink.push(CheckError::DuplicateNoise {
                    name: target.node.clone(),
                    span: target.span.into(),
                    first: (*span).into(),
                });
                continue;
            }
            first.insert(&target.node, target.span);
            if let Some(terms) = &terms {
                levels.extend(level(target, terms, symbols, units, sink));
            }
        }
    }
    levels
}

/// The terms of one declaration, checked on their own (without the quantity).
struct Terms<'a> {
    relative: f64,
    absolute: Option<(&'a NoiseTerm, Option<Unit>)>,
}

/// Checks the terms: signs, at most one of each kind, known units, not all zero. `None`
/// when any is wrong.
fn check_terms<'a>(declaration: &'a ast::NoiseDecl, sink: &mut Sink) -> Option<Terms<'a>> {
    let terms = &declaration.terms;
    let errors = sink.errors.len();
    let mut relative: Option<&NoiseTerm> = None;
    let mut absolute: Option<(&NoiseTerm, Option<Unit>)> = None;
    for term in terms {
        check_value(term, sink);
        let unit = match &term.kind {
            NoiseKind::Relative => None,
            NoiseKind::Absolute(unit) => unit.as_ref(),
        };
        let resolved = unit.map(|unit| {
            resolve(unit).map_err(|unknown| {
                (unknown.into_iter())
                    .for_each(|(span, symbol)| sink.push(unknown_unit(&symbol, span)))
            })
        });
        let kind = if term.kind == NoiseKind::Relative {
            "relative"
        } else {
            "absolute"
        };
        let earlier = match term.kind {
            NoiseKind::Relative => relative.replace(term),
            NoiseKind::Absolute(_) => {
                let unit = resolved.and_then(Result::ok);
                absolute.replace((term, unit)).map(|(earlier, _)| earlier)
            }
        };
        if let Some(earlier) = earlier {
            sink.push(two_terms(kind, term, earlier));
        }
    }
    if sink.errors.len() > errors {
        return None;
    }
    if terms.iter().all(|term| term.value.node == 0.0) {
        let span = terms.iter().map(|t| t.span).reduce(Span::join);
        sink.push(CheckError::ZeroNoise {
            found: declaration.terms_text(),
            span: span.unwrap_or_default().into(),
        });
        return None;
    }
    Some(Terms {
        relative: relative.map_or(0.0, |term| term.value.node / 100.0),
        absolute,
    })
}

/// A term's number must be a finite level at or above zero.
fn check_value(term: &NoiseTerm, sink: &mut Sink) {
    let value = term.value.node;
    if value >= 0.0 && value.is_finite() {
        return;
    }
    let written = match term.kind {
        NoiseKind::Relative => format!("{} %", ast::format_number(value)),
        NoiseKind::Absolute(_) => ast::format_number(value),
    };
    sink.push(CheckError::BadNoiseValue {
        expected: "a noise level >= 0".to_string(),
        found: written,
        span: term.span.into(),
        help: "a standard deviation is never negative: write the size of the error, \
               e.g. `0.01`"
            .to_string(),
    });
}

fn two_terms(kind: &str, term: &NoiseTerm, earlier: &NoiseTerm) -> CheckError {
    let mut help = "a noise has at most one relative term (a bare `%` after the number) and \
                    one absolute term, joined by `+`: `noise X = 4 % + 0.01 [g/L]`"
        .to_string();
    if kind == "absolute" {
        help.push_str("; a relative term is written `4 %`, not `0.04`");
    }
    CheckError::NoiseTerms {
        kind: kind.to_string(),
        span: term.span.into(),
        first: earlier.span.into(),
        help,
    }
}

/// Whether `target` names a measured state or an output; reports what it is otherwise.
fn check_target(target: &ast::Ident, symbols: &Symbols, sink: &mut Sink) -> bool {
    let name = &target.node;
    let Some(symbol) = symbols.get(Scope::Model, name) else {
        let mut measured: Vec<&str> = (symbols.model.iter())
            .filter(|(_, s)| matches!(s.kind, Kind::State | Kind::Output))
            .map(|(name, _)| name.as_str())
            .collect();
        measured.sort_unstable();
        sink.push(CheckError::UnknownName {
            name: name.clone(),
            span: target.span.into(),
            help: crate::suggest::did_you_mean(name, &measured, "measured quantities"),
        });
        return false;
    };
    if matches!(symbol.kind, Kind::State | Kind::Output) {
        return true;
    }
    let why = match symbol.kind {
        Kind::Hidden => format!(
            "a hidden state is never compared with data; make `{name}` a `state` if it is \
             measured"
        ),
        Kind::Input => "an input is set, not measured: gbc takes it as exact".to_string(),
        Kind::Let => format!("make `{name}` an `output` if a sensor reads it"),
        _ => format!("`{name}` is never compared with data"),
    };
    sink.push(CheckError::NoiseTarget {
        name: name.clone(),
        kind: symbol.kind.describe().to_string(),
        span: target.span.into(),
        help: format!(
            "noise is the precision of a measurement: declare it for measured `state`s and \
             `output`s (an output is measured where its name is a data column); {why}"
        ),
    });
    false
}

/// The level of one quantity: the absolute term converted to its unit.
fn level(
    target: &ast::Ident,
    terms: &Terms,
    symbols: &Symbols,
    units: &UnitTable,
    sink: &mut Sink,
) -> Option<NoiseLevel> {
    let name = &target.node;
    let mut absolute = 0.0;
    if let Some((term, written)) = &terms.absolute {
        let quantity = units.get(symbols, Scope::Model, name);
        absolute = term.value.node;
        if let (Some(written), Some(quantity)) = (written, quantity) {
            absolute *= conversion(name, term, written, quantity, sink)?;
        }
        if !absolute.is_finite() {
            let unit = quantity.map_or(String::new(), |q| format!(" in {}", q.text));
            sink.push(CheckError::BadNoiseValue {
                expected: format!("a finite noise level{unit}"),
                found: ast::format_number(absolute),
                span: term.span.into(),
                help: format!("write the absolute term of `{name}` in its own unit"),
            });
            return None;
        }
    }
    Some(NoiseLevel {
        name: name.clone(),
        relative: terms.relative,
        absolute,
    })
}

/// The factor from the unit written to the quantity's unit, or the dimension mismatch.
fn conversion(
    name: &str,
    term: &NoiseTerm,
    written: &Unit,
    quantity: &super::units::UnitEntry,
    sink: &mut Sink,
) -> Option<f64> {
    match written.compare(&quantity.unit) {
        Comparison::Equal => Some(1.0),
        Comparison::Scale(factor) => Some(factor),
        Comparison::Incompatible => {
            let (expected, found) = (shown(&quantity.unit), shown(written));
            let mut help = format!(
                "an absolute noise has the unit of its quantity ({name}: {}); {found} ({}) and \
                 {expected} ({}) are different dimensions",
                quantity.text,
                written.dimension_words(),
                quantity.unit.dimension_words()
            );
            if written.is_dimensionless() {
                help.push_str("; a relative term is a bare `%` after the number: `4 %`");
            }
            let span = match &term.kind {
                NoiseKind::Absolute(Some(unit)) => unit.span,
                _ => term.span,
            };
            sink.push(CheckError::UnitMismatch {
                context: format!("absolute noise of `{name}`"),
                expected,
                found,
                span: span.into(),
                origin: Some(quantity.origin.into()),
                help,
            });
            None
        }
    }
}

#[cfg(test)]
mod tests;
