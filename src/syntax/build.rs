//! Builds the AST from pest's parse tree. Each function takes the pair of one grammar rule.

use super::span::span_of;
use super::{Rule, SyntaxError};
use crate::ast::*;
use pest::iterators::Pair;
use pest::pratt_parser::{Assoc, Op, PrattParser};
use std::sync::LazyLock;

type Result<T> = std::result::Result<T, SyntaxError>;

/// Operator precedence, lowest first: `+ -`, `* /`, unary `-`, `^` (right associative).
static PRATT: LazyLock<PrattParser<Rule>> = LazyLock::new(|| {
    PrattParser::new()
        .op(Op::infix(Rule::add, Assoc::Left) | Op::infix(Rule::sub, Assoc::Left))
        .op(Op::infix(Rule::mul, Assoc::Left) | Op::infix(Rule::div, Assoc::Left))
        .op(Op::prefix(Rule::neg))
        .op(Op::infix(Rule::pow, Assoc::Right))
});

fn ident(pair: Pair<Rule>) -> Ident {
    Spanned::new(pair.as_str().to_string(), span_of(&pair))
}

fn unexpected_shape(pair: &Pair<Rule>) -> SyntaxError {
    SyntaxError::internal(pair.as_span().start(), "unexpected parse tree shape")
}

/// Takes the next child pair, or reports an internal error at `parent`.
fn next<'a>(
    children: &mut pest::iterators::Pairs<'a, Rule>,
    parent: &Pair<'a, Rule>,
) -> Result<Pair<'a, Rule>> {
    children.next().ok_or_else(|| unexpected_shape(parent))
}

/// The `file` rule: header then declarations.
pub fn model(source: &str, file: Pair<Rule>) -> Result<Model> {
    let mut children = file.clone().into_inner();
    let header = next(&mut children, &file)?;
    let header_span = span_of(&header);
    let mut parts = header.clone().into_inner();
    let name = ident(next(&mut parts, &header)?);
    let description = parts.next().map(|s| string_text(&s));
    let mut items = Vec::new();
    for pair in children {
        if pair.as_rule() == Rule::EOI {
            break;
        }
        items.push(item(source, pair, Place::TopLevel)?);
    }
    Ok(Model {
        name,
        description,
        doc: doc_above(source, header_span.start),
        items,
    })
}

/// Where a declaration appears, for the placement rules the grammar does not encode.
#[derive(Clone, Copy, PartialEq)]
enum Place {
    TopLevel,
    Effect,
}

fn string_text(pair: &Pair<Rule>) -> String {
    pair.clone()
        .into_inner()
        .next()
        .map(|body| body.as_str().to_string())
        .unwrap_or_default()
}

/// The `##` lines directly above byte offset `start`, joined, without the markers, when
/// the declaration at `start` is the first thing on its line.
fn doc_above(source: &str, start: usize) -> Option<String> {
    let line_start = source[..start].rfind('\n').map_or(0, |i| i + 1);
    if !source[line_start..start].trim().is_empty() {
        return None;
    }
    let mut lines = Vec::new();
    let mut end = line_start;
    while end > 0 {
        let previous_end = end - 1; // the '\n' ending the previous line
        let previous_start = source[..previous_end].rfind('\n').map_or(0, |i| i + 1);
        let text = source[previous_start..previous_end].trim();
        match text.strip_prefix("##") {
            Some(doc) => lines.push(doc.strip_prefix(' ').unwrap_or(doc).to_string()),
            None => break,
        }
        end = previous_start;
    }
    if lines.is_empty() {
        return None;
    }
    lines.reverse();
    Some(lines.join("\n"))
}

fn item(source: &str, pair: Pair<Rule>, place: Place) -> Result<Item> {
    let span = span_of(&pair);
    let doc = doc_above(source, span.start);
    let rule = pair.as_rule();
    let kind = match rule {
        Rule::time_decl => ItemKind::Time(ident(first_child(&pair)?)),
        Rule::input_decl => ItemKind::Input(each_child(&pair, input_entry)?),
        Rule::state_decl => ItemKind::State(each_child(&pair, binding)?),
        Rule::hidden_decl => ItemKind::Hidden(each_child(&pair, binding)?),
        Rule::const_decl => ItemKind::Const(each_child(&pair, binding)?),
        Rule::param_decl => ItemKind::Param(each_child(&pair, param_entry)?),
        Rule::let_decl => ItemKind::Let(equation(&pair)?),
        Rule::output_decl => ItemKind::Output(equation(&pair)?),
        Rule::next_decl => ItemKind::Next(equation(&pair)?),
        Rule::der_decl => der(&pair, place)?,
        Rule::closure_decl => ItemKind::Closure(closure(&pair)?),
        Rule::effect_decl => ItemKind::Effect(effect(source, &pair, place)?),
        Rule::patch => ItemKind::Patch(patch(&pair)?),
        Rule::noise_decl => ItemKind::Noise(noise(&pair, place)?),
        _ => return Err(unexpected_shape(&pair)),
    };
    Ok(Item { doc, kind, span })
}

