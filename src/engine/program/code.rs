//! The compiled program as data: its instructions, what it reads, and the registers of
//! what it computes (the compiler writes it, [`super::Program`]'s methods run it).

use crate::engine::elementwise::{Binary, Unary};
use crate::engine::error::BackendError;
use crate::ir::{self, Var};

/// One instruction; operands are earlier registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Instr {
    /// A literal, stored as its bit pattern so instructions can be hashed.
    Const(u64),
    /// Entry `i` of the state vector (measured states, then hidden states).
    State(usize),
    /// Held input `i`.
    Input(usize),
    /// Unconstrained (raw) value of param `i`.
    RawParam(usize),
    /// Network output `output` of closure `closure` (before prior and scale).
    Net {
        closure: usize,
        output: usize,
    },
    Unary(Unary, usize),
    Binary(Binary, usize, usize),
}

/// How many values of each kind a program reads per row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProgramShape {
    /// Length of the state vector (measured + hidden).
    pub states: usize,
    /// Number of inputs.
    pub inputs: usize,
    /// Number of params.
    pub params: usize,
    /// Number of network outputs of each closure.
    pub nets: Vec<usize>,
}

/// The compiled physics of a model.
#[derive(Debug, Clone)]
pub struct Program {
    pub(super) instrs: Vec<Instr>,
    /// Whether register `r` depends on a state, a raw param or a network output.
    pub(super) active: Vec<bool>,
    /// Whether register `r` holds the same value on every row (literals, raw params and
    /// what is computed from them alone): evaluated once per batch, not per row.
    pub(super) uniform: Vec<bool>,
    pub(super) shape: ProgramShape,
    /// Per state-vector entry, the register of its balance (derivative or next value).
    pub balances: Vec<usize>,
    /// Registers of every closure output, closures in order, outputs in order.
    pub closure_outputs: Vec<usize>,
    /// Registers of the constrained param values.
    pub param_values: Vec<usize>,
    /// Registers of the model's `output`s.
    pub outputs: Vec<usize>,
}

/// Position of a state or hidden state in the state vector (measured first).
pub fn state_index(model: &ir::Model, var: Var) -> Result<usize, BackendError> {
    match var {
        Var::State(i) if i < model.states.len() => Ok(i),
        Var::Hidden(j) if j < model.hidden.len() => Ok(model.states.len() + j),
        other => Err(BackendError::internal(format!(
            "{other:?} is not a state of the model"
        ))),
    }
}
