//! Fast numeric programs compiled from IR expressions.
//!
//! A [`Layout`] gives every [`Var`] of a model a slot in one flat `f64` array. A
//! [`Program`] (one expression) or a [`ProgramSet`] (several expressions sharing common
//! subexpressions) is compiled against that layout into straight-line register code: no
//! name look-ups, no allocation and no recursion when evaluated. Literal arithmetic and
//! consts are folded at compile time. [`CompiledRhs`] evaluates all balances of a model
//! at once. [`JacobianProgram`] adds the exact derivatives of such code with respect to
//! chosen slots (states, params), for the implicit integrator and forward sensitivities.
//! [`interpret`] is a plain tree-walking interpreter kept as an independent
//! reference for tests.
//!
//! **Invariant:** const slots are folded into the code, so changing a const's slot value
//! after compilation has no effect; params, states, hidden states, inputs and closure
//! outputs are read from the slots at every evaluation.

mod derivative;
mod interpret;
mod layout;
mod program;
mod scalar;
#[cfg(test)]
mod tests;

#[cfg(test)]
pub use crate::vocabulary::softplus;
pub use derivative::JacobianProgram;
pub use interpret::interpret;
pub use layout::Layout;
pub use program::{CompileError, CompiledRhs, Program, ProgramSet};
pub use scalar::sigmoid;
