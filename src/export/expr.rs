//! The physics of a compiled model as ONNX nodes: one general translation of
//! [`ir::Expr`] (balances, priors, `output`s), closure outputs from network outputs (prior,
//! magnitude and constraint, spec section 3) and params through their transforms, the same
//! arithmetic as the trainable network's physics program (`backend::program`).
//!
//! Every value is a `[batch, 1]` column or a constant folded at export time in `f64`, as
//! the physics program folds literal sub-expressions; identical sub-expressions of one
//! stage share their nodes.

use std::collections::HashMap;

use super::graph::{Builder, Value};
use crate::ir::{self, BinOp, Constraint, Func, PriorKind, Var};

/// What the physics reads besides the stage state: the held inputs and the raw params.
pub struct Physics<'m> {
    model: &'m ir::Model,
    scales: &'m [Vec<f64>],
    /// `[batch, inputs]`, when the model has inputs.
    inputs: Option<String>,
    /// `[params]` raw (unconstrained) values, when the model has params.
    raw_params: Option<String>,
    held: HashMap<Var, Value>,
}

/// The tensors of one stage: the stage state and every closure's network output.
pub struct Stage {
    /// `[batch, measured + hidden]`.
    pub state: String,
    /// Per closure, `[batch, outputs]` before prior and magnitude.
    pub nets: Vec<String>,
    memo: HashMap<String, Value>,
}

impl Stage {
    /// A stage at `state` with network outputs `nets`.
    pub fn new(state: String, nets: Vec<String>) -> Self {
        Stage {
            state,
            nets,
            memo: HashMap::new(),
        }
    }
}

impl<'m> Physics<'m> {
    /// The physics of `model` with closure magnitudes `scales`, reading `inputs`
    /// (`[batch, inputs]`) and `raw_params` (`[params]`).
    pub fn new(
        model: &'m ir::Model,
        scales: &'m [Vec<f64>],
        inputs: Option<String>,
        raw_params: Option<String>,
    ) -> Self {
        Physics {
            model,
            scales,
            inputs,
            raw_params,
            held: HashMap::new(),
        }
    }

    /// The value of `expr` at `stage`.
    pub fn expr(&mut self, graph: &mut Builder, stage: &mut Stage, expr: &ir::Expr) -> Value {
        let key = format!("{expr:?}");
        if let Some(value) = stage.memo.get(&key) {
            return value.clone();
        }
        let value = match expr {
            ir::Expr::Num(number) => Value::Const(*number),
            ir::Expr::Var(var) => self.var(graph, stage, *var),
            ir::Expr::Neg(inner) => match self.expr(graph, stage, inner) {
                Value::Const(number) => Value::Const(-number),
                other => graph.map(&other, |g, x| g.unary("Neg", x)),
            },
            ir::Expr::Bin(op, left, right) => {
                let a = self.expr(graph, stage, left);
                let b = self.expr(graph, stage, right);
                let op = match op {
                    BinOp::Add => "Add",
                    BinOp::Sub => "Sub",
                    BinOp::Mul => "Mul",
                    BinOp::Div => "Div",
                    BinOp::Pow => "Pow",
                };
                graph.binary(op, &a, &b)
            }
            ir::Expr::Call(func, args) => {
                let values: Vec<Value> = args.iter().map(|a| self.expr(graph, stage, a)).collect();
                call(graph, *func, &values)
            }
        };
        stage.memo.insert(key, value.clone());
        value
    }

