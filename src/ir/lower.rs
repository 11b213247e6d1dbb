//! Lowering: a [`Checked`] model (plus the effects to apply) becomes an [`ir::Model`](Model).
//!
//! Names are resolved to [`Var`]s; `let`s and `output`s are inlined; an applied effect adds
//! its params and hidden states and its patches are folded into every use of the patched
//! name (`NAME *= e`, `+=`, `:=`) or into the patched balance (`der X += e`). Inside a patch
//! expression the patched name means its value before that patch.

use super::*;
use crate::ast::{self, ItemKind, PatchOp, SExpr, Span};
use crate::check::{Checked, Scope};
use miette::Diagnostic;
use std::collections::HashMap;
use thiserror::Error;

use items::{closure_outputs, combine};

mod items;
mod terms;

pub use terms::{effect_violations, NegativeLearnedTerm};

/// The most nested definitions (lets through lets, or patches) lowering follows.
const MAX_DEPTH: usize = 256;
/// The most expression nodes one inlined expression may have.
const MAX_NODES: usize = 2_000_000;

/// A problem found while lowering a checked model.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum LowerError {
    /// An effect name that the model does not declare.
    #[error("unknown effect `{name}`")]
    #[diagnostic(code(gbm::E0130))]
    UnknownEffect {
        /// The name asked for.
        name: String,
        /// The effects the model has.
        #[help]
        help: String,
    },
    /// `let`s (or patches) nested deeper than lowering follows.
    #[error("definitions nest more than {limit} levels deep")]
    #[diagnostic(
        code(gbm::E0131),
        help("each `let` used inside another adds a level; flatten the chain of definitions")
    )]
    NestingTooDeep {
        /// The limit.
        limit: usize,
        /// Where the limit was crossed.
        #[label("while inlining this")]
        span: miette::SourceSpan,
    },
    /// Inlining produced an enormous expression.
    #[error("expression too large after inlining `let`s ({nodes} nodes)")]
    #[diagnostic(
        code(gbm::E0132),
        help("a `let` used many times inside other `let`s is copied each time; simplify the definitions")
    )]
    TooLarge {
        /// Node count reached.
        nodes: usize,
        /// Where.
        #[label("inlining this")]
        span: miette::SourceSpan,
    },
    /// A prior that depends on a closure output through a `let`.
    #[error("prior for `{target}` depends on a closure output through `let`s")]
    #[diagnostic(
        code(gbm::E0133),
        help("priors may use states, inputs, consts and params only; the network's output cannot feed its own prior")
    )]
    PriorUsesClosure {
        /// The prior target.
        target: String,
        /// The prior expression.
        #[label("this prior")]
        span: miette::SourceSpan,
    },
    /// A term of a `nonnegative` state's balance that uses a closure output and is not
    /// provably `>= 0` where the state is 0 ([`super::nonnegative`]).
    #[error(transparent)]
    #[diagnostic(transparent)]
    NegativeLearnedTerm(Box<NegativeLearnedTerm>),
}

type Key = (Scope, String);

/// Lowers `checked` with the named effects applied (in the order given); the first error.
pub fn lower(checked: &Checked, effects: &[&str]) -> Result<Model, LowerError> {
    lower_reporting(checked, effects).map_err(|mut errors| errors.swap_remove(0))
}

/// [`lower`], with every error found: every term of a `nonnegative` state's balance that
/// is not proven (E0136) is reported, in source order (other errors stop lowering).
pub fn lower_reporting(checked: &Checked, effects: &[&str]) -> Result<Model, Vec<LowerError>> {
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
    if errors.is_empty() {
        Ok(model)
    } else {
        Err(errors)
    }
}

/// Items of the model and of the applied effects, each with its scope.
fn scoped_items<'a>(
    checked: &'a Checked,
    effects: &[&'a ast::EffectDecl],
    applied: &[usize],
) -> Vec<(Scope, &'a ast::Item)> {
    let mut items: Vec<(Scope, &ast::Item)> = checked
        .ast
        .items
        .iter()
        .filter(|i| !matches!(i.kind, ItemKind::Effect(_)))
        .map(|i| (Scope::Model, i))
        .collect();
    for &index in applied {
        items.extend(
            effects[index]
                .items
                .iter()
                .map(|i| (Scope::Effect(index), i)),
        );
    }
    items
}

