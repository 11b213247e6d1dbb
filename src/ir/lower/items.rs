//! Lowering of the items that build the model around its expressions: closures (their
//! outputs, observed variables and networks), the balances with their patches, the units
//! and the effects' source lines.

use super::error::LowerError;
use super::lowerer::{combine, Lowerer};
use crate::ast::{self, ItemKind, PatchOp};
use crate::check::Scope;
use crate::ir::model::{
    uses_closure, Balance, Closure, ClosureOutput, Effect, Embedding, Expr, Model, Network, Prior,
    PriorKind, QuantityUnit, Units, Var,
};
use crate::vocabulary::Activation;
use std::collections::HashMap;

impl<'a> Lowerer<'a> {
    pub(super) fn closure(&mut self, decl: &ast::ClosureDecl) -> Result<Closure, LowerError> {
        let mut outputs = Vec::new();
        let mut observe_names: Option<Vec<String>> = None;
        let (mut delay, mut dim) = (None, 1usize);
        let mut network = Network {
            hidden: vec![20, 20, 20],
            activation: Activation::Softplus,
        };
        for line in &decl.items {
            match &line.node {
                ast::ClosureItem::Outputs(list) => {
                    for output in list {
                        outputs.push(ClosureOutput {
                            name: output.name.node.clone(),
                            scale: output
                                .scale
                                .as_ref()
                                .map(|s| self.constant(s, Scope::Model)),
                            prior: None,
                            constraint: self.constraint(output.constraint.as_ref(), Scope::Model),
                        });
                    }
                }
                ast::ClosureItem::Observe(names) => {
                    observe_names = Some(names.iter().map(|n| n.node.clone()).collect())
                }
                ast::ClosureItem::Embed { delay: d, dim: n } => {
                    delay = d.as_ref().map(|d| self.constant(d, Scope::Model));
                    dim = n.as_ref().map_or(1, |n| n.node as usize);
                }
                ast::ClosureItem::Network { hidden, activation } => {
                    if let Some(widths) = hidden {
                        network.hidden = widths.iter().map(|w| w.node as usize).collect();
                    }
                    if let Some(name) = activation {
                        network.activation =
                            Activation::from_name(&name.node).unwrap_or(Activation::Softplus);
                    }
                }
                ast::ClosureItem::Prior(_) => {}
            }
        }
        for line in &decl.items {
            if let ast::ClosureItem::Prior(prior) = &line.node {
                let expr = self.expr(&prior.expr, Scope::Model)?;
                if uses_closure(&expr) {
                    return Err(LowerError::PriorUsesClosure {
                        target: prior.target.node.clone(),
                        span: prior.expr.span.into(),
                    });
                }
                let kind = match prior.op {
                    PatchOp::Add => PriorKind::Add,
                    _ => PriorKind::Mul,
                };
                if let Some(output) = outputs.iter_mut().find(|o| o.name == prior.target.node) {
                    output.prior = Some(Prior { kind, expr });
                }
            }
        }
        let observe = match observe_names {
            Some(names) => names
                .iter()
                .filter_map(|n| self.vars.get(&(Scope::Model, n.clone())).copied())
                .collect(),
            None => self.default_observe(),
        };
        Ok(Closure {
            name: decl.name.node.clone(),
            outputs,
            embedding: Embedding {
                observe,
                delay: delay.unwrap_or(1.0),
                dim: dim.max(1),
            },
            network,
        })
    }

    /// All inputs, then all measured states (the paper's `z = [u, x_c]`).
    pub(super) fn default_observe(&self) -> Vec<Var> {
        let mut vars: Vec<Var> = self
            .vars
            .iter()
            .filter(|((scope, _), _)| *scope == Scope::Model)
            .map(|(_, var)| *var)
            .filter(|var| matches!(var, Var::Input(_) | Var::State(_)))
            .collect();
        vars.sort();
        vars
    }

