//! Structural checks: every state has exactly one balance, dynamics are not mixed, closures
//! are well formed and used, params start inside their constraints, effects patch real names.

use super::error::{suggest, CheckError};
use super::exprs::{names, Evaluator};
use super::sink::Sink;
use super::symbols::{effect_items, Kind, Scope, Symbols};
use crate::ast::{self, ClosureItem, Constraint, ItemKind, Span};
use crate::suggest::closest;
use crate::vocabulary::Activation;
use std::collections::{HashMap, HashSet};

type Values = HashMap<(Scope, String), f64>;

/// Runs the structural check families.
pub fn check_all(model: &ast::Model, symbols: &Symbols, values: &Values, sink: &mut Sink) {
    check_balances(model, symbols, sink);
    check_closures(model, symbols, values, sink);
    check_params(model, symbols, values, sink);
    check_effects(model, symbols, sink);
    check_inputs(model, symbols, values, sink);
}

fn const_value(expr: &ast::SExpr, scope: Scope, symbols: &Symbols, values: &Values) -> Option<f64> {
    let exprs = HashMap::new();
    let mut evaluator = Evaluator::new(symbols, &exprs, values.clone());
    evaluator.eval(expr, scope)
}

fn check_balances(model: &ast::Model, symbols: &Symbols, sink: &mut Sink) {
    let mut seen: HashMap<String, Span> = HashMap::new();
    let mut first_der: Option<Span> = None;
    let mut first_next: Option<Span> = None;
    let mut check_one = |eq: &ast::Equation, keyword: &str, scope: Scope, span: Span| {
        let name = &eq.name.node;
        match symbols.get(scope, name) {
            None => sink.push(CheckError::UnknownName {
                name: name.clone(),
                span: eq.name.span.into(),
                help: suggest(name, symbols.visible(scope), "state"),
            }),
            Some(symbol) if !symbol.kind.is_state() => sink.push(CheckError::BalanceOfNonState {
                keyword: keyword.to_string(),
                name: name.clone(),
                kind: symbol.kind.describe().to_string(),
                span: eq.name.span.into(),
                help: format!(
                    "only `state`s and `hidden` states have balances; {} is fixed by the data \
                         or the model",
                    name
                ),
            }),
            Some(_) => match seen.get(name) {
                Some(first) => sink.push(CheckError::TwoBalances {
                    name: name.clone(),
                    span: span.into(),
                    first: (*first).into(),
                }),
                None => {
                    seen.insert(name.clone(), span);
                }
            },
        }
    };
    let mut visit = |item: &ast::Item, scope: Scope| match &item.kind {
        ItemKind::Der(eq) => {
            first_der.get_or_insert(item.span);
            check_one(eq, "der", scope, item.span);
        }
        ItemKind::Next(eq) => {
            first_next.get_or_insert(item.span);
            check_one(eq, "next", scope, item.span);
        }
        _ => {}
    };
    for item in &model.items {
        visit(item, Scope::Model);
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            visit(item, Scope::Effect(index));
        }
    }
    if let (Some(der), Some(next)) = (first_der, first_next) {
        sink.push(CheckError::MixedDynamics {
            span: next.into(),
            first: der.into(),
        });
    }
    check_states_covered(model, symbols, &seen, sink);
}

fn check_states_covered(
    model: &ast::Model,
    symbols: &Symbols,
    balances: &HashMap<String, Span>,
    sink: &mut Sink,
) {
    let trainable = symbols
        .model
        .values()
        .any(|s| matches!(s.kind, Kind::Param | Kind::ClosureOutput(_)));
    let mut any_state = false;
    let mut visit = |item: &ast::Item| {
        let (states, hidden) = match &item.kind {
            ItemKind::State(states) => (states, false),
            ItemKind::Hidden(states) => (states, true),
            _ => return,
        };
        for binding in states {
            any_state |= !hidden;
            if !balances.contains_key(&binding.name.node) {
                sink.push(CheckError::NoBalance {
                    name: binding.name.node.clone(),
                    span: binding.name.span.into(),
                    help: format!(
                        "add `der {0} = ...` (or `next {0} = ...` in a discrete-time model)",
                        binding.name.node
                    ),
                });
            }
            if hidden && trainable && binding.value.is_none() {
                sink.push(CheckError::HiddenWithoutInit {
                    name: binding.name.node.clone(),
                    span: binding.name.span.into(),
                });
            }
        }
    };
    model.items.iter().for_each(&mut visit);
    effect_items(model)
        .flat_map(|e| &e.items)
        .for_each(&mut visit);
    if !any_state {
        sink.push(CheckError::NoStates {
            name: model.name.node.clone(),
            span: model.name.span.into(),
        });
    }
}

