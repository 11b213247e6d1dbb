//! The compiled model: plain, device-free data produced by [`lower`](crate::ir::lower) from a
//! checked AST.
//!
//! Every name is resolved to an index ([`Var`]), every `let` is inlined, consts keep their
//! evaluated values, and each closure carries its embedding layout and network shape. The
//! simulator, the trainable backend and the diagnosis all start from this form; nothing here
//! depends on how it is executed.

pub use crate::ast::BinOp;
pub use crate::units::Unit;
pub use crate::vocabulary::{sigmoid, Activation, Func};

use std::collections::BTreeMap;

mod lower;
mod mechanism;
mod noise;
pub mod nonnegative;
mod print;

pub use lower::{effect_violations, lower, lower_reporting, uses_closure, LowerError};
pub use noise::{merge_noise, parse_noise_spec, Measured, Noise, NoiseSpec};
pub use print::{expr_text, print, var_name};

/// A resolved reference to a model quantity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Var {
    /// Actuator `inputs[i]`.
    Input(usize),
    /// Measured state `states[i]`.
    State(usize),
    /// Hidden (unmeasured) state `hidden[i]`.
    Hidden(usize),
    /// Known constant `consts[i]`.
    Const(usize),
    /// Trainable constant `params[i]` (its constrained value).
    Param(usize),
    /// Output `output` of closure `closure` (its final value, prior applied).
    ClosureOutput {
        /// Index into [`Model::closures`].
        closure: usize,
        /// Index into that closure's outputs.
        output: usize,
    },
}

/// A compiled expression: names resolved, lets inlined.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A literal.
    Num(f64),
    /// A model quantity.
    Var(Var),
    /// Unary minus.
    Neg(Box<Expr>),
    /// A binary operation.
    Bin(BinOp, Box<Expr>, Box<Expr>),
    /// A function call (arity already checked).
    Call(Func, Vec<Expr>),
}

/// An actuator with optional bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct Input {
    /// Name (data column).
    pub name: String,
    /// `in [lo, hi]`.
    pub bounds: Option<(f64, f64)>,
}

/// A measured or hidden state.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Name (data column for measured states).
    pub name: String,
    /// Initial value: a constant expression of consts and params.
    pub init: Option<Expr>,
    /// Declared `nonnegative`: no learned term of its balance can drive it below zero
    /// (proved when lowering, [`nonnegative`]); free runs refine a step that crosses zero.
    pub nonnegative: bool,
}

/// A known constant.
#[derive(Debug, Clone, PartialEq)]
pub struct Const {
    /// Name.
    pub name: String,
    /// Evaluated value.
    pub value: f64,
}

/// A constraint on a trainable value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Constraint {
    /// Unconstrained.
    Free,
    /// Strictly positive (trained through softplus).
    Positive,
    /// Hard bounds `[lo, hi]` (trained through a sigmoid).
    Bounds(f64, f64),
}

/// A trainable constant.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Name.
    pub name: String,
    /// Initial guess (evaluated).
    pub init: f64,
    /// Its constraint.
    pub constraint: Constraint,
}

/// A named algebraic quantity (`let` or `output`) with its definition inlined.
#[derive(Debug, Clone, PartialEq)]
pub struct Definition {
    /// Name.
    pub name: String,
    /// Inlined expression.
    pub expr: Expr,
}

/// How a prior combines with the network (spec section 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PriorKind {
    /// `o = p * (1 + n)`.
    Mul,
    /// `o = p + s * n`.
    Add,
}

/// A prior on a closure output.
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    /// Multiplicative or additive.
    pub kind: PriorKind,
    /// The prior expression (states, inputs, consts, params).
    pub expr: Expr,
}

/// One value a closure provides.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosureOutput {
    /// Name.
    pub name: String,
    /// `~` magnitude as written; `None` means the data-driven default is chosen at training.
    pub scale: Option<f64>,
    /// Prior, if any.
    pub prior: Option<Prior>,
    /// Constraint on the value, if declared.
    pub constraint: Constraint,
}

/// The time-delay embedding of a closure.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    /// The observed variables `z` (inputs and measured states).
    pub observe: Vec<Var>,
    /// Delay between lags (model time units).
    pub delay: f64,
    /// Number of lags (>= 1).
    pub dim: usize,
}

impl Embedding {
    /// The network input layout: entry `k` is `(variable, lag)`, lag-major as in the paper
    /// (`z(t)` first, then `z(t - delay)`, ...).
    pub fn layout(&self) -> Vec<(Var, usize)> {
        (0..self.dim)
            .flat_map(|lag| self.observe.iter().map(move |&v| (v, lag)))
            .collect()
    }
    /// Number of network inputs.
    pub fn width(&self) -> usize {
        self.observe.len() * self.dim
    }
    /// How much history the embedding needs before its first use.
    pub fn span(&self) -> f64 {
        (self.dim.saturating_sub(1)) as f64 * self.delay
    }
}

