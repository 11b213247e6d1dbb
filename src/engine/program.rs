//! The physics layer as a register program: the model's balances, closure outputs (priors
//! and scales applied), param transforms and `output`s compiled from [`ir::Expr`] into a flat
//! list of instructions evaluated column-wise on a batch, with a hand-written reverse sweep.
//!
//! Each register holds one value per batch row. Identical sub-expressions share a register
//! (the IR inlines `let`s, so `mu` used in two balances is computed once), constant
//! sub-expressions are folded at compile time, and only registers that depend on a state,
//! a param or a network output take part in the reverse sweep. The graph backend wraps
//! [`Program::forward`] and [`Program::backward`] as one fused operation.

mod code;
mod compile;
pub mod outputs;

pub use code::{state_index, Program, ProgramShape};

use code::Instr;
use compile::Compiler;

use super::elementwise::{
    binary, binary_column, binary_column_reverse, binary_derivatives, unary, unary_column,
    unary_column_reverse, unary_derivative, Operands,
};
use super::error::BackendError;
use crate::ir;
use crate::numeric::Real;

/// The values a program reads: row-major `rows x width` blocks.
#[derive(Debug, Clone, Copy)]
pub struct ProgramInputs<'a, E> {
    /// Batch rows.
    pub rows: usize,
    /// `rows x shape.states`.
    pub states: &'a [E],
    /// `rows x shape.inputs`.
    pub inputs: &'a [E],
    /// Raw (unconstrained) params, one each.
    pub params: &'a [E],
    /// Per closure, `rows x shape.nets[c]`.
    pub nets: &'a [&'a [E]],
}

/// Gradients of a scalar with respect to everything a program reads.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramGradients<E> {
    /// `rows x shape.states`.
    pub states: Vec<E>,
    /// One per raw param (summed over rows).
    pub params: Vec<E>,
    /// Per closure, `rows x shape.nets[c]`.
    pub nets: Vec<Vec<E>>,
}

impl Program {
    /// Compiles the physics of `model` (spec section 3 for closure outputs; params through
    /// their transforms: `positive` as softplus, `in [lo, hi]` as `lo + (hi - lo) sigmoid`).
    pub fn compile(model: &ir::Model, scales: &[Vec<f64>]) -> Result<Program, BackendError> {
        Compiler::new(model, scales, false).program()
    }

    /// The physics with every closure output `o = k_o + v_o`: `k_o` its value at network
    /// output 0 when it has a prior (0 without one), `v_o` read from its network slot, so that
    /// callers set the unknown part of each output themselves: what the balances ask of the
    /// outputs before training (`train::analysis`).
    pub fn compile_with_free_outputs(model: &ir::Model) -> Result<Program, BackendError> {
        Compiler::new(model, &[], true).program()
    }

    /// What the program reads per row.
    pub fn shape(&self) -> &ProgramShape {
        &self.shape
    }

    /// Evaluates every register on a batch; register `r` is `values[r * rows..][..rows]`.
    pub fn forward<E: Real>(&self, inputs: &ProgramInputs<E>) -> Vec<E> {
        let mut values = Vec::new();
        self.forward_into(inputs, &mut values);
        values
    }

    /// [`Program::forward`] into a buffer kept from call to call (every register is
    /// written, so what it held does not matter).
    pub fn forward_into<E: Real>(&self, inputs: &ProgramInputs<E>, values: &mut Vec<E>) {
        let rows = inputs.rows;
        values.resize(self.instrs.len() * rows, E::ZERO);
        if rows == 0 {
            return;
        }
        for (index, instr) in self.instrs.iter().enumerate() {
            let (before, rest) = values.split_at_mut(index * rows);
            let out = &mut rest[..rows];
            let column = |reg: usize| &before[reg * rows..(reg + 1) * rows];
            if self.uniform[index] {
                // The same value on every row: computed once, then spread.
                let first = |reg: usize| before[reg * rows];
                let value = match *instr {
                    Instr::Const(bits) => E::from_double(f64::from_bits(bits)),
                    Instr::RawParam(i) => inputs.params[i],
                    Instr::Unary(op, a) => unary(op, first(a)),
                    Instr::Binary(op, a, b) => binary(op, first(a), first(b)),
                    Instr::State(_) | Instr::Input(_) | Instr::Net { .. } => E::ZERO,
                };
                out.fill(value);
                continue;
            }
            match *instr {
                Instr::Const(bits) => out.fill(E::from_double(f64::from_bits(bits))),
                Instr::State(i) => gather(out, inputs.states, self.shape.states, i),
                Instr::Input(i) => gather(out, inputs.inputs, self.shape.inputs, i),
                Instr::RawParam(i) => out.fill(inputs.params[i]),
                Instr::Net { closure, output } => {
                    gather(out, inputs.nets[closure], self.shape.nets[closure], output)
                }
                Instr::Unary(op, a) => unary_column(op, out, column(a)),
                Instr::Binary(op, a, b) => binary_column(op, out, column(a), column(b)),
            }
        }
    }

    /// Reads registers `targets` from forward `values` as a row-major `rows x targets.len()`
    /// block.
    pub fn read<E: Real>(&self, values: &[E], rows: usize, targets: &[usize]) -> Vec<E> {
        let mut block = vec![E::ZERO; rows * targets.len()];
        for (column, &reg) in targets.iter().enumerate() {
            for row in 0..rows {
                block[row * targets.len() + column] = values[reg * rows + row];
            }
        }
        block
    }

