//! The compiler of [`Program`]: the model's expressions lowered to register instructions,
//! shared sub-expressions interned, constants folded, and the registers that take part in
//! the reverse sweep marked.

use std::collections::HashMap;

use super::code::{state_index, Instr, Program, ProgramShape};
use crate::engine::elementwise::{binary, unary, Binary, Unary};
use crate::engine::error::BackendError;
use crate::ir::{self, BinOp, Constraint, Func, Var};

/// Builds a [`Program`] from a model; `scales[c][k]` is the magnitude `s_o` of output `k`
/// of closure `c` (already resolved from `~` or the data-driven default).
pub(super) struct Compiler<'m> {
    pub(super) model: &'m ir::Model,
    pub(super) scales: &'m [Vec<f64>],
    pub(super) instrs: Vec<Instr>,
    pub(super) interned: HashMap<Instr, usize>,
    pub(super) closure_output_regs: HashMap<(usize, usize), usize>,
    pub(super) param_regs: HashMap<usize, usize>,
    pub(super) in_progress: Vec<(usize, usize)>,
    /// Whether closure outputs are their known part plus their network slot:
    /// [`Program::compile_with_free_outputs`].
    pub(super) free_outputs: bool,
}

impl<'m> Compiler<'m> {
    pub(super) fn new(model: &'m ir::Model, scales: &'m [Vec<f64>], free_outputs: bool) -> Self {
        Compiler {
            model,
            scales,
            instrs: Vec::new(),
            interned: HashMap::new(),
            closure_output_regs: HashMap::new(),
            param_regs: HashMap::new(),
            in_progress: Vec::new(),
            free_outputs,
        }
    }

