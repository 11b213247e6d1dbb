//! Straight-line register code compiled from expressions.
//!
//! Each instruction writes one register, reading its operands from a slot, an earlier
//! register or an immediate value. Compilation folds instructions whose operands are all
//! immediate (literals and consts) and shares identical subexpressions (hash-consing), so
//! a `let` inlined in several balances is computed once per evaluation of a
//! [`ProgramSet`].

use super::layout::Layout;
use super::scalar::{apply_binary, apply_func};
use crate::ir::{BinOp, Expr, Func, Model, Var};
use std::collections::HashMap;

/// Why an expression could not be compiled against a layout.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompileError {
    /// The expression names a quantity the layout's model does not have.
    #[error("internal error: variable {0:?} is not part of the model")]
    UnknownVar(Var),
    /// The balances do not govern each state exactly once.
    #[error("internal error: the balances do not govern each state exactly once")]
    Balances,
}

/// Where an instruction reads a value from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Operand {
    Slot(usize),
    Register(usize),
    Value(f64),
}

/// One instruction; its result goes to the register with its own index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Instr {
    Neg(Operand),
    Square(Operand),
    Binary(BinOp, Operand, Operand),
    Call(Func, Operand, Operand),
    /// `1` unless the first operand is at most the second (so `1` where either is NaN),
    /// else `0`: the branch indicator of the derivatives of `abs`, `min` and `max`; never in
    /// a program compiled from an expression alone.
    Exceeds(Operand, Operand),
    /// The chain rule's product `slope * partial`, `0` where the partial is `0`: a slope
    /// that is infinite (`sqrt` at `0`) or NaN times an inner function that does not move
    /// there is `0`, the limit the finite differences see; never in a program compiled from
    /// an expression alone.
    Chain(Operand, Operand),
}

/// The identity of an instruction for sharing: immediates compared by their bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum OperandKey {
    Slot(usize),
    Register(usize),
    Value(u64),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum InstrKey {
    Neg(OperandKey),
    Square(OperandKey),
    Binary(BinOp, OperandKey, OperandKey),
    Call(Func, OperandKey, OperandKey),
    Exceeds(OperandKey, OperandKey),
    Chain(OperandKey, OperandKey),
}

impl Operand {
    fn key(self) -> OperandKey {
        match self {
            Operand::Slot(slot) => OperandKey::Slot(slot),
            Operand::Register(register) => OperandKey::Register(register),
            Operand::Value(value) => OperandKey::Value(value.to_bits()),
        }
    }

    #[inline(always)]
    pub(super) fn fetch(self, slots: &[f64], registers: &[f64]) -> f64 {
        match self {
            Operand::Slot(slot) => slots[slot],
            Operand::Register(register) => registers[register],
            Operand::Value(value) => value,
        }
    }
}

impl Instr {
    fn key(self) -> InstrKey {
        match self {
            Instr::Neg(a) => InstrKey::Neg(a.key()),
            Instr::Square(a) => InstrKey::Square(a.key()),
            Instr::Binary(op, a, b) => InstrKey::Binary(op, a.key(), b.key()),
            Instr::Call(func, a, b) => InstrKey::Call(func, a.key(), b.key()),
            Instr::Exceeds(a, b) => InstrKey::Exceeds(a.key(), b.key()),
            Instr::Chain(a, b) => InstrKey::Chain(a.key(), b.key()),
        }
    }

    fn is_immediate(self) -> bool {
        let immediate = |operand: Operand| matches!(operand, Operand::Value(_));
        match self {
            Instr::Neg(a) | Instr::Square(a) => immediate(a),
            Instr::Binary(_, a, b)
            | Instr::Call(_, a, b)
            | Instr::Exceeds(a, b)
            | Instr::Chain(a, b) => immediate(a) && immediate(b),
        }
    }

