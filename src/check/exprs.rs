//! Expression checks: names resolve, functions exist with the right arity, constant
//! expressions are constant, definitions are acyclic; and evaluation of constants.

use super::error::{suggest, CheckError};
use super::sink::Sink;
use super::symbols::{effect_items, Kind, Scope, Symbols};
use crate::ast::{self, Expr, ItemKind, SExpr, Span};
use crate::suggest::closest;
use crate::vocabulary::Func;
use std::collections::HashMap;

/// What an expression is allowed to refer to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Context {
    /// Consts only (const values, bounds, magnitudes, delays, param initial values).
    Constant,
    /// Consts and params (initial values of states).
    Initial,
    /// Anything (balances, lets, outputs, patches).
    Dynamic,
    /// Anything but closure outputs (priors).
    Prior,
}

/// One expression of the model with where it sits.
pub struct Site<'a> {
    /// The expression.
    pub expr: &'a SExpr,
    /// The scope names resolve in.
    pub scope: Scope,
    /// What it may refer to.
    pub context: Context,
    /// What it is, in words (for messages).
    pub what: &'static str,
}

/// Every expression of the model, with its scope and context.
pub fn sites(model: &ast::Model) -> Vec<Site<'_>> {
    let mut out = Vec::new();
    for item in &model.items {
        if let ItemKind::Effect(_) = item.kind {
            continue;
        }
        item_sites(item, Scope::Model, &mut out);
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            item_sites(item, Scope::Effect(index), &mut out);
        }
    }
    out
}

fn item_sites<'a>(item: &'a ast::Item, scope: Scope, out: &mut Vec<Site<'a>>) {
    let mut push = |expr: &'a SExpr, context: Context, what: &'static str| {
        out.push(Site {
            expr,
            scope,
            context,
            what,
        })
    };
    match &item.kind {
        ItemKind::Input(inputs) => {
            for (lo, hi) in inputs.iter().filter_map(|i| i.bounds.as_ref()) {
                push(lo, Context::Constant, "an input bound");
                push(hi, Context::Constant, "an input bound");
            }
        }
        ItemKind::State(states) | ItemKind::Hidden(states) => {
            for value in states.iter().filter_map(|b| b.value.as_ref()) {
                push(value, Context::Initial, "an initial value");
            }
        }
        ItemKind::Const(consts) => {
            for value in consts.iter().filter_map(|b| b.value.as_ref()) {
                push(value, Context::Constant, "a const value");
            }
        }
        ItemKind::Param(params) => {
            for param in params {
                push(&param.init, Context::Constant, "a param's initial value");
                if let Some(ast::Constraint::Bounds(lo, hi)) = &param.constraint {
                    push(lo, Context::Constant, "a param bound");
                    push(hi, Context::Constant, "a param bound");
                }
            }
        }
        ItemKind::Let(eq)
        | ItemKind::Output(eq)
        | ItemKind::Der(eq)
        | ItemKind::DerPatch(eq)
        | ItemKind::Next(eq) => push(&eq.expr, Context::Dynamic, "an equation"),
        ItemKind::Patch(patch) => push(&patch.expr, Context::Dynamic, "a patch"),
        ItemKind::Closure(closure) => {
            for line in &closure.items {
                match &line.node {
                    ast::ClosureItem::Outputs(outputs) => {
                        for output in outputs {
                            if let Some(scale) = &output.scale {
                                push(scale, Context::Constant, "a magnitude `~`");
                            }
                            if let Some(ast::Constraint::Bounds(lo, hi)) = &output.constraint {
                                push(lo, Context::Constant, "an output bound");
                                push(hi, Context::Constant, "an output bound");
                            }
                        }
                    }
                    ast::ClosureItem::Embed {
                        delay: Some(delay), ..
                    } => push(delay, Context::Constant, "an embedding delay"),
                    ast::ClosureItem::Prior(prior) => push(&prior.expr, Context::Prior, "a prior"),
                    _ => {}
                }
            }
        }
        ItemKind::Time(_) | ItemKind::Effect(_) | ItemKind::Noise(_) => {}
    }
}

