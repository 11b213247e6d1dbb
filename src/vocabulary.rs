//! The vocabulary every stage shares: the language's built-in functions and network
//! activations. It sits below both the checks (`crate::check`, which resolves names to them)
//! and the IR (`crate::ir`, which carries them), so neither imports the other for it.

use crate::numeric::Real;

/// The name of the one tensor that holds a model's params, in declaration order: in the
/// network's weights, `weights.safetensors`, checkpoints, the fused step and ONNX files.
pub const PARAMS_TENSOR: &str = "params";

/// A built-in function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Func {
    /// `exp(x)`
    Exp,
    /// `log(x)`: natural logarithm.
    Log,
    /// `sqrt(x)`
    Sqrt,
    /// `abs(x)`
    Abs,
    /// `tanh(x)`
    Tanh,
    /// `sigmoid(x) = 1 / (1 + exp(-x))`
    Sigmoid,
    /// `softplus(x) = log(1 + exp(x))`, evaluated safely for large |x|.
    Softplus,
    /// `min(a, b)`
    Min,
    /// `max(a, b)`
    Max,
    /// `pow(a, b) = a ^ b`
    Pow,
}

impl Func {
    /// Every function, for look-ups and suggestions.
    pub const ALL: [Func; 10] = [
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Abs,
        Func::Tanh,
        Func::Sigmoid,
        Func::Softplus,
        Func::Min,
        Func::Max,
        Func::Pow,
    ];
    /// The name used in source.
    pub fn name(self) -> &'static str {
        match self {
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Tanh => "tanh",
            Func::Sigmoid => "sigmoid",
            Func::Softplus => "softplus",
            Func::Min => "min",
            Func::Max => "max",
            Func::Pow => "pow",
        }
    }
    /// Number of arguments it takes.
    pub fn arity(self) -> usize {
        match self {
            Func::Min | Func::Max | Func::Pow => 2,
            _ => 1,
        }
    }
    /// Looks a function up by its source name.
    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }
    /// Applies the function to its arguments (`b` is ignored by one-argument functions).
    /// The single scalar definition every evaluator shares; `softplus` and `sigmoid` are
    /// written to stay finite and accurate for large |x|.
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            Func::Exp => a.exp(),
            Func::Log => a.ln(),
            Func::Sqrt => a.sqrt(),
            Func::Abs => a.abs(),
            Func::Tanh => a.tanh(),
            Func::Sigmoid => sigmoid(a),
            Func::Softplus => softplus(a),
            Func::Min => a.min(b),
            Func::Max => a.max(b),
            Func::Pow => a.powf(b),
        }
    }
}

/// Activation of the hidden layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Activation {
    /// `log(1 + exp(x))` (default).
    Softplus,
    /// `tanh(x)`
    Tanh,
    /// `max(0, x)`
    Relu,
    /// `1 / (1 + exp(-x))`
    Sigmoid,
    /// `x * Phi(x)` (tanh approximation).
    Gelu,
    /// Identity.
    Linear,
}

impl Activation {
    /// Every activation, for look-ups and suggestions.
    pub const ALL: [Activation; 6] = [
        Activation::Softplus,
        Activation::Tanh,
        Activation::Relu,
        Activation::Sigmoid,
        Activation::Gelu,
        Activation::Linear,
    ];
    /// The name used in source.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Softplus => "softplus",
            Activation::Tanh => "tanh",
            Activation::Relu => "relu",
            Activation::Sigmoid => "sigmoid",
            Activation::Gelu => "gelu",
            Activation::Linear => "linear",
        }
    }
    /// Looks an activation up by its source name.
    pub fn from_name(name: &str) -> Option<Activation> {
        Activation::ALL.into_iter().find(|a| a.name() == name)
    }
}

/// `log(1 + exp(x))` without overflow for large `x` or loss of precision for very negative `x`
/// ([`Real::softplus`], the one definition).
pub fn softplus(x: f64) -> f64 {
    Real::softplus(x)
}

/// `1 / (1 + exp(-x))`, evaluated through `exp(-|x|)` so neither tail overflows and the
/// negative tail keeps full relative accuracy ([`Real::sigmoid`]).
pub fn sigmoid(x: f64) -> f64 {
    Real::sigmoid(x)
}