fn check_closures(model: &ast::Model, symbols: &Symbols, values: &Values, sink: &mut Sink) {
    let used = used_names(model);
    for item in &model.items {
        if let ItemKind::Closure(closure) = &item.kind {
            check_closure(closure, symbols, values, &used, sink);
        }
    }
}

/// Names used by the equations of the model and of its effects (a closure output that only
/// an effect uses is a learned correction waiting for that effect to be applied).
fn used_names(model: &ast::Model) -> HashSet<&str> {
    let mut used = HashSet::new();
    let items = model
        .items
        .iter()
        .chain(effect_items(model).flat_map(|e| &e.items));
    for item in items {
        match &item.kind {
            ItemKind::Let(eq)
            | ItemKind::Output(eq)
            | ItemKind::Der(eq)
            | ItemKind::DerPatch(eq)
            | ItemKind::Next(eq) => used.extend(names(&eq.expr).into_iter().map(|(n, _)| n)),
            ItemKind::Patch(patch) => used.extend(names(&patch.expr).into_iter().map(|(n, _)| n)),
            _ => {}
        }
    }
    used
}

/// Reports a repeated closure line.
fn once(seen: &mut HashMap<&'static str, Span>, what: &'static str, span: Span, sink: &mut Sink) {
    if seen.insert(what, span).is_some() {
        sink.push(CheckError::BadClosure {
            message: format!("closure has more than one `{what}` line"),
            span: span.into(),
            help: format!("merge the `{what}` lines into one"),
        });
    }
}

fn check_closure(
    closure: &ast::ClosureDecl,
    symbols: &Symbols,
    values: &Values,
    used: &HashSet<&str>,
    sink: &mut Sink,
) {
    let mut seen = HashMap::new();
    let mut outputs: Vec<&ast::ClosureOutputDecl> = Vec::new();
    let mut priors: HashMap<&str, Span> = HashMap::new();
    for line in &closure.items {
        match &line.node {
            ClosureItem::Outputs(list) => {
                once(&mut seen, "outputs", line.span, sink);
                outputs.extend(list);
            }
            ClosureItem::Observe(list) => {
                once(&mut seen, "observe", line.span, sink);
                for name in list {
                    check_observed(&closure.name.node, name, symbols, sink);
                }
            }
            ClosureItem::Embed { delay, dim } => {
                once(&mut seen, "embed", line.span, sink);
                check_embedding(
                    delay.as_ref(),
                    dim.as_ref(),
                    line.span,
                    symbols,
                    values,
                    sink,
                );
            }
            ClosureItem::Network { hidden, activation } => {
                once(&mut seen, "network", line.span, sink);
                check_network(hidden.as_deref(), activation.as_ref(), sink);
            }
            ClosureItem::Prior(prior) => {
                if let Some(first) = priors.insert(&prior.target.node, prior.target.span) {
                    let _ = first;
                    sink.push(CheckError::BadClosure {
                        message: format!("two priors for `{}`", prior.target.node),
                        span: prior.target.span.into(),
                        help: "combine them into one prior expression".to_string(),
                    });
                }
            }
        }
    }
    if outputs.is_empty() {
        sink.push(CheckError::BadClosure {
            message: format!("closure `{}` declares no outputs", closure.name.node),
            span: closure.name.span.into(),
            help: "add a line `outputs NAME ~ magnitude` naming the values it provides".to_string(),
        });
    }
    let output_names: Vec<&str> = outputs.iter().map(|o| o.name.node.as_str()).collect();
    for line in &closure.items {
        if let ClosureItem::Prior(prior) = &line.node {
            check_prior(&closure.name.node, prior, &output_names, symbols, sink);
        }
    }
    for output in outputs {
        if !used.contains(output.name.node.as_str()) {
            sink.push(CheckError::UnusedClosureOutput {
                name: output.name.node.clone(),
                span: output.name.span.into(),
            });
        }
        if let Some(constraint) = &output.constraint {
            check_bounds(constraint, None, "closure output", symbols, values, sink);
        }
    }
}