/// Calls `visit` on every node of `expr`, parents first.
pub fn walk<'a>(expr: &'a SExpr, visit: &mut impl FnMut(&'a SExpr)) {
    visit(expr);
    match &expr.node {
        Expr::Num(_) | Expr::Name(_) => {}
        Expr::Neg(inner) => walk(inner, visit),
        Expr::Binary(_, lhs, rhs) => {
            walk(lhs, visit);
            walk(rhs, visit);
        }
        Expr::Call(_, args) => args.iter().for_each(|arg| walk(arg, visit)),
    }
}

/// The names an expression refers to, with their spans.
pub fn names(expr: &SExpr) -> Vec<(&str, Span)> {
    let mut out = Vec::new();
    walk(expr, &mut |node| {
        if let Expr::Name(name) = &node.node {
            out.push((name.as_str(), node.span));
        }
    });
    out
}

/// Unknown names, unknown functions, wrong arity, and names a context does not allow.
pub fn check_names(model: &ast::Model, symbols: &Symbols, sink: &mut Sink) {
    for site in sites(model) {
        walk(site.expr, &mut |node| match &node.node {
            Expr::Name(name) => match symbols.get(site.scope, name) {
                None => sink.push(CheckError::UnknownName {
                    name: name.clone(),
                    span: node.span.into(),
                    help: suggest(name, symbols.visible(site.scope), "name"),
                }),
                Some(symbol) => check_context(&site, name, symbol.kind, node.span, sink),
            },
            Expr::Call(function, args) => check_call(function, args.len(), node.span, sink),
            _ => {}
        });
    }
}

fn check_context(site: &Site, name: &str, kind: Kind, span: Span, sink: &mut Sink) {
    let allowed = match site.context {
        Context::Constant => kind == Kind::Const,
        Context::Initial => matches!(kind, Kind::Const | Kind::Param),
        Context::Dynamic => true,
        Context::Prior => !matches!(kind, Kind::ClosureOutput(_)),
    };
    if allowed {
        return;
    }
    if site.context == Context::Prior {
        // Reported with the prior's target by the closure checks.
        return;
    }
    let help = match site.context {
        Context::Initial => "initial values may use numbers, consts and params",
        _ => "this value may use numbers and consts only",
    };
    sink.push(CheckError::NotConstant {
        what: site.what.to_string(),
        name: name.to_string(),
        kind: kind.describe().to_string(),
        span: span.into(),
        help: help.to_string(),
    });
}

fn check_call(function: &ast::Ident, found: usize, span: Span, sink: &mut Sink) {
    let Some(func) = Func::from_name(&function.node) else {
        sink.push(CheckError::UnknownFunction {
            name: function.node.clone(),
            span: function.span.into(),
            help: match closest(&function.node, Func::ALL.iter().map(|f| f.name())) {
                Some(best) => format!("did you mean `{best}`?"),
                None => format!(
                    "the functions are {}",
                    Func::ALL.map(|f| f.name()).join(", ")
                ),
            },
        });
        return;
    };
    let expected = func.arity();
    if expected != found {
        let params = if expected == 1 { "x" } else { "a, b" };
        sink.push(CheckError::Arity {
            name: function.node.clone(),
            expected,
            plural: if expected == 1 { "" } else { "s" },
            found,
            span: span.into(),
            help: format!("write `{}({params})`", func.name()),
        });
    }
}

/// A definition that may refer to others: a `let`, `output` or `const`.
struct Definition<'a> {
    scope: Scope,
    name: &'a ast::Ident,
    expr: &'a SExpr,
}