fn first_child<'a>(pair: &Pair<'a, Rule>) -> Result<Pair<'a, Rule>> {
    pair.clone()
        .into_inner()
        .next()
        .ok_or_else(|| unexpected_shape(pair))
}

fn each_child<T>(pair: &Pair<Rule>, build: fn(Pair<Rule>) -> Result<T>) -> Result<Vec<T>> {
    pair.clone().into_inner().map(build).collect()
}

/// The children of an entry rule (`X [g/L] = 1`, `k = 1 [1/h] positive`), by kind.
struct EntryParts<'a> {
    name: Ident,
    unit: Option<SUnit>,
    exprs: Vec<Pair<'a, Rule>>,
    rest: Vec<Pair<'a, Rule>>,
}

/// Splits an entry into its name, its unit (at most one, before or after the value) and
/// the other children in order.
fn entry_parts<'a>(pair: &Pair<'a, Rule>) -> Result<EntryParts<'a>> {
    let mut children = pair.clone().into_inner();
    let name = ident(next(&mut children, pair)?);
    let mut parts = EntryParts {
        name,
        unit: None,
        exprs: Vec::new(),
        rest: Vec::new(),
    };
    for child in children {
        match child.as_rule() {
            Rule::unit => {
                let unit = super::unit::unit(&child)?;
                if parts.unit.is_some() {
                    return Err(SyntaxError::Misplaced {
                        span: unit.span.into(),
                        what: "a second unit".to_string(),
                        place: format!("on `{}`", parts.name.node),
                        help: "write the unit once, after the name or after the value".to_string(),
                    });
                }
                parts.unit = Some(unit);
            }
            Rule::expr => parts.exprs.push(child),
            _ => parts.rest.push(child),
        }
    }
    Ok(parts)
}

fn input_entry(pair: Pair<Rule>) -> Result<InputDecl> {
    let parts = entry_parts(&pair)?;
    let bounds = parts.rest.first().map(bounds).transpose()?;
    Ok(InputDecl {
        name: parts.name,
        unit: parts.unit,
        bounds,
    })
}

fn bounds(pair: &Pair<Rule>) -> Result<(SExpr, SExpr)> {
    let mut children = pair.clone().into_inner();
    let lo = expr(next(&mut children, pair)?)?;
    let hi = expr(next(&mut children, pair)?)?;
    Ok((lo, hi))
}

fn binding(pair: Pair<Rule>) -> Result<Binding> {
    let parts = entry_parts(&pair)?;
    let value = parts.exprs.into_iter().next().map(expr).transpose()?;
    let nonnegative = (parts.rest.iter())
        .find(|child| child.as_rule() == Rule::nonnegative)
        .map(span_of);
    Ok(Binding {
        name: parts.name,
        unit: parts.unit,
        value,
        nonnegative,
    })
}

fn constraint(pair: Pair<Rule>) -> Result<Constraint> {
    match pair.as_rule() {
        Rule::positive => Ok(Constraint::Positive(span_of(&pair))),
        Rule::bounds => {
            let (lo, hi) = bounds(&pair)?;
            Ok(Constraint::Bounds(lo, hi))
        }
        _ => Err(unexpected_shape(&pair)),
    }
}

fn param_entry(pair: Pair<Rule>) -> Result<ParamDecl> {
    let parts = entry_parts(&pair)?;
    let init = parts
        .exprs
        .into_iter()
        .next()
        .ok_or_else(|| unexpected_shape(&pair))?;
    let constraint = parts.rest.into_iter().next().map(constraint).transpose()?;
    Ok(ParamDecl {
        name: parts.name,
        unit: parts.unit,
        init: expr(init)?,
        constraint,
    })
}

/// `NAME [op] expr` where the operator (if any) is skipped.
fn equation(pair: &Pair<Rule>) -> Result<Equation> {
    let parts = entry_parts(pair)?;
    let rhs = parts
        .exprs
        .into_iter()
        .next()
        .ok_or_else(|| unexpected_shape(pair))?;
    Ok(Equation {
        name: parts.name,
        unit: parts.unit,
        expr: expr(rhs)?,
    })
}

