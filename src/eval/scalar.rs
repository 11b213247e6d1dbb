//! Scalar semantics of the built-in functions and operators, shared by the compiled
//! programs and the reference interpreter. The definitions live with the IR
//! ([`BinOp::apply`], [`Func::apply`], [`crate::vocabulary::softplus`], [`crate::ir::sigmoid`]) so that
//! constant evaluation in the checks uses the very same arithmetic.

use crate::ir::{BinOp, Func};

pub use crate::ir::sigmoid;

/// Applies a binary operator.
pub fn apply_binary(op: BinOp, a: f64, b: f64) -> f64 {
    op.apply(a, b)
}

/// Applies a built-in function to its arguments; `b` is ignored by one-argument functions.
pub fn apply_func(func: Func, a: f64, b: f64) -> f64 {
    func.apply(a, b)
}