struct Lowerer<'a> {
    checked: &'a Checked,
    effects: Vec<&'a ast::EffectDecl>,
    items: Vec<(Scope, &'a ast::Item)>,
    vars: HashMap<Key, Var>,
    definitions: HashMap<Key, &'a SExpr>,
    patches: HashMap<Key, Vec<(Scope, &'a ast::Patch)>>,
    limits: HashMap<Key, usize>,
    depth: usize,
    nodes: usize,
    /// Where each `nonnegative` state (by name) is declared so.
    nonnegative: HashMap<String, Span>,
    /// Terms of `nonnegative` states' balances not proven (E0136).
    violations: Vec<LowerError>,
}

impl<'a> Lowerer<'a> {
    fn new(checked: &'a Checked, effects: &[&'a ast::EffectDecl], applied: &[usize]) -> Self {
        let items = scoped_items(checked, effects, applied);
        let mut lowerer = Lowerer {
            checked,
            effects: effects.to_vec(),
            items,
            vars: HashMap::new(),
            definitions: HashMap::new(),
            patches: HashMap::new(),
            limits: HashMap::new(),
            depth: 0,
            nodes: 0,
            nonnegative: HashMap::new(),
            violations: Vec::new(),
        };
        lowerer.index();
        lowerer
    }

    /// The scope that declares `name` as seen from `scope`.
    fn owner(&self, scope: Scope, name: &str) -> Scope {
        match scope {
            Scope::Effect(i) if self.checked.symbols.effects[i].contains_key(name) => scope,
            _ => Scope::Model,
        }
    }

    fn index(&mut self) {
        let mut counts = [0usize; 5];
        let mut closure = 0;
        for (scope, item) in self.items.clone() {
            let mut add = |slot: usize, name: &ast::Ident, make: fn(usize) -> Var| {
                self.vars
                    .insert((scope, name.node.clone()), make(counts[slot]));
                counts[slot] += 1;
            };
            match &item.kind {
                ItemKind::Input(list) => list.iter().for_each(|i| add(0, &i.name, Var::Input)),
                ItemKind::State(list) => list.iter().for_each(|b| add(1, &b.name, Var::State)),
                ItemKind::Hidden(list) => list.iter().for_each(|b| add(2, &b.name, Var::Hidden)),
                ItemKind::Const(list) => list.iter().for_each(|b| add(3, &b.name, Var::Const)),
                ItemKind::Param(list) => list.iter().for_each(|p| add(4, &p.name, Var::Param)),
                ItemKind::Let(eq) | ItemKind::Output(eq) => {
                    self.definitions
                        .insert((scope, eq.name.node.clone()), &eq.expr);
                }
                ItemKind::Patch(patch) => {
                    let key = (
                        self.owner(scope, &patch.target.node),
                        patch.target.node.clone(),
                    );
                    self.patches.entry(key).or_default().push((scope, patch));
                }
                ItemKind::Closure(decl) => {
                    for (output, name) in closure_outputs(decl).into_iter().enumerate() {
                        let var = Var::ClosureOutput { closure, output };
                        self.vars.insert((scope, name.node.clone()), var);
                    }
                    closure += 1;
                }
                _ => {}
            }
        }
    }

    fn count(&mut self, span: Span) -> Result<(), LowerError> {
        self.nodes += 1;
        if self.nodes > MAX_NODES {
            return Err(LowerError::TooLarge {
                nodes: self.nodes,
                span: span.into(),
            });
        }
        Ok(())
    }

    /// Lowers an expression written in `scope`.
    fn expr(&mut self, expr: &SExpr, scope: Scope) -> Result<Expr, LowerError> {
        self.count(expr.span)?;
        Ok(match &expr.node {
            ast::Expr::Num(value) => Expr::Num(*value),
            ast::Expr::Name(name) => self.resolve(scope, name, expr.span)?,
            ast::Expr::Neg(inner) => Expr::Neg(Box::new(self.expr(inner, scope)?)),
            ast::Expr::Binary(op, lhs, rhs) => Expr::Bin(
                *op,
                Box::new(self.expr(lhs, scope)?),
                Box::new(self.expr(rhs, scope)?),
            ),
            ast::Expr::Call(function, args) => {
                // Names and arity were checked; an unknown function cannot reach here.
                let func = Func::from_name(&function.node).unwrap_or(Func::Exp);
                let args = args
                    .iter()
                    .map(|a| self.expr(a, scope))
                    .collect::<Result<_, _>>()?;
                Expr::Call(func, args)
            }
        })
    }

    /// The value of `name` as seen from `scope`: its definition with all patches applied
    /// (or, inside a patch of `name`, with the patches before that one).
    fn resolve(&mut self, scope: Scope, name: &str, span: Span) -> Result<Expr, LowerError> {
        let key = (self.owner(scope, name), name.to_string());
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(LowerError::NestingTooDeep {
                limit: MAX_DEPTH,
                span: span.into(),
            });
        }
        let mut value = match (self.vars.get(&key), self.definitions.get(&key)) {
            (Some(var), _) => Expr::Var(*var),
            (None, Some(definition)) => {
                let definition = *definition;
                self.expr(definition, key.0)?
            }
            (None, None) => Expr::Num(f64::NAN),
        };
        let patches = self.patches.get(&key).cloned().unwrap_or_default();
        let limit = self.limits.get(&key).copied().unwrap_or(patches.len());
        for (k, (patch_scope, patch)) in patches.iter().take(limit).enumerate() {
            let saved = self.limits.insert(key.clone(), k);
            let term = self.expr(&patch.expr, *patch_scope);
            match saved {
                Some(previous) => self.limits.insert(key.clone(), previous),
                None => self.limits.remove(&key),
            };
            value = combine(value, patch.op, term?);
        }
        self.depth -= 1;
        Ok(value)
    }

    fn constant(&self, expr: &SExpr, scope: Scope) -> f64 {
        self.checked.constant(expr, scope).unwrap_or(f64::NAN)
    }

    fn build(&mut self) -> Result<Model, LowerError> {
        let ast = &self.checked.ast;
        let mut model = Model {
            name: ast.name.node.clone(),
            description: ast.description.clone(),
            time_unit: None,
            inputs: Vec::new(),
            states: Vec::new(),
            hidden: Vec::new(),
            consts: Vec::new(),
            params: Vec::new(),
            lets: Vec::new(),
            outputs: Vec::new(),
            closures: Vec::new(),
            dynamics: Dynamics::Continuous,
            balances: Vec::new(),
            effects: Vec::new(),
            units: Units::default(),
            noise: Vec::new(),
        };
        let mut balance_items: HashMap<String, (Scope, &ast::Equation)> = HashMap::new();
        let mut balance_patches: Vec<(Scope, &ast::Equation)> = Vec::new();
        for (scope, item) in self.items.clone() {
            match &item.kind {
                ItemKind::Time(unit) => model.time_unit = Some(unit.node.clone()),
                ItemKind::Input(list) => {
                    for input in list {
                        let bounds = input
                            .bounds
                            .as_ref()
                            .map(|(lo, hi)| (self.constant(lo, scope), self.constant(hi, scope)));
                        model.inputs.push(Input {
                            name: input.name.node.clone(),
                            bounds,
                        });
                    }
                }
                ItemKind::State(list) => model.states.extend(self.states(list, scope)?),
                ItemKind::Hidden(list) => model.hidden.extend(self.states(list, scope)?),
                ItemKind::Const(list) => {
                    for binding in list {
                        let key = (scope, binding.name.node.clone());
                        model.consts.push(Const {
                            name: binding.name.node.clone(),
                            value: self.checked.values.get(&key).copied().unwrap_or(f64::NAN),
                        });
                    }
                }
                ItemKind::Param(list) => model
                    .params
                    .extend(list.iter().map(|p| self.param(p, scope))),
                ItemKind::Let(eq) if scope == Scope::Model => {
                    let expr = self.resolve(scope, &eq.name.node, eq.name.span)?;
                    model.lets.push(Definition {
                        name: eq.name.node.clone(),
                        expr,
                    });
                }
                ItemKind::Output(eq) => {
                    let expr = self.resolve(scope, &eq.name.node, eq.name.span)?;
                    model.outputs.push(Definition {
                        name: eq.name.node.clone(),
                        expr,
                    });
                }
                ItemKind::Closure(decl) => model.closures.push(self.closure(decl)?),
                ItemKind::Der(eq) => {
                    balance_items.insert(eq.name.node.clone(), (scope, eq));
                }
                ItemKind::Next(eq) => {
                    model.dynamics = Dynamics::Discrete;
                    balance_items.insert(eq.name.node.clone(), (scope, eq));
                }
                ItemKind::DerPatch(eq) => balance_patches.push((scope, eq)),
                _ => {}
            }
        }
        model.balances = self.balances(&model, &balance_items, &balance_patches)?;
        self.violations = self.nonnegative_violations(&model, &balance_items, &balance_patches)?;
        model.effects = self.effects();
        model.units = self.units();
        model.noise = super::noise::lower_noise(&self.checked.noise, &model);
        Ok(model)
    }

    fn states(&mut self, list: &[ast::Binding], scope: Scope) -> Result<Vec<State>, LowerError> {
        list.iter()
            .map(|binding| {
                let init = match &binding.value {
                    Some(value) => Some(self.expr(value, scope)?),
                    None => None,
                };
                if let Some(span) = binding.nonnegative {
                    self.nonnegative.insert(binding.name.node.clone(), span);
                }
                Ok(State {
                    name: binding.name.node.clone(),
                    init,
                    nonnegative: binding.nonnegative.is_some(),
                })
            })
            .collect()
    }

    fn param(&self, param: &ast::ParamDecl, scope: Scope) -> Param {
        let key = (scope, param.name.node.clone());
        Param {
            name: param.name.node.clone(),
            init: self.checked.values.get(&key).copied().unwrap_or(f64::NAN),
            constraint: self.constraint(param.constraint.as_ref(), scope),
        }
    }

    fn constraint(&self, constraint: Option<&ast::Constraint>, scope: Scope) -> Constraint {
        match constraint {
            None => Constraint::Free,
            Some(ast::Constraint::Positive(_)) => Constraint::Positive,
            Some(ast::Constraint::Bounds(lo, hi)) => {
                Constraint::Bounds(self.constant(lo, scope), self.constant(hi, scope))
            }
        }
    }
}

/// Whether an expression refers to any closure output.
pub fn uses_closure(expr: &Expr) -> bool {
    match expr {
        Expr::Var(Var::ClosureOutput { .. }) => true,
        Expr::Num(_) | Expr::Var(_) => false,
        Expr::Neg(inner) => uses_closure(inner),
        Expr::Bin(_, a, b) => uses_closure(a) || uses_closure(b),
        Expr::Call(_, args) => args.iter().any(uses_closure),
    }
}