fn check_observed(closure: &str, name: &ast::Ident, symbols: &Symbols, sink: &mut Sink) {
    match symbols.get(Scope::Model, &name.node) {
        None => sink.push(CheckError::UnknownName {
            name: name.node.clone(),
            span: name.span.into(),
            help: suggest(&name.node, symbols.visible(Scope::Model), "name"),
        }),
        Some(symbol) if !matches!(symbol.kind, Kind::Input | Kind::State) => {
            sink.push(CheckError::BadObserve {
                closure: closure.to_string(),
                name: name.node.clone(),
                kind: symbol.kind.describe().to_string(),
                span: name.span.into(),
            })
        }
        Some(_) => {}
    }
}

fn check_embedding(
    delay: Option<&ast::SExpr>,
    dim: Option<&ast::Spanned<u64>>,
    line: Span,
    symbols: &Symbols,
    values: &Values,
    sink: &mut Sink,
) {
    if let Some(dim) = dim {
        if dim.node < 1 {
            sink.push(CheckError::BadEmbedding {
                message: "embedding dimension must be at least 1".to_string(),
                span: dim.span.into(),
                help: "`dim 1` uses only the current values; `dim 10` adds nine delayed copies"
                    .to_string(),
            });
        }
    }
    match delay {
        Some(delay) => {
            let value = const_value(delay, Scope::Model, symbols, values);
            if value.is_some_and(|v| v <= 0.0 || !v.is_finite()) {
                sink.push(CheckError::BadEmbedding {
                    message: format!(
                        "embedding delay must be positive, found {}",
                        value.unwrap_or(0.0)
                    ),
                    span: delay.span.into(),
                    help: "the delay is the time between lags, in the model's time unit"
                        .to_string(),
                });
            }
        }
        None if dim.is_some_and(|d| d.node > 1) => sink.push(CheckError::BadEmbedding {
            message: "an embedding with `dim` above 1 needs a `delay`".to_string(),
            span: line.into(),
            help: "write e.g. `embed delay 5 dim 10`".to_string(),
        }),
        None => {}
    }
}

fn check_network(
    hidden: Option<&[ast::Spanned<u64>]>,
    activation: Option<&ast::Ident>,
    sink: &mut Sink,
) {
    for width in hidden.unwrap_or_default() {
        if width.node == 0 || width.node > 100_000 {
            sink.push(CheckError::BadClosure {
                message: format!(
                    "hidden layer width must be between 1 and 100000, found {}",
                    width.node
                ),
                span: width.span.into(),
                help: "the paper uses `hidden [20, 20, 20]`".to_string(),
            });
        }
    }
    if let Some(activation) = activation {
        if Activation::from_name(&activation.node).is_none() {
            let names = Activation::ALL.map(|a| a.name());
            sink.push(CheckError::UnknownActivation {
                name: activation.node.clone(),
                span: activation.span.into(),
                help: match closest(&activation.node, names) {
                    Some(best) => format!("did you mean `{best}`?"),
                    None => format!("the activations are {}", names.join(", ")),
                },
            });
        }
    }
}

fn check_prior(
    closure: &str,
    prior: &ast::PriorDecl,
    outputs: &[&str],
    symbols: &Symbols,
    sink: &mut Sink,
) {
    if !outputs.contains(&prior.target.node.as_str()) {
        let help = match closest(&prior.target.node, outputs.iter().copied()) {
            Some(best) => format!("did you mean `{best}`?"),
            None => format!("its outputs are {}", outputs.join(", ")),
        };
        sink.push(CheckError::PriorTarget {
            name: prior.target.node.clone(),
            closure: closure.to_string(),
            span: prior.target.span.into(),
            help,
        });
    }
    for (name, span) in names(&prior.expr) {
        if let Some(symbol) = symbols.get(Scope::Model, name) {
            if matches!(symbol.kind, Kind::ClosureOutput(_)) {
                sink.push(CheckError::PriorUsesClosure {
                    target: prior.target.node.clone(),
                    name: name.to_string(),
                    span: span.into(),
                });
            }
        }
    }
}