    /// The value of closure output `output` of closure `closure` at `stage`.
    pub fn closure_output(
        &mut self,
        graph: &mut Builder,
        stage: &mut Stage,
        (closure, output): (usize, usize),
    ) -> Value {
        let key = format!("closure {closure}.{output}");
        if let Some(value) = stage.memo.get(&key) {
            return value.clone();
        }
        let spec = &self.model.closures[closure].outputs[output];
        let scale = self.scales[closure][output];
        let net = Value::Column(graph.column(&stage.nets[closure], output));
        let value = match &spec.prior {
            _ if matches!(spec.constraint, Constraint::Bounds(..)) => {
                let prior = (spec.prior.as_ref())
                    .map(|prior| (self.expr(graph, stage, &prior.expr), prior.kind));
                bounded(graph, prior, &net, spec.constraint, scale)
            }
            None => {
                let plain = graph.binary("Mul", &Value::Const(scale), &net);
                match spec.constraint {
                    // `max(s n, -s n)`: 0 at the start (`backend::program::outputs`).
                    Constraint::Positive => {
                        let mirrored = graph.binary("Sub", &Value::Const(0.0), &plain);
                        graph.binary("Max", &plain, &mirrored)
                    }
                    _ => constrain(graph, &plain, spec.constraint, scale),
                }
            }
            Some(prior) => {
                let p = self.expr(graph, stage, &prior.expr);
                with_prior(graph, (&p, prior.kind), &net, spec.constraint, scale)
            }
        };
        stage.memo.insert(key, value.clone());
        value
    }

    fn var(&mut self, graph: &mut Builder, stage: &mut Stage, var: Var) -> Value {
        match var {
            Var::State(i) => Value::Column(graph.column(&stage.state, i)),
            Var::Hidden(j) => {
                Value::Column(graph.column(&stage.state, self.model.states.len() + j))
            }
            Var::Const(i) => Value::Const(self.model.consts[i].value),
            Var::ClosureOutput { closure, output } => {
                self.closure_output(graph, stage, (closure, output))
            }
            Var::Input(_) | Var::Param(_) => {
                if let Some(value) = self.held.get(&var) {
                    return value.clone();
                }
                let value = match var {
                    Var::Input(i) => {
                        let inputs = self.inputs.clone().unwrap_or_default();
                        Value::Column(graph.column(&inputs, i))
                    }
                    _ => self.param(graph, var),
                };
                self.held.insert(var, value.clone());
                value
            }
        }
    }

    /// A param's constrained value: its raw value through the transform of its
    /// constraint (`positive`: softplus; `in [lo, hi]`: `lo + (hi - lo) sigmoid`).
    fn param(&mut self, graph: &mut Builder, var: Var) -> Value {
        let Var::Param(index) = var else {
            return Value::Const(f64::NAN);
        };
        let raw_params = self.raw_params.clone().unwrap_or_default();
        let indices = graph.ints("param_index", &[], &[index as i64]);
        let raw = Value::Scalar(graph.node("Gather", &[&raw_params, &indices], &[("axis", 0)]));
        constrain(graph, &raw, self.model.params[index].constraint, 1.0)
    }
}

/// A closure output with a prior `p` from its network output `net`, as the physics program
/// computes it (`backend::program::outputs`): a `positive` output is `max(p, 0) g(n)` with
/// `g(n) = max(n + 7/8, 0) + exp(8 min(0, n + 7/8)) / 8` under `*=` and `max(p + s n, 0)`
/// under `+=`.
fn with_prior(
    graph: &mut Builder,
    (p, kind): (&Value, PriorKind),
    net: &Value,
    constraint: Constraint,
    scale: f64,
) -> Value {
    let zero = Value::Const(0.0);
    let positive = matches!(constraint, Constraint::Positive);
    match (kind, positive) {
        (PriorKind::Mul, true) => {
            use crate::engine::program::outputs::{JOIN, TAIL};
            let clipped = graph.binary("Max", p, &zero);
            let shifted = graph.binary("Add", net, &Value::Const(JOIN));
            let upper = graph.binary("Max", &shifted, &zero);
            let lower = graph.binary("Min", &zero, &shifted);
            let scaled = graph.binary("Mul", &Value::Const(1.0 / TAIL), &lower);
            let decay = unary(graph, Func::Exp, &scaled);
            let tail = graph.binary("Mul", &Value::Const(TAIL), &decay);
            let factor = graph.binary("Add", &upper, &tail);
            graph.binary("Mul", &clipped, &factor)
        }
        (PriorKind::Mul, false) => {
            let factor = graph.binary("Add", &Value::Const(1.0), net);
            let combined = graph.binary("Mul", p, &factor);
            constrain(graph, &combined, constraint, scale)
        }
        (PriorKind::Add, positive) => {
            let correction = graph.binary("Mul", &Value::Const(scale), net);
            let combined = graph.binary("Add", p, &correction);
            if positive {
                graph.binary("Max", &combined, &zero)
            } else {
                constrain(graph, &combined, constraint, scale)
            }
        }
    }
}

