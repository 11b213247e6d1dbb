//! Scalar semantics of the built-in functions and operators, shared by the compiled
//! programs and the reference interpreter.

use crate::ir::{BinOp, Func};

/// `softplus(x) = ln(1 + e^x)`, evaluated as `max(x, 0) + ln_1p(e^-|x|)`: no overflow for
/// large positive `x`, full relative accuracy for large negative `x`.
pub fn softplus(x: f64) -> f64 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// `sigmoid(x) = 1 / (1 + e^-x)`, evaluated through `e^-|x|` so neither tail overflows and
/// the negative tail keeps full relative accuracy.
pub fn sigmoid(x: f64) -> f64 {
    let decay = (-x.abs()).exp();
    if x >= 0.0 {
        1.0 / (1.0 + decay)
    } else {
        decay / (1.0 + decay)
    }
}

/// Applies a binary operator.
pub fn apply_binary(op: BinOp, a: f64, b: f64) -> f64 {
    match op {
        BinOp::Add => a + b,
        BinOp::Sub => a - b,
        BinOp::Mul => a * b,
        BinOp::Div => a / b,
        BinOp::Pow => a.powf(b),
    }
}

/// Applies a built-in function to its arguments; `b` is ignored by one-argument functions.
pub fn apply_func(func: Func, a: f64, b: f64) -> f64 {
    match func {
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