    /// Reverse sweep: given forward `values` and the adjoint `seed` (row-major
    /// `rows x targets.len()`) of registers `targets`, returns the gradients of everything
    /// the program reads.
    pub fn backward<E: Real>(
        &self,
        inputs: &ProgramInputs<E>,
        values: &[E],
        targets: &[usize],
        seed: &[E],
    ) -> ProgramGradients<E> {
        let mut scratch = ReverseScratch::default();
        self.backward_into(inputs, values, (targets, seed), &mut scratch);
        scratch.gradients
    }

    /// [`Program::backward`] into buffers kept from call to call; the gradients are left in
    /// `scratch.gradients`.
    pub fn backward_into<E: Real>(
        &self,
        inputs: &ProgramInputs<E>,
        values: &[E],
        (targets, seed): (&[usize], &[E]),
        scratch: &mut ReverseScratch<E>,
    ) {
        let rows = inputs.rows;
        let ReverseScratch { adjoint, gradients } = scratch;
        adjoint.clear();
        adjoint.resize(values.len(), E::ZERO);
        for (column, &reg) in targets.iter().enumerate() {
            for row in 0..rows {
                adjoint[reg * rows + row] += seed[row * targets.len() + column];
            }
        }
        refill(&mut gradients.states, rows * self.shape.states);
        refill(&mut gradients.params, self.shape.params);
        (gradients.nets).resize_with(self.shape.nets.len(), Vec::new);
        for (net, &width) in gradients.nets.iter_mut().zip(&self.shape.nets) {
            refill(net, rows * width);
        }
        if rows == 0 {
            return;
        }
        for index in (0..self.instrs.len()).rev() {
            if !self.active[index] {
                continue;
            }
            let (adjoint_before, adjoint_rest) = adjoint.split_at_mut(index * rows);
            let upstream = &adjoint_rest[..rows];
            let value = |reg: usize| &values[reg * rows..(reg + 1) * rows];
            if self.uniform[index] {
                // Every row holds the same value: the row sum of the adjoint goes to the
                // operands' first rows (their own sweep sums their rows in turn).
                let total = upstream.iter().fold(E::ZERO, |sum, &g| sum + g);
                let first = |reg: usize| values[reg * rows];
                match self.instrs[index] {
                    Instr::RawParam(i) => gradients.params[i] += total,
                    Instr::Unary(op, a) => {
                        adjoint_before[a * rows] +=
                            total * unary_derivative(op, first(a), first(index));
                    }
                    Instr::Binary(op, a, b) => {
                        let (da, db) = binary_derivatives(op, first(a), first(b), first(index));
                        adjoint_before[a * rows] += total * da;
                        adjoint_before[b * rows] += total * db;
                    }
                    Instr::Const(_) | Instr::State(_) | Instr::Input(_) | Instr::Net { .. } => {}
                }
                continue;
            }
            match self.instrs[index] {
                Instr::Const(_) | Instr::Input(_) => {}
                Instr::State(i) => scatter(&mut gradients.states, self.shape.states, i, upstream),
                Instr::RawParam(i) => {
                    for &g in upstream {
                        gradients.params[i] += g;
                    }
                }
                Instr::Net { closure, output } => scatter(
                    &mut gradients.nets[closure],
                    self.shape.nets[closure],
                    output,
                    upstream,
                ),
                Instr::Unary(op, a) => {
                    let target = &mut adjoint_before[a * rows..(a + 1) * rows];
                    unary_column_reverse(op, target, upstream, (value(a), value(index)));
                }
                Instr::Binary(op, a, b) => {
                    let operands = operand_adjoints(adjoint_before, rows, a, b);
                    let columns = (value(a), value(b), value(index));
                    binary_column_reverse(op, operands, upstream, columns);
                }
            }
        }
    }
}

/// Buffers of [`Program::backward_into`].
#[derive(Debug, Clone)]
pub struct ReverseScratch<E> {
    /// One adjoint per register and row.
    adjoint: Vec<E>,
    /// The gradients of the last sweep.
    pub gradients: ProgramGradients<E>,
}

impl<E> Default for ReverseScratch<E> {
    fn default() -> Self {
        ReverseScratch {
            adjoint: Vec::new(),
            gradients: ProgramGradients {
                states: Vec::new(),
                params: Vec::new(),
                nets: Vec::new(),
            },
        }
    }
}

/// Zeroes `buffer` at `length` entries.
fn refill<E: Real>(buffer: &mut Vec<E>, length: usize) {
    buffer.clear();
    buffer.resize(length, E::ZERO);
}

/// The adjoint columns of registers `a` and `b` (both below the current one).
fn operand_adjoints<E>(adjoint: &mut [E], rows: usize, a: usize, b: usize) -> Operands<'_, E> {
    if a == b {
        return Operands::Same(&mut adjoint[a * rows..(a + 1) * rows]);
    }
    let (low, high) = (a.min(b), a.max(b));
    let (head, tail) = adjoint.split_at_mut(high * rows);
    let (low_column, high_column) = (&mut head[low * rows..(low + 1) * rows], &mut tail[..rows]);
    if a < b {
        Operands::Distinct(low_column, high_column)
    } else {
        Operands::Distinct(high_column, low_column)
    }
}

fn gather<E: Real>(out: &mut [E], block: &[E], width: usize, column: usize) {
    for (row, value) in out.iter_mut().enumerate() {
        *value = block[row * width + column];
    }
}

fn scatter<E: Real>(block: &mut [E], width: usize, column: usize, values: &[E]) {
    for (row, &value) in values.iter().enumerate() {
        block[row * width + column] += value;
    }
}