    #[inline(always)]
    fn execute(self, slots: &[f64], registers: &[f64]) -> f64 {
        match self {
            Instr::Neg(a) => -a.fetch(slots, registers),
            Instr::Square(a) => {
                let value = a.fetch(slots, registers);
                value * value
            }
            Instr::Binary(op, a, b) => {
                apply_binary(op, a.fetch(slots, registers), b.fetch(slots, registers))
            }
            Instr::Call(func, a, b) => {
                apply_func(func, a.fetch(slots, registers), b.fetch(slots, registers))
            }
            Instr::Exceeds(a, b) => {
                let (a, b) = (a.fetch(slots, registers), b.fetch(slots, registers));
                // `a > b` or either is NaN: not `a <= b`.
                f64::from(u8::from(a.partial_cmp(&b).is_none_or(|o| o.is_gt())))
            }
            Instr::Chain(slope, partial) => {
                let partial = partial.fetch(slots, registers);
                if partial == 0.0 {
                    0.0
                } else {
                    slope.fetch(slots, registers) * partial
                }
            }
        }
    }
}

/// Builds register code, folding immediates and sharing repeated instructions.
pub(super) struct Builder<'a> {
    layout: &'a Layout,
    pub(super) code: Vec<Instr>,
    shared: HashMap<InstrKey, usize>,
}

impl<'a> Builder<'a> {
    pub(super) fn new(layout: &'a Layout) -> Self {
        Builder {
            layout,
            code: Vec::new(),
            shared: HashMap::new(),
        }
    }

    pub(super) fn lower(&mut self, expr: &Expr) -> Result<Operand, CompileError> {
        let instr = match expr {
            Expr::Num(value) => return Ok(Operand::Value(*value)),
            Expr::Var(var) => return self.variable(*var),
            Expr::Neg(inner) => Instr::Neg(self.lower(inner)?),
            Expr::Bin(BinOp::Pow, base, exponent) if matches!(**exponent, Expr::Num(two) if two == 2.0) => {
                Instr::Square(self.lower(base)?)
            }
            Expr::Bin(op, left, right) => Instr::Binary(*op, self.lower(left)?, self.lower(right)?),
            Expr::Call(func, args) => {
                let mut argument = |k: usize| match args.get(k) {
                    Some(arg) => self.lower(arg),
                    None => Ok(Operand::Value(f64::NAN)),
                };
                let first = argument(0)?;
                let second = if func.arity() == 2 {
                    argument(1)?
                } else {
                    Operand::Value(0.0)
                };
                Instr::Call(*func, first, second)
            }
        };
        Ok(self.emit(instr))
    }

    fn variable(&self, var: Var) -> Result<Operand, CompileError> {
        if !self.layout.contains(var) {
            return Err(CompileError::UnknownVar(var));
        }
        Ok(match var {
            Var::Const(index) => match self.layout.const_value(index) {
                Some(value) => Operand::Value(value),
                None => return Err(CompileError::UnknownVar(var)),
            },
            _ => Operand::Slot(self.layout.slot(var)),
        })
    }

    pub(super) fn emit(&mut self, instr: Instr) -> Operand {
        if instr.is_immediate() {
            return Operand::Value(instr.execute(&[], &[]));
        }
        let register = *self.shared.entry(instr.key()).or_insert(self.code.len());
        if register == self.code.len() {
            self.code.push(instr);
        }
        Operand::Register(register)
    }
}

/// Runs `code`, leaving instruction `i`'s result in `registers[i]`.
#[inline]
pub(super) fn run(code: &[Instr], slots: &[f64], registers: &mut Vec<f64>) {
    if registers.len() < code.len() {
        registers.resize(code.len(), 0.0);
    }
    for (index, instr) in code.iter().enumerate() {
        let value = instr.execute(slots, &registers[..index]);
        registers[index] = value;
    }
}

/// One compiled expression.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    code: Vec<Instr>,
    result: Operand,
}

impl Program {
    /// Compiles `expr` against `layout`.
    pub fn compile(expr: &Expr, layout: &Layout) -> Result<Self, CompileError> {
        let mut builder = Builder::new(layout);
        let result = builder.lower(expr)?;
        Ok(Program {
            code: builder.code,
            result,
        })
    }

