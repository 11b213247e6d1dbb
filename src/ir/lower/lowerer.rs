//! The lowerer: the model's items with their scopes, every name's variable or definition,
//! and the lowering of expressions (lets inlined, patches folded in) and of the declarations
//! into the compiled model.

use super::error::LowerError;
use crate::ast::{self, BinOp, ItemKind, PatchOp, SExpr, Span};
use crate::check::{Checked, Scope};
use crate::ir::model::{
    Const, Constraint, Definition, Dynamics, Expr, Input, Model, Param, State, Units, Var,
};
use crate::vocabulary::Func;
use std::collections::HashMap;

/// The most nested definitions (lets through lets, or patches) lowering follows.
pub(super) const MAX_DEPTH: usize = 256;
/// The most expression nodes one inlined expression may have.
pub(super) const MAX_NODES: usize = 2_000_000;

/// A name as its declaring scope sees it.
pub(super) type Key = (Scope, String);

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

/// Lowers one checked model: what it has indexed, and the limits it keeps to.
pub(super) struct Lowerer<'a> {
    pub(super) checked: &'a Checked,
    pub(super) effects: Vec<&'a ast::EffectDecl>,
    pub(super) items: Vec<(Scope, &'a ast::Item)>,
    pub(super) vars: HashMap<Key, Var>,
    pub(super) definitions: HashMap<Key, &'a SExpr>,
    pub(super) patches: HashMap<Key, Vec<(Scope, &'a ast::Patch)>>,
    pub(super) limits: HashMap<Key, usize>,
    pub(super) depth: usize,
    pub(super) nodes: usize,
    /// Where each `nonnegative` state (by name) is declared so.
    pub(super) nonnegative: HashMap<String, Span>,
    /// Terms of `nonnegative` states' balances not proven (E0136).
    pub(super) violations: Vec<LowerError>,
}

impl<'a> Lowerer<'a> {
    pub(super) fn new(
        checked: &'a Checked,
        effects: &[&'a ast::EffectDecl],
        applied: &[usize],
    ) -> Self {
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
    pub(super) fn owner(&self, scope: Scope, name: &str) -> Scope {
        match scope {
            Scope::Effect(i) if self.checked.symbols.effects[i].contains_key(name) => scope,
            _ => Scope::Model,
        }
    }

    pub(super) fn index(&mut self) {
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

    pub(super) fn count(&mut self, span: Span) -> Result<(), LowerError> {
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
    pub(super) fn expr(&mut self, expr: &SExpr, scope: Scope) -> Result<Expr, LowerError> {
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
    pub(super) fn resolve(
        &mut self,
        scope: Scope,
        name: &str,
        span: Span,
    ) -> Result<Expr, LowerError> {
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

    pub(super) fn constant(&self, expr: &SExpr, scope: Scope) -> f64 {
        self.checked.constant(expr, scope).unwrap_or(f64::NAN)
    }

    pub(super) fn build(&mut self) -> Result<Model, LowerError> {
        let mut model = self.empty_model();
        let mut balance_items: HashMap<String, (Scope, &ast::Equation)> = HashMap::new();
        let mut balance_patches: Vec<(Scope, &ast::Equation)> = Vec::new();
        for (scope, item) in self.items.clone() {
            match &item.kind {
                ItemKind::Der(eq) => {
                    balance_items.insert(eq.name.node.clone(), (scope, eq));
                }
                ItemKind::Next(eq) => {
                    model.dynamics = Dynamics::Discrete;
                    balance_items.insert(eq.name.node.clone(), (scope, eq));
                }
                ItemKind::DerPatch(eq) => balance_patches.push((scope, eq)),
                kind => self.declaration(&mut model, kind, scope)?,
            }
        }
        model.balances = self.balances(&model, &balance_items, &balance_patches)?;
        self.violations = self.nonnegative_violations(&model, &balance_items, &balance_patches)?;
        model.effects = self.effects();
        model.units = self.units();
        model.noise = crate::ir::noise::lower_noise(&self.checked.noise, &model);
        Ok(model)
    }

    /// The model with its name and description, and nothing declared yet.
    pub(super) fn empty_model(&self) -> Model {
        let ast = &self.checked.ast;
        Model {
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
        }
    }

    /// Adds what an item other than a balance (or its patch) declares to `model`.
    pub(super) fn declaration(
        &mut self,
        model: &mut Model,
        kind: &ItemKind,
        scope: Scope,
    ) -> Result<(), LowerError> {
        match kind {
            ItemKind::Time(unit) => model.time_unit = Some(unit.node.clone()),
            ItemKind::Input(list) => {
                (model.inputs).extend(list.iter().map(|input| self.input(input, scope)));
            }
            ItemKind::State(list) => model.states.extend(self.states(list, scope)?),
            ItemKind::Hidden(list) => model.hidden.extend(self.states(list, scope)?),
            ItemKind::Const(list) => {
                (model.consts).extend(list.iter().map(|binding| self.const_value(binding, scope)));
            }
            ItemKind::Param(list) => model
                .params
                .extend(list.iter().map(|p| self.param(p, scope))),
            ItemKind::Let(eq) if scope == Scope::Model => {
                model.lets.push(self.definition(eq, scope)?);
            }
            ItemKind::Output(eq) => model.outputs.push(self.definition(eq, scope)?),
            ItemKind::Closure(decl) => model.closures.push(self.closure(decl)?),
            _ => {}
        }
        Ok(())
    }

    /// An input with its bounds, if it has any.
    pub(super) fn input(&self, input: &ast::InputDecl, scope: Scope) -> Input {
        let bounds = input
            .bounds
            .as_ref()
            .map(|(lo, hi)| (self.constant(lo, scope), self.constant(hi, scope)));
        Input {
            name: input.name.node.clone(),
            bounds,
        }
    }

    /// A const with the value checking gave it.
    pub(super) fn const_value(&self, binding: &ast::Binding, scope: Scope) -> Const {
        let key = (scope, binding.name.node.clone());
        Const {
            name: binding.name.node.clone(),
            value: self.checked.values.get(&key).copied().unwrap_or(f64::NAN),
        }
    }

    /// A `let` or `output`: its name and its resolved expression.
    pub(super) fn definition(
        &mut self,
        eq: &ast::Equation,
        scope: Scope,
    ) -> Result<Definition, LowerError> {
        let expr = self.resolve(scope, &eq.name.node, eq.name.span)?;
        Ok(Definition {
            name: eq.name.node.clone(),
            expr,
        })
    }

    pub(super) fn states(
        &mut self,
        list: &[ast::Binding],
        scope: Scope,
    ) -> Result<Vec<State>, LowerError> {
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

    pub(super) fn param(&self, param: &ast::ParamDecl, scope: Scope) -> Param {
        let key = (scope, param.name.node.clone());
        Param {
            name: param.name.node.clone(),
            init: self.checked.values.get(&key).copied().unwrap_or(f64::NAN),
            constraint: self.constraint(param.constraint.as_ref(), scope),
        }
    }

    pub(super) fn constraint(
        &self,
        constraint: Option<&ast::Constraint>,
        scope: Scope,
    ) -> Constraint {
        match constraint {
            None => Constraint::Free,
            Some(ast::Constraint::Positive(_)) => Constraint::Positive,
            Some(ast::Constraint::Bounds(lo, hi)) => {
                Constraint::Bounds(self.constant(lo, scope), self.constant(hi, scope))
            }
        }
    }
}

/// The names of a closure's outputs, in declaration order.
fn closure_outputs(decl: &ast::ClosureDecl) -> Vec<&ast::Ident> {
    decl.items
        .iter()
        .filter_map(|line| match &line.node {
            ast::ClosureItem::Outputs(list) => Some(list),
            _ => None,
        })
        .flatten()
        .map(|o| &o.name)
        .collect()
}

/// `value` with the patch `op term` applied.
pub(super) fn combine(value: Expr, op: PatchOp, term: Expr) -> Expr {
    match op {
        PatchOp::Mul => Expr::Bin(BinOp::Mul, Box::new(value), Box::new(term)),
        PatchOp::Add => Expr::Bin(BinOp::Add, Box::new(value), Box::new(term)),
        PatchOp::Set => term,
    }
}