fn definitions(model: &ast::Model) -> Vec<Definition<'_>> {
    let mut out = Vec::new();
    for item in &model.items {
        push_definitions(item, Scope::Model, &mut out);
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            push_definitions(item, Scope::Effect(index), &mut out);
        }
    }
    out
}

fn push_definitions<'a>(item: &'a ast::Item, scope: Scope, out: &mut Vec<Definition<'a>>) {
    match &item.kind {
        ItemKind::Let(eq) | ItemKind::Output(eq) => out.push(Definition {
            scope,
            name: &eq.name,
            expr: &eq.expr,
        }),
        ItemKind::Const(consts) => {
            for binding in consts {
                if let Some(expr) = &binding.value {
                    out.push(Definition {
                        scope,
                        name: &binding.name,
                        expr,
                    });
                }
            }
        }
        _ => {}
    }
}

/// Cycles among `let`s, `output`s and `const`s (each reported once, at its first member).
pub fn check_cycles(model: &ast::Model, symbols: &Symbols, sink: &mut Sink) {
    let defs = definitions(model);
    let index: HashMap<(Scope, &str), usize> = defs
        .iter()
        .enumerate()
        .map(|(i, d)| ((d.scope, d.name.node.as_str()), i))
        .collect();
    let lookup = |scope: Scope, name: &str| -> Option<usize> {
        index
            .get(&(scope, name))
            .or_else(|| index.get(&(Scope::Model, name)))
            .copied()
            .filter(|_| symbols.get(scope, name).is_some())
    };
    let edges: Vec<Vec<usize>> = defs
        .iter()
        .map(|d| {
            names(d.expr)
                .into_iter()
                .filter_map(|(name, _)| lookup(d.scope, name))
                .collect()
        })
        .collect();
    let mut state = vec![0u8; defs.len()]; // 0 new, 1 on the path, 2 done
    for start in 0..defs.len() {
        let mut path = Vec::new();
        if let Some(cycle) = find_cycle(start, &edges, &mut state, &mut path) {
            let first = cycle[0];
            let mut words: Vec<&str> = cycle.iter().map(|&i| defs[i].name.node.as_str()).collect();
            words.push(defs[first].name.node.as_str());
            sink.push(CheckError::Cycle {
                cycle: words.join(" -> "),
                span: defs[first].name.span.into(),
            });
        }
    }
}

/// Depth-first search from `node`; returns the nodes of the first cycle found.
fn find_cycle(
    node: usize,
    edges: &[Vec<usize>],
    state: &mut [u8],
    path: &mut Vec<usize>,
) -> Option<Vec<usize>> {
    match state[node] {
        2 => return None,
        1 => {
            let at = path.iter().position(|&n| n == node).unwrap_or(0);
            return Some(path[at..].to_vec());
        }
        _ => {}
    }
    state[node] = 1;
    path.push(node);
    for &next in &edges[node] {
        if let Some(cycle) = find_cycle(next, edges, state, path) {
            // Mark the rest of the path done so the cycle is reported once.
            for &n in path.iter() {
                state[n] = 2;
            }
            return Some(cycle);
        }
    }
    path.pop();
    state[node] = 2;
    None
}

/// Evaluates every const value and param initial value (after the name checks; errors in
/// them were already reported, so failures here are silent).
pub fn evaluate_constants(
    model: &ast::Model,
    symbols: &Symbols,
    sink: &mut Sink,
) -> HashMap<(Scope, String), f64> {
    let mut exprs: HashMap<(Scope, String), &SExpr> = HashMap::new();
    let mut param_exprs = Vec::new();
    for item in &model.items {
        collect_values(item, Scope::Model, &mut exprs, &mut param_exprs);
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            collect_values(item, Scope::Effect(index), &mut exprs, &mut param_exprs);
        }
    }
    let mut evaluator = Evaluator {
        symbols,
        exprs: &exprs,
        values: HashMap::new(),
        depth: 0,
    };
    let keys: Vec<(Scope, String)> = exprs.keys().cloned().collect();
    for key in keys {
        if let Some(value) = evaluator.constant(key.0, &key.1) {
            check_finite(value, exprs[&key], sink);
        }
    }
    for (scope, name, init) in param_exprs {
        if let Some(value) = evaluator.eval(init, scope) {
            check_finite(value, init, sink);
            evaluator.values.insert((scope, name), value);
        }
    }
    evaluator.values
}