    /// The program of the whole model: balances, closure outputs, params, `output`s.
    pub(super) fn program(mut self) -> Result<Program, BackendError> {
        let model = self.model;
        let state_count = model.states.len() + model.hidden.len();
        let mut balances = vec![None; state_count];
        for balance in &model.balances {
            let index = state_index(model, balance.state)?;
            balances[index] = Some(self.expr(&balance.expr)?);
        }
        let balances = balances
            .into_iter()
            .enumerate()
            .map(|(index, reg)| {
                reg.ok_or_else(|| BackendError::internal(format!("state {index} has no balance")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut closure_outputs = Vec::new();
        for (closure, spec) in model.closures.iter().enumerate() {
            for output in 0..spec.outputs.len() {
                closure_outputs.push(self.closure_output(closure, output)?);
            }
        }
        let param_values = (0..model.params.len())
            .map(|index| self.param(index))
            .collect::<Result<Vec<_>, _>>()?;
        let outputs = model
            .outputs
            .iter()
            .map(|definition| self.expr(&definition.expr))
            .collect::<Result<Vec<_>, _>>()?;
        let shape = ProgramShape {
            states: state_count,
            inputs: model.inputs.len(),
            params: model.params.len(),
            nets: model.closures.iter().map(|c| c.outputs.len()).collect(),
        };
        let active = activity(&self.instrs);
        let uniform = uniformity(&self.instrs);
        Ok(Program {
            instrs: self.instrs,
            active,
            uniform,
            shape,
            balances,
            closure_outputs,
            param_values,
            outputs,
        })
    }
}

impl Compiler<'_> {
    pub(super) fn push(&mut self, instr: Instr) -> usize {
        if let Some(folded) = self.fold(instr) {
            return self.push(Instr::Const(folded.to_bits()));
        }
        if let Some(&reg) = self.interned.get(&instr) {
            return reg;
        }
        self.instrs.push(instr);
        let reg = self.instrs.len() - 1;
        self.interned.insert(instr, reg);
        reg
    }

    /// The value of an instruction whose operands are all literals.
    pub(super) fn fold(&self, instr: Instr) -> Option<f64> {
        let literal = |reg: usize| match self.instrs[reg] {
            Instr::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        };
        match instr {
            Instr::Unary(op, a) => Some(unary(op, literal(a)?)),
            Instr::Binary(op, a, b) => Some(binary(op, literal(a)?, literal(b)?)),
            _ => None,
        }
    }

    pub(super) fn constant(&mut self, value: f64) -> usize {
        self.push(Instr::Const(value.to_bits()))
    }

    pub(super) fn unary(&mut self, op: Unary, a: usize) -> usize {
        self.push(Instr::Unary(op, a))
    }

    pub(super) fn binary(&mut self, op: Binary, a: usize, b: usize) -> usize {
        self.push(Instr::Binary(op, a, b))
    }

    pub(super) fn expr(&mut self, expr: &ir::Expr) -> Result<usize, BackendError> {
        Ok(match expr {
            ir::Expr::Num(value) => self.constant(*value),
            ir::Expr::Var(var) => self.var(*var)?,
            ir::Expr::Neg(inner) => {
                let a = self.expr(inner)?;
                self.unary(Unary::Neg, a)
            }
            ir::Expr::Bin(op, left, right) => {
                let a = self.expr(left)?;
                let b = self.expr(right)?;
                self.binary(binary_of(*op), a, b)
            }
            ir::Expr::Call(func, args) => self.call(*func, args)?,
        })
    }

    pub(super) fn call(&mut self, func: Func, args: &[ir::Expr]) -> Result<usize, BackendError> {
        if args.len() != func.arity() {
            return Err(BackendError::internal(format!(
                "{} called with {} arguments",
                func.name(),
                args.len()
            )));
        }
        let registers = args
            .iter()
            .map(|arg| self.expr(arg))
            .collect::<Result<Vec<_>, _>>()?;
        let op = match func {
            Func::Exp => Unary::Exp,
            Func::Log => Unary::Log,
            Func::Sqrt => Unary::Sqrt,
            Func::Abs => Unary::Abs,
            Func::Tanh => Unary::Tanh,
            Func::Sigmoid => Unary::Sigmoid,
            Func::Softplus => Unary::Softplus,
            Func::Min => return Ok(self.binary(Binary::Min, registers[0], registers[1])),
            Func::Max => return Ok(self.binary(Binary::Max, registers[0], registers[1])),
            Func::Pow => return Ok(self.binary(Binary::Pow, registers[0], registers[1])),
        };
        Ok(self.unary(op, registers[0]))
    }

    pub(super) fn var(&mut self, var: Var) -> Result<usize, BackendError> {
        match var {
            Var::Input(i) => Ok(self.push(Instr::Input(i))),
            Var::State(_) | Var::Hidden(_) => {
                let index = state_index(self.model, var)?;
                Ok(self.push(Instr::State(index)))
            }
            Var::Const(i) => {
                let value = (self.model.consts.get(i))
                    .ok_or_else(|| BackendError::internal(format!("no const {i}")))?
                    .value;
                Ok(self.constant(value))
            }
            Var::Param(i) => self.param(i),
            Var::ClosureOutput { closure, output } => self.closure_output(closure, output),
        }
    }

    /// The constrained value of param `index` (spec section 2: `positive`, `in [lo, hi]`).
    pub(super) fn param(&mut self, index: usize) -> Result<usize, BackendError> {
        if let Some(&reg) = self.param_regs.get(&index) {
            return Ok(reg);
        }
        let param = (self.model.params.get(index))
            .ok_or_else(|| BackendError::internal(format!("no param {index}")))?;
        let raw = self.push(Instr::RawParam(index));
        let reg = self.constrain(raw, param.constraint, 1.0);
        self.param_regs.insert(index, reg);
        Ok(reg)
    }

    /// Maps an unconstrained register onto a constraint: `scale * softplus(raw / scale)` for
    /// `positive` (scale 1 for params) and `lo + (hi - lo) sigmoid(raw)` for bounds.
    pub(super) fn constrain(&mut self, raw: usize, constraint: Constraint, scale: f64) -> usize {
        match constraint {
            Constraint::Free => raw,
            Constraint::Positive => {
                let inverse = self.constant(1.0 / scale);
                let scaled = self.binary(Binary::Mul, raw, inverse);
                let soft = self.unary(Unary::Softplus, scaled);
                let outer = self.constant(scale);
                self.binary(Binary::Mul, outer, soft)
            }
            Constraint::Bounds(lo, hi) => {
                let squashed = self.unary(Unary::Sigmoid, raw);
                let width = self.constant(hi - lo);
                let spread = self.binary(Binary::Mul, width, squashed);
                let low = self.constant(lo);
                self.binary(Binary::Add, low, spread)
            }
        }
    }
}

fn binary_of(op: BinOp) -> Binary {
    match op {
        BinOp::Add => Binary::Add,
        BinOp::Sub => Binary::Sub,
        BinOp::Mul => Binary::Mul,
        BinOp::Div => Binary::Div,
        BinOp::Pow => Binary::Pow,
    }
}

/// Marks registers that depend on a state, raw param or network output.
fn activity(instrs: &[Instr]) -> Vec<bool> {
    let mut active = Vec::with_capacity(instrs.len());
    for instr in instrs {
        let is_active = match *instr {
            Instr::Const(_) | Instr::Input(_) => false,
            Instr::State(_) | Instr::RawParam(_) | Instr::Net { .. } => true,
            Instr::Unary(_, a) => active[a],
            Instr::Binary(_, a, b) => active[a] || active[b],
        };
        active.push(is_active);
    }
    active
}

/// Marks registers that hold one value for every row: literals, raw params, and operations
/// on those alone.
fn uniformity(instrs: &[Instr]) -> Vec<bool> {
    let mut uniform = Vec::with_capacity(instrs.len());
    for instr in instrs {
        let is_uniform = match *instr {
            Instr::Const(_) | Instr::RawParam(_) => true,
            Instr::State(_) | Instr::Input(_) | Instr::Net { .. } => false,
            Instr::Unary(_, a) => uniform[a],
            Instr::Binary(_, a, b) => uniform[a] && uniform[b],
        };
        uniform.push(is_uniform);
    }
    uniform
}