/// An output `in [lo, hi]` as the physics program computes it
/// (`backend::program::outputs`): `lo + (hi - lo) sigmoid(ln((q - lo) / (hi - q)) + 4 c /
/// (hi - lo))`, `q` the prior (or 0) clamped short of the ends, `c` the correction (`s n`,
/// or `p n` under `*=`).
fn bounded(
    graph: &mut Builder,
    prior: Option<(Value, PriorKind)>,
    net: &Value,
    constraint: Constraint,
    scale: f64,
) -> Value {
    let Constraint::Bounds(lo, hi) = constraint else {
        return Value::Const(f64::NAN);
    };
    let (start, factor) = match prior {
        Some((p, PriorKind::Mul)) => (p.clone(), p),
        Some((p, PriorKind::Add)) => (p, Value::Const(scale)),
        None => (Value::Const(0.0), Value::Const(scale)),
    };
    let correction = graph.binary("Mul", &factor, net);
    let margin = (hi - lo) * crate::engine::program::outputs::BOUNDED_MARGIN;
    let below_top = graph.binary("Min", &start, &Value::Const(hi - margin));
    let q = graph.binary("Max", &below_top, &Value::Const(lo + margin));
    let above = graph.binary("Sub", &q, &Value::Const(lo));
    let under = graph.binary("Sub", &Value::Const(hi), &q);
    let odds = graph.binary("Div", &above, &under);
    let centre = unary(graph, Func::Log, &odds);
    let moved = graph.binary("Mul", &Value::Const(4.0 / (hi - lo)), &correction);
    let argument = graph.binary("Add", &centre, &moved);
    constrain(graph, &argument, constraint, 1.0)
}

/// `scale * softplus(raw / scale)` for `positive`, `lo + (hi - lo) sigmoid(raw)` for
/// bounds (multiplications by 1 left out: they are exact).
fn constrain(graph: &mut Builder, raw: &Value, constraint: Constraint, scale: f64) -> Value {
    match constraint {
        Constraint::Free => raw.clone(),
        Constraint::Positive => {
            let scaled = if scale == 1.0 {
                raw.clone()
            } else {
                graph.binary("Mul", raw, &Value::Const(1.0 / scale))
            };
            let soft = unary(graph, Func::Softplus, &scaled);
            if scale == 1.0 {
                soft
            } else {
                graph.binary("Mul", &Value::Const(scale), &soft)
            }
        }
        Constraint::Bounds(lo, hi) => {
            let squashed = unary(graph, Func::Sigmoid, raw);
            let spread = graph.binary("Mul", &Value::Const(hi - lo), &squashed);
            graph.binary("Add", &Value::Const(lo), &spread)
        }
    }
}

/// A built-in function on its arguments.
fn call(graph: &mut Builder, func: Func, args: &[Value]) -> Value {
    match func {
        Func::Min => graph.binary("Min", &args[0], &args[1]),
        Func::Max => graph.binary("Max", &args[0], &args[1]),
        Func::Pow => graph.binary("Pow", &args[0], &args[1]),
        _ => unary(graph, func, &args[0]),
    }
}

/// A one-argument function, folded on a constant.
fn unary(graph: &mut Builder, func: Func, arg: &Value) -> Value {
    if let Value::Const(number) = arg {
        return Value::Const(func.apply(*number, 0.0));
    }
    graph.map(arg, |graph, x| match func {
        Func::Exp => graph.unary("Exp", x),
        Func::Log => graph.unary("Log", x),
        Func::Sqrt => graph.unary("Sqrt", x),
        Func::Abs => graph.unary("Abs", x),
        Func::Tanh => graph.unary("Tanh", x),
        Func::Sigmoid => graph.sigmoid(x),
        _ => graph.softplus(x),
    })
}