type ParamInits<'a> = Vec<(Scope, String, &'a SExpr)>;

fn collect_values<'a>(
    item: &'a ast::Item,
    scope: Scope,
    exprs: &mut HashMap<(Scope, String), &'a SExpr>,
    params: &mut ParamInits<'a>,
) {
    match &item.kind {
        ItemKind::Const(consts) => {
            for binding in consts {
                if let Some(expr) = &binding.value {
                    exprs.insert((scope, binding.name.node.clone()), expr);
                }
            }
        }
        ItemKind::Param(list) => {
            for param in list {
                params.push((scope, param.name.node.clone(), &param.init));
            }
        }
        _ => {}
    }
}

fn check_finite(value: f64, expr: &SExpr, sink: &mut Sink) {
    if !value.is_finite() {
        sink.push(CheckError::BadValue {
            message: format!("this constant evaluates to {value}"),
            span: expr.span.into(),
            help: "constants must be finite numbers".to_string(),
        });
    }
}

/// Evaluates constant expressions over consts (and, once known, params).
pub struct Evaluator<'a> {
    symbols: &'a Symbols,
    exprs: &'a HashMap<(Scope, String), &'a SExpr>,
    /// Values computed so far.
    pub values: HashMap<(Scope, String), f64>,
    depth: usize,
}

impl<'a> Evaluator<'a> {
    /// An evaluator over the given definitions, starting from known `values`.
    pub fn new(
        symbols: &'a Symbols,
        exprs: &'a HashMap<(Scope, String), &'a SExpr>,
        values: HashMap<(Scope, String), f64>,
    ) -> Self {
        Evaluator {
            symbols,
            exprs,
            values,
            depth: 0,
        }
    }

    fn constant(&mut self, scope: Scope, name: &str) -> Option<f64> {
        let key = (scope, name.to_string());
        if let Some(value) = self.values.get(&key) {
            return Some(*value);
        }
        // Cycles were reported by check_cycles; the depth bound only stops the recursion.
        if self.depth > 256 {
            return None;
        }
        let expr = self.exprs.get(&key)?;
        self.depth += 1;
        let value = self.eval(expr, scope);
        self.depth -= 1;
        let value = value?;
        self.values.insert(key, value);
        Some(value)
    }

    /// The value of a constant expression, or `None` if it uses something non-constant.
    pub fn eval(&mut self, expr: &SExpr, scope: Scope) -> Option<f64> {
        Some(match &expr.node {
            Expr::Num(value) => *value,
            Expr::Name(name) => {
                let owner = match scope {
                    Scope::Effect(i) if self.symbols.effects.get(i)?.contains_key(name) => scope,
                    _ => Scope::Model,
                };
                match self.symbols.get(scope, name)?.kind {
                    Kind::Const => self.constant(owner, name)?,
                    Kind::Param => *self.values.get(&(owner, name.clone()))?,
                    _ => return None,
                }
            }
            Expr::Neg(inner) => -self.eval(inner, scope)?,
            Expr::Binary(op, lhs, rhs) => {
                let (a, b) = (self.eval(lhs, scope)?, self.eval(rhs, scope)?);
                op.apply(a, b)
            }
            Expr::Call(function, args) => {
                let func = Func::from_name(&function.node)?;
                let a = self.eval(args.first()?, scope)?;
                let b = match args.get(1) {
                    Some(arg) => self.eval(arg, scope)?,
                    None => 0.0,
                };
                func.apply(a, b)
            }
        })
    }
}