/// Checks `in [lo, hi]` has lo < hi and, when `value` is given, that it lies inside.
fn check_bounds(
    constraint: &Constraint,
    value: Option<(f64, Span)>,
    what: &str,
    symbols: &Symbols,
    values: &Values,
    sink: &mut Sink,
) {
    let Constraint::Bounds(lo_expr, hi_expr) = constraint else {
        return;
    };
    let lo = const_value(lo_expr, Scope::Model, symbols, values);
    let hi = const_value(hi_expr, Scope::Model, symbols, values);
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return;
    };
    if lo >= hi || !lo.is_finite() || !hi.is_finite() {
        sink.push(CheckError::BadValue {
            message: format!("{what} bounds must satisfy lo < hi, found [{lo}, {hi}]"),
            span: lo_expr.span.join(hi_expr.span).into(),
            help: "write `in [lo, hi]` with the lower bound first".to_string(),
        });
        return;
    }
    if let Some((value, span)) = value {
        if value <= lo || value >= hi {
            sink.push(CheckError::BadValue {
                message: format!("initial value {value} is not strictly inside [{lo}, {hi}]"),
                span: span.into(),
                help: "start a bounded param strictly between its bounds".to_string(),
            });
        }
    }
}

fn check_params(model: &ast::Model, symbols: &Symbols, values: &Values, sink: &mut Sink) {
    let mut visit = |item: &ast::Item, scope: Scope| {
        let ItemKind::Param(params) = &item.kind else {
            return;
        };
        for param in params {
            let value = values.get(&(scope, param.name.node.clone())).copied();
            match (&param.constraint, value) {
                (Some(Constraint::Positive(_)), Some(v)) if v <= 0.0 => {
                    sink.push(CheckError::NonPositiveInit {
                        name: param.name.node.clone(),
                        value: v,
                        span: param.init.span.into(),
                    })
                }
                (Some(constraint), v) => check_bounds(
                    constraint,
                    v.map(|v| (v, param.init.span)),
                    "param",
                    symbols,
                    values,
                    sink,
                ),
                _ => {}
            }
        }
    };
    for item in &model.items {
        visit(item, Scope::Model);
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            visit(item, Scope::Effect(index));
        }
    }
}

fn check_inputs(model: &ast::Model, symbols: &Symbols, values: &Values, sink: &mut Sink) {
    for item in &model.items {
        if let ItemKind::Input(inputs) = &item.kind {
            for (lo, hi) in inputs.iter().filter_map(|i| i.bounds.clone()) {
                let bounds = Constraint::Bounds(lo, hi);
                check_bounds(&bounds, None, "input", symbols, values, sink);
            }
        }
    }
}

/// What effects may patch, in words.
const PATCHABLE: &str = "effects may patch a const, a `let`, an `output` or a closure output, \
                         and add to a balance with `der X += ...`";

fn check_effects(model: &ast::Model, symbols: &Symbols, sink: &mut Sink) {
    for (index, effect) in effect_items(model).enumerate() {
        let scope = Scope::Effect(index);
        for item in &effect.items {
            match &item.kind {
                ItemKind::Patch(patch) => {
                    check_patch(&effect.name.node, patch, scope, symbols, sink)
                }
                ItemKind::DerPatch(eq) => match symbols.get(scope, &eq.name.node) {
                    None => sink.push(CheckError::UnknownPatchTarget {
                        effect: effect.name.node.clone(),
                        name: eq.name.node.clone(),
                        span: eq.name.span.into(),
                        help: suggest(&eq.name.node, symbols.visible(scope), "state"),
                    }),
                    Some(symbol) if !symbol.kind.is_state() => {
                        sink.push(CheckError::NotPatchable {
                            name: eq.name.node.clone(),
                            kind: symbol.kind.describe().to_string(),
                            span: eq.name.span.into(),
                            help: "`der X += ...` adds a term to the balance of a state"
                                .to_string(),
                        })
                    }
                    Some(_) => {}
                },
                _ => {}
            }
        }
    }
}

fn check_patch(effect: &str, patch: &ast::Patch, scope: Scope, symbols: &Symbols, sink: &mut Sink) {
    let name = &patch.target.node;
    match symbols.get(scope, name) {
        None => sink.push(CheckError::UnknownPatchTarget {
            effect: effect.to_string(),
            name: name.clone(),
            span: patch.target.span.into(),
            help: suggest(name, symbols.visible(scope), "name"),
        }),
        Some(symbol) => {
            let patchable = matches!(
                symbol.kind,
                Kind::Const | Kind::Let | Kind::Output | Kind::ClosureOutput(_)
            );
            if !patchable {
                let help = if symbol.kind.is_state() {
                    format!("to change the dynamics of `{name}`, write `der {name} += ...`")
                } else {
                    PATCHABLE.to_string()
                };
                sink.push(CheckError::NotPatchable {
                    name: name.clone(),
                    kind: symbol.kind.describe().to_string(),
                    span: patch.target.span.into(),
                    help,
                });
            }
        }
    }
}