    /// Evaluates the program on `slots` (laid out by the layout it was compiled against),
    /// using `scratch` as registers; `scratch` only grows, so reusing it avoids allocation.
    ///
    /// Panics if `slots` is shorter than the layout.
    pub fn eval(&self, slots: &[f64], scratch: &mut Vec<f64>) -> f64 {
        run(&self.code, slots, scratch);
        self.result.fetch(slots, scratch)
    }

    /// The value of the program if it folded to a constant.
    #[cfg(test)]
    pub fn as_constant(&self) -> Option<f64> {
        match self.result {
            Operand::Value(value) => Some(value),
            _ => None,
        }
    }

    /// Number of instructions executed per evaluation.
    #[cfg(test)]
    pub fn instruction_count(&self) -> usize {
        self.code.len()
    }
}

/// Several expressions compiled together, sharing their common subexpressions.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramSet {
    code: Vec<Instr>,
    results: Vec<Operand>,
}

impl ProgramSet {
    /// Compiles `exprs` against `layout`; result `k` is the value of `exprs[k]`.
    pub fn compile<'e>(
        exprs: impl IntoIterator<Item = &'e Expr>,
        layout: &Layout,
    ) -> Result<Self, CompileError> {
        let mut builder = Builder::new(layout);
        let results = exprs
            .into_iter()
            .map(|expr| builder.lower(expr))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ProgramSet {
            code: builder.code,
            results,
        })
    }

    /// Evaluates every expression on `slots` into `out` (`out[k]` for expression `k`).
    ///
    /// Panics if `out` is shorter than [`ProgramSet::len`] or `slots` than the layout.
    pub fn eval_into(&self, slots: &[f64], scratch: &mut Vec<f64>, out: &mut [f64]) {
        run(&self.code, slots, scratch);
        for (value, result) in out.iter_mut().zip(&self.results) {
            *value = result.fetch(slots, scratch);
        }
    }

    /// Number of expressions.
    pub fn len(&self) -> usize {
        self.results.len()
    }
}

/// All balances of a model compiled together: the right-hand side `f` of `dx/dt = f`
/// (or of `x(t + h) = f` for a discrete model), in the state order of
/// [`Layout::state_range`] (measured states, then hidden).
#[derive(Debug, Clone, PartialEq)]
pub struct CompiledRhs {
    set: ProgramSet,
}

impl CompiledRhs {
    /// Compiles the balances of `model` against `layout`.
    pub fn new(model: &Model, layout: &Layout) -> Result<Self, CompileError> {
        Ok(CompiledRhs {
            set: ProgramSet::compile(balance_order(model, layout)?, layout)?,
        })
    }

    /// Number of states.
    pub fn dim(&self) -> usize {
        self.set.len()
    }

    /// Evaluates every balance on `slots` into `out` (length [`CompiledRhs::dim`]).
    pub fn eval(&self, slots: &[f64], scratch: &mut Vec<f64>, out: &mut [f64]) {
        self.set.eval_into(slots, scratch, out);
    }
}

/// The balances' expressions in the state order of [`Layout::state_range`] (measured
/// states, then hidden); an error unless they govern each state exactly once.
pub(super) fn balance_order<'m>(
    model: &'m Model,
    layout: &Layout,
) -> Result<Vec<&'m Expr>, CompileError> {
    let states = layout.state_range();
    let mut ordered: Vec<Option<&Expr>> = vec![None; states.len()];
    for balance in &model.balances {
        let governed = match balance.state {
            Var::State(_) | Var::Hidden(_) if layout.contains(balance.state) => {
                layout.slot(balance.state) - states.start
            }
            _ => return Err(CompileError::Balances),
        };
        if ordered[governed].replace(&balance.expr).is_some() {
            return Err(CompileError::Balances);
        }
    }
    ordered
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or(CompileError::Balances)
}
