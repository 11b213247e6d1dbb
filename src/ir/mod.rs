//! The compiled model: plain, device-free data produced by [`lower`](crate::ir::lower) from a
//! checked AST.
//!
//! Every name is resolved to an index ([`Var`]), every `let` is inlined, consts keep their
//! evaluated values, and each closure carries its embedding layout and network shape. The
//! simulator, the trainable backend and the diagnosis all start from this form; nothing here
//! depends on how it is executed.

pub use crate::ast::BinOp;
pub use crate::vocabulary::{sigmoid, Activation, Func};

mod lower;
mod mechanism;
mod model;
mod noise;
pub mod nonnegative;
mod print;
mod release;

pub use lower::{effect_violations, lower, lower_reporting, lower_unguarded, LowerError};
pub use model::{
    uses_closure, var_name, Balance, Closure, ClosureOutput, Constraint, Definition, Dynamics,
    Expr, Input, Measured, Model, Noise, Param, PriorKind, State, Var,
};
#[cfg(test)]
pub use model::{Const, Embedding, Network, Prior};
pub use noise::{merge_noise, parse_noise_spec, NoiseSpec};
pub use print::{expr_text, print};
pub use release::{releasable, release};
