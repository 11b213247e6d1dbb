//! The places where a unit is required: every expression of the model with the unit it
//! must have.

use crate::ast::{self, ClosureItem, Constraint, ItemKind, PatchOp, SExpr};
use crate::check::symbols::{effect_items, owner, Key, Scope, Symbols};

/// What unit an expression must have.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// The unit of a name (definitions, initial values, bounds, priors, magnitudes, patches,
    /// `next`).
    Name(Key),
    /// The unit of a state per time unit (`der X = ...`, `der X += ...`).
    Rate(Key),
    /// No unit (`NAME *= factor`).
    Dimensionless,
    /// The time unit (`embed delay`).
    Time,
}

/// One expression with the unit it must have.
#[derive(Debug)]
pub struct Site<'a> {
    /// The expression.
    pub expr: &'a SExpr,
    /// Where its names resolve.
    pub scope: Scope,
    /// The unit it must have.
    pub target: Target,
    /// What it is, in words, for messages (`balance of `X``).
    pub context: String,
}

/// Every site of the model, in source order (effects after the model).
pub fn sites<'a>(model: &'a ast::Model, symbols: &Symbols) -> Vec<Site<'a>> {
    let mut out = Vec::new();
    for item in &model.items {
        if !matches!(item.kind, ItemKind::Effect(_)) {
            item_sites(item, Scope::Model, symbols, &mut out);
        }
    }
    for (index, effect) in effect_items(model).enumerate() {
        for item in &effect.items {
            item_sites(item, Scope::Effect(index), symbols, &mut out);
        }
    }
    out
}

struct Collector<'a, 'b> {
    scope: Scope,
    symbols: &'b Symbols,
    out: &'b mut Vec<Site<'a>>,
}

impl<'a> Collector<'a, '_> {
    fn key(&self, name: &str) -> Key {
        (owner(self.symbols, self.scope, name), name.to_string())
    }

    fn push(&mut self, expr: &'a SExpr, target: Target, context: String) {
        self.out.push(Site {
            expr,
            scope: self.scope,
            target,
            context,
        });
    }

    fn named(&mut self, expr: &'a SExpr, name: &ast::Ident, what: &str) {
        let context = format!("{what} `{}`", name.node);
        self.push(expr, Target::Name(self.key(&name.node)), context);
    }

    fn bounds(&mut self, constraint: Option<&'a Constraint>, name: &ast::Ident) {
        if let Some(Constraint::Bounds(lo, hi)) = constraint {
            self.named(lo, name, "lower bound of");
            self.named(hi, name, "upper bound of");
        }
    }
}

fn item_sites<'a>(item: &'a ast::Item, scope: Scope, symbols: &Symbols, out: &mut Vec<Site<'a>>) {
    let mut c = Collector {
        scope,
        symbols,
        out,
    };
    match &item.kind {
        ItemKind::Input(inputs) => {
            for input in inputs {
                if let Some((lo, hi)) = &input.bounds {
                    c.named(lo, &input.name, "lower bound of");
                    c.named(hi, &input.name, "upper bound of");
                }
            }
        }
        ItemKind::State(list) | ItemKind::Hidden(list) => {
            for binding in list {
                if let Some(value) = &binding.value {
                    c.named(value, &binding.name, "initial value of");
                }
            }
        }
        ItemKind::Const(list) => {
            for binding in list {
                if let Some(value) = &binding.value {
                    c.named(value, &binding.name, "value of");
                }
            }
        }
        ItemKind::Param(list) => {
            for param in list {
                c.named(&param.init, &param.name, "initial guess of");
                c.bounds(param.constraint.as_ref(), &param.name);
            }
        }
        ItemKind::Let(eq) | ItemKind::Output(eq) => c.named(&eq.expr, &eq.name, "definition of"),
        ItemKind::Next(eq) => c.named(&eq.expr, &eq.name, "update of"),
        ItemKind::Der(eq) => {
            let context = format!("balance of `{}`", eq.name.node);
            c.push(&eq.expr, Target::Rate(c.key(&eq.name.node)), context);
        }
        ItemKind::DerPatch(eq) => {
            let context = format!("term added to the balance of `{}`", eq.name.node);
            c.push(&eq.expr, Target::Rate(c.key(&eq.name.node)), context);
        }
        ItemKind::Patch(patch) => {
            let name = &patch.target;
            match patch.op {
                PatchOp::Mul => {
                    let context = format!("factor of `{} *=`", name.node);
                    c.push(&patch.expr, Target::Dimensionless, context);
                }
                PatchOp::Add => c.named(&patch.expr, name, "term added to"),
                PatchOp::Set => c.named(&patch.expr, name, "replacement of"),
            }
        }
        ItemKind::Closure(closure) => closure_sites(closure, &mut c),
        ItemKind::Time(_) | ItemKind::Effect(_) | ItemKind::Noise(_) => {}
    }
}

fn closure_sites<'a>(closure: &'a ast::ClosureDecl, c: &mut Collector<'a, '_>) {
    for line in &closure.items {
        match &line.node {
            ClosureItem::Outputs(outputs) => {
                for output in outputs {
                    if let Some(scale) = &output.scale {
                        c.named(scale, &output.name, "magnitude of");
                    }
                    c.bounds(output.constraint.as_ref(), &output.name);
                }
            }
            ClosureItem::Embed {
                delay: Some(delay), ..
            } => c.push(delay, Target::Time, "embedding delay".to_string()),
            ClosureItem::Prior(prior) => c.named(&prior.expr, &prior.target, "prior for"),
            _ => {}
        }
    }
}