    pub(super) fn balances(
        &mut self,
        model: &Model,
        items: &HashMap<String, (Scope, &ast::Equation)>,
        patches: &[(Scope, &ast::Equation)],
    ) -> Result<Vec<Balance>, LowerError> {
        let states = model
            .states
            .iter()
            .enumerate()
            .map(|(i, s)| (Var::State(i), s));
        let hidden = model
            .hidden
            .iter()
            .enumerate()
            .map(|(i, s)| (Var::Hidden(i), s));
        let mut balances = Vec::new();
        for (var, state) in states.chain(hidden) {
            let mut expr = match items.get(&state.name) {
                Some((scope, eq)) => self.expr(&eq.expr, *scope)?,
                None => Expr::Num(0.0),
            };
            for (scope, eq) in patches.iter().filter(|(_, eq)| eq.name.node == state.name) {
                expr = combine(expr, PatchOp::Add, self.expr(&eq.expr, *scope)?);
            }
            balances.push(Balance { state: var, expr });
        }
        Ok(balances)
    }

    /// The units of the model's names and of its applied effects' names; those of the
    /// other effects by effect.
    pub(super) fn units(&self) -> Units {
        let table = &self.checked.units;
        let mut units = Units {
            time: table.time.clone(),
            ..Units::default()
        };
        let applied: Vec<Scope> = self.items.iter().map(|(scope, _)| *scope).collect();
        for ((scope, name), entry) in &table.names {
            let unit = QuantityUnit {
                unit: entry.unit.clone(),
                text: entry.text.clone(),
                inferred: entry.inferred,
            };
            match scope {
                Scope::Effect(index) if !applied.contains(scope) => {
                    if let Some(effect) = self.effects.get(*index) {
                        let effect = effect.name.node.clone();
                        units
                            .effects
                            .entry(effect)
                            .or_default()
                            .insert(name.clone(), unit);
                    }
                }
                _ => {
                    units.names.insert(name.clone(), unit);
                }
            }
        }
        units
    }

    /// Every effect of the model, in printable form (not applied).
    pub(super) fn effects(&self) -> Vec<Effect> {
        self.effects
            .iter()
            .enumerate()
            .map(|(index, decl)| {
                let scope = Scope::Effect(index);
                let mut params = Vec::new();
                let mut lines = Vec::new();
                for item in &decl.items {
                    match &item.kind {
                        ItemKind::Param(list) => {
                            params.extend(list.iter().map(|p| self.param(p, scope)))
                        }
                        other => lines.extend(effect_lines(other)),
                    }
                }
                Effect {
                    name: decl.name.node.clone(),
                    description: decl.description.clone(),
                    params,
                    lines,
                }
            })
            .collect()
    }
}

/// Canonical source lines of one effect declaration.
fn effect_lines(kind: &ItemKind) -> Vec<String> {
    let unit = |annotation: &Option<ast::SUnit>| match annotation {
        Some(unit) => format!(" [{}]", unit.node),
        None => String::new(),
    };
    let bindings = |keyword: &str, list: &[ast::Binding]| -> Vec<String> {
        list.iter()
            .map(|b| {
                let value = match &b.value {
                    Some(value) => format!(" = {}", value.node),
                    None => String::new(),
                };
                let sign = if b.nonnegative.is_some() {
                    " nonnegative"
                } else {
                    ""
                };
                format!("{keyword} {}{}{value}{sign}", b.name.node, unit(&b.unit))
            })
            .collect()
    };
    match kind {
        ItemKind::Hidden(list) => bindings("hidden", list),
        ItemKind::Const(list) => bindings("const", list),
        ItemKind::Let(eq) => vec![format!(
            "let {}{} = {}",
            eq.name.node,
            unit(&eq.unit),
            eq.expr.node
        )],
        ItemKind::Der(eq) => vec![format!("der {} = {}", eq.name.node, eq.expr.node)],
        ItemKind::DerPatch(eq) => vec![format!("der {} += {}", eq.name.node, eq.expr.node)],
        ItemKind::Patch(patch) => vec![format!(
            "{} {} {}",
            patch.target.node,
            patch.op.symbol(),
            patch.expr.node
        )],
        _ => Vec::new(),
    }
}