fn der(pair: &Pair<Rule>, place: Place) -> Result<ItemKind> {
    let is_patch = pair
        .clone()
        .into_inner()
        .any(|child| child.as_rule() == Rule::add_assign);
    let equation = equation(pair)?;
    if !is_patch {
        return Ok(ItemKind::Der(equation));
    }
    if place != Place::Effect {
        return Err(SyntaxError::Misplaced {
            span: span_of(pair).into(),
            what: "a balance patch `der X += ...`".to_string(),
            place: "outside an effect".to_string(),
            help: "write the term into the balance itself, or put the patch inside an \
                   `effect NAME { ... }` block"
                .to_string(),
        });
    }
    Ok(ItemKind::DerPatch(equation))
}

/// `noise X, S = 4 % + 0.01 [g/L]`, refused inside an effect.
fn noise(pair: &Pair<Rule>, place: Place) -> Result<NoiseDecl> {
    if place == Place::Effect {
        return Err(SyntaxError::Misplaced {
            span: span_of(pair).into(),
            what: "a noise declaration".to_string(),
            place: "inside an effect".to_string(),
            help: "measurement noise belongs to the data, not to a candidate effect: declare \
                   `noise` at the top level of the model"
                .to_string(),
        });
    }
    let mut targets = Vec::new();
    let mut terms = Vec::new();
    for child in pair.clone().into_inner() {
        match child.as_rule() {
            Rule::ident => targets.push(ident(child)),
            _ => terms.push(noise_term(&child)?),
        }
    }
    Ok(NoiseDecl { targets, terms })
}

/// `-`? number, then `%` or an optional unit.
fn noise_term(pair: &Pair<Rule>) -> Result<NoiseTerm> {
    let span = span_of(pair);
    let mut negative = None;
    let mut number = None;
    let mut kind = NoiseKind::Absolute(None);
    for child in pair.clone().into_inner() {
        match child.as_rule() {
            Rule::neg => negative = Some(span_of(&child)),
            Rule::number => number = Some(child),
            Rule::percent => kind = NoiseKind::Relative,
            Rule::unit => kind = NoiseKind::Absolute(Some(super::unit::unit(&child)?)),
            _ => return Err(unexpected_shape(&child)),
        }
    }
    let number = number.ok_or_else(|| unexpected_shape(pair))?;
    let Expr::Num(magnitude) = primary(number.clone())?.node else {
        return Err(unexpected_shape(&number));
    };
    let literal = span_of(&number);
    let value = match negative {
        Some(sign) => Spanned::new(-magnitude, sign.join(literal)),
        None => Spanned::new(magnitude, literal),
    };
    Ok(NoiseTerm { value, kind, span })
}

fn assign_op(pair: &Pair<Rule>) -> Result<PatchOp> {
    match pair.as_rule() {
        Rule::mul_assign => Ok(PatchOp::Mul),
        Rule::add_assign => Ok(PatchOp::Add),
        Rule::set_assign => Ok(PatchOp::Set),
        _ => Err(unexpected_shape(pair)),
    }
}

fn patch(pair: &Pair<Rule>) -> Result<Patch> {
    let mut children = pair.clone().into_inner();
    let target = ident(next(&mut children, pair)?);
    let op_pair = next(&mut children, pair)?;
    let op = assign_op(&op_pair)?;
    let expr = expr(next(&mut children, pair)?)?;
    Ok(Patch {
        target,
        op,
        expr,
        op_span: span_of(&op_pair),
    })
}

fn integer(pair: &Pair<Rule>) -> Result<Spanned<u64>> {
    let text = pair.as_str();
    match text.parse::<u64>() {
        Ok(value) if value < (1 << 32) => Ok(Spanned::new(value, span_of(pair))),
        _ => Err(SyntaxError::BadNumber {
            span: span_of(pair).into(),
            text: text.to_string(),
        }),
    }
}

fn closure(pair: &Pair<Rule>) -> Result<ClosureDecl> {
    let mut children = pair.clone().into_inner();
    let name = ident(next(&mut children, pair)?);
    let items = children
        .map(|line| Ok(Spanned::new(closure_item(&line)?, span_of(&line))))
        .collect::<Result<Vec<_>>>()?;
    Ok(ClosureDecl { name, items })
}

