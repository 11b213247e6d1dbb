//! The reference tree-walking interpreter.

use super::scalar::{apply_binary, apply_func};
use crate::ir::{Expr, Var};

/// Evaluates `expr` by walking the tree, reading each variable through `value_of`.
///
/// Slow but obviously correct: it is the reference the compiled [`Program`](super::Program)s
/// are tested against. A call with a missing argument evaluates that argument as NaN.
pub fn interpret(expr: &Expr, value_of: &impl Fn(Var) -> f64) -> f64 {
    match expr {
        Expr::Num(value) => *value,
        Expr::Var(var) => value_of(*var),
        Expr::Neg(inner) => -interpret(inner, value_of),
        Expr::Bin(op, left, right) => {
            apply_binary(*op, interpret(left, value_of), interpret(right, value_of))
        }
        Expr::Call(func, args) => {
            let argument = |k: usize| args.get(k).map_or(f64::NAN, |a| interpret(a, value_of));
            let second = if func.arity() == 2 { argument(1) } else { 0.0 };
            apply_func(*func, argument(0), second)
        }
    }
}