/// The network of a closure: a multilayer perceptron with a linear output layer.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Hidden-layer activation.
    pub activation: Activation,
}

/// An unknown constitutive law learned by one network.
#[derive(Debug, Clone, PartialEq)]
pub struct Closure {
    /// Name.
    pub name: String,
    /// The values it provides (network output `k` is `outputs[k]`).
    pub outputs: Vec<ClosureOutput>,
    /// Its delay embedding.
    pub embedding: Embedding,
    /// Its network shape.
    pub network: Network,
}

/// Whether balances are derivatives (`der`) or discrete updates (`next`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dynamics {
    /// `der X = f`: dX/dt = f, integrated (RK4 in training, adaptive in simulation).
    Continuous,
    /// `next X = f`: X(t + h) = f.
    Discrete,
}

/// The right-hand side of one state's balance.
#[derive(Debug, Clone, PartialEq)]
pub struct Balance {
    /// The state it governs (`Var::State` or `Var::Hidden`).
    pub state: Var,
    /// Inlined right-hand side.
    pub expr: Expr,
}

/// A candidate unmodelled effect, as listed in the compiled model (not applied: applying it
/// means lowering again with its name, see [`lower`](crate::ir::lower)).
#[derive(Debug, Clone, PartialEq)]
pub struct Effect {
    /// Name.
    pub name: String,
    /// Description.
    pub description: Option<String>,
    /// Params it adds.
    pub params: Vec<Param>,
    /// Its other declarations and patches, one canonical source line each
    /// (e.g. `mu *= 1 / (1 + S / K_I)`, `hidden L = 0`, `der L = (u - L) / tau`).
    pub lines: Vec<String>,
}

/// The unit of measure of one named quantity.
#[derive(Debug, Clone, PartialEq)]
pub struct QuantityUnit {
    /// The unit, for comparison and arithmetic.
    pub unit: Unit,
    /// How to show it (as written where declared, e.g. `g/g`; canonical where inferred):
    /// the text for an axis label or a column header.
    pub text: String,
    /// Whether gbc inferred it from the equations (not written in the model).
    pub inferred: bool,
}

/// Units of measure of the model's quantities, as plain data. Empty for a model that
/// declares no unit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Units {
    /// The time unit (`time h`), when the model uses units.
    pub time: Option<Unit>,
    /// Declared and inferred units by name: inputs, states, hidden states, consts, params,
    /// `let`s, `output`s and closure outputs (and the names of applied effects).
    pub names: BTreeMap<String, QuantityUnit>,
    /// Units of the names declared inside each effect that is not applied, by effect name.
    pub effects: BTreeMap<String, BTreeMap<String, QuantityUnit>>,
}

/// A compiled model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// Model name.
    pub name: String,
    /// Header description.
    pub description: Option<String>,
    /// Time unit label.
    pub time_unit: Option<String>,
    /// Actuators.
    pub inputs: Vec<Input>,
    /// Measured states.
    pub states: Vec<State>,
    /// Hidden states.
    pub hidden: Vec<State>,
    /// Known constants.
    pub consts: Vec<Const>,
    /// Trainable constants.
    pub params: Vec<Param>,
    /// `let`s, inlined (kept for reporting and prediction).
    pub lets: Vec<Definition>,
    /// `output`s, inlined.
    pub outputs: Vec<Definition>,
    /// Closures.
    pub closures: Vec<Closure>,
    /// Continuous or discrete.
    pub dynamics: Dynamics,
    /// One balance per state, measured states first then hidden, in declaration order.
    pub balances: Vec<Balance>,
    /// Effects declared in the model (applied ones are already folded into the above).
    pub effects: Vec<Effect>,
    /// Units of measure of the named quantities (empty when the model declares none).
    pub units: Units,
    /// The declared measurement noise, at most one per measured state or output, sorted by
    /// quantity (states first); `--noise` specs are laid over it with [`merge_noise`].
    pub noise: Vec<Noise>,
}

impl Model {
    /// The unit of a named quantity (input, state, const, param, `let`, `output`, closure
    /// output), if the model declares or implies one.
    pub fn unit(&self, name: &str) -> Option<&QuantityUnit> {
        self.units.names.get(name)
    }

    /// The unit of a variable, if known.
    pub fn unit_of(&self, var: Var) -> Option<&QuantityUnit> {
        self.unit(print::var_name(self, var))
    }
}

impl Model {
    /// An axis title for the quantity `name`: `X [g/L]` where the model gives it a unit,
    /// else the name alone.
    pub fn axis_label(&self, name: &str) -> String {
        match self.units.names.get(name) {
            Some(unit) if !unit.text.is_empty() => format!("{name} [{}]", unit.text),
            _ => name.to_string(),
        }
    }

    /// The time axis title: `time [h]` where the model names a time unit.
    pub fn time_label(&self) -> String {
        match &self.time_unit {
            Some(unit) if !unit.is_empty() => format!("time [{unit}]"),
            _ => "time".to_string(),
        }
    }
}