fn closure_item(pair: &Pair<Rule>) -> Result<ClosureItem> {
    let children = pair.clone().into_inner();
    Ok(match pair.as_rule() {
        Rule::outputs_item => ClosureItem::Outputs(each_child(pair, closure_output)?),
        Rule::observe_item => ClosureItem::Observe(children.map(ident).collect()),
        Rule::embed_item => {
            let (mut delay, mut dim) = (None, None);
            for child in children {
                let value = first_child(&child)?;
                match child.as_rule() {
                    Rule::embed_delay => delay = Some(expr(value)?),
                    _ => dim = Some(integer(&value)?),
                }
            }
            ClosureItem::Embed { delay, dim }
        }
        Rule::network_item => {
            let (mut hidden, mut activation) = (None, None);
            for child in children {
                match child.as_rule() {
                    Rule::hidden_layers => {
                        let widths = child.clone().into_inner();
                        hidden = Some(widths.map(|w| integer(&w)).collect::<Result<_>>()?);
                    }
                    _ => activation = Some(ident(child)),
                }
            }
            ClosureItem::Network { hidden, activation }
        }
        Rule::prior_item => {
            let patch = patch(pair)?;
            ClosureItem::Prior(PriorDecl {
                target: patch.target,
                op: patch.op,
                expr: patch.expr,
            })
        }
        _ => return Err(unexpected_shape(pair)),
    })
}

fn closure_output(pair: Pair<Rule>) -> Result<ClosureOutputDecl> {
    let parts = entry_parts(&pair)?;
    let scale = parts.exprs.into_iter().next().map(expr).transpose()?;
    let constraint = parts.rest.into_iter().next().map(constraint).transpose()?;
    Ok(ClosureOutputDecl {
        name: parts.name,
        unit: parts.unit,
        scale,
        constraint,
    })
}

fn effect(source: &str, pair: &Pair<Rule>, place: Place) -> Result<EffectDecl> {
    if place == Place::Effect {
        return Err(SyntaxError::Misplaced {
            span: span_of(pair).into(),
            what: "an effect".to_string(),
            place: "inside another effect".to_string(),
            help: "declare effects at the top level; combine them when diagnosing".to_string(),
        });
    }
    let mut children = pair.clone().into_inner();
    let name = ident(next(&mut children, pair)?);
    let mut description = None;
    let mut items = Vec::new();
    for child in children {
        if child.as_rule() == Rule::string {
            description = Some(string_text(&child));
        } else {
            items.push(item(source, child, Place::Effect)?);
        }
    }
    Ok(EffectDecl {
        name,
        description,
        items,
    })
}

/// The `expr` rule, folded by precedence.
pub fn expr(pair: Pair<Rule>) -> Result<SExpr> {
    PRATT
        .map_primary(primary)
        .map_prefix(|op, operand| {
            let operand = operand?;
            let span = span_of(&op).join(operand.span);
            Ok(Spanned::new(Expr::Neg(Box::new(operand)), span))
        })
        .map_infix(|lhs, op, rhs| {
            let (lhs, rhs) = (lhs?, rhs?);
            let op = match op.as_rule() {
                Rule::add => BinOp::Add,
                Rule::sub => BinOp::Sub,
                Rule::mul => BinOp::Mul,
                Rule::div => BinOp::Div,
                _ => BinOp::Pow,
            };
            let span = lhs.span.join(rhs.span);
            Ok(Spanned::new(
                Expr::Binary(op, Box::new(lhs), Box::new(rhs)),
                span,
            ))
        })
        .parse(pair.into_inner())
}

fn primary(pair: Pair<Rule>) -> Result<SExpr> {
    let span = span_of(&pair);
    match pair.as_rule() {
        Rule::number => {
            let text = pair.as_str();
            match text.parse::<f64>() {
                Ok(value) if value.is_finite() => Ok(Spanned::new(Expr::Num(value), span)),
                _ => Err(SyntaxError::BadNumber {
                    span: span.into(),
                    text: text.to_string(),
                }),
            }
        }
        Rule::ident => Ok(Spanned::new(Expr::Name(pair.as_str().to_string()), span)),
        Rule::call => {
            let mut children = pair.clone().into_inner();
            let name = ident(next(&mut children, &pair)?);
            let args = children.map(expr).collect::<Result<Vec<_>>>()?;
            Ok(Spanned::new(Expr::Call(name, args), span))
        }
        Rule::expr => expr(pair),
        Rule::paren => {
            // The node keeps the span of its parentheses (the formatter keeps them).
            let inner = expr(first_child(&pair)?)?;
            Ok(Spanned::new(inner.node, span))
        }
        _ => Err(unexpected_shape(&pair)),
    }
}
