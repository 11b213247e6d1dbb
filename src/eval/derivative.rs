//! Exact first derivatives of compiled expressions, as straight-line code.
//!
//! [`JacobianProgram::compile`] lowers expressions into register code (as
//! [`super::ProgramSet`] does) and then differentiates that code forward, instruction by
//! instruction, with respect to chosen slots: each register's partial derivatives are new
//! instructions built from its operands' partials by the chain rule. The derivative code
//! goes through the same builder, so literals fold (a partial that is structurally zero
//! never exists: the Jacobian is sparse by construction), and repeated subexpressions are
//! shared with the values and with each other. Nothing is finite-differenced: the result
//! is the derivative of the very arithmetic the values are computed with.
//!
//! Non-smooth functions get their one-sided derivative: `abs'(0) = 0`; `min(a, b)` follows
//! `a` where `a <= b`, `max(a, b)` follows `a` where `a >= b`.

use super::layout::Layout;
use super::program::{balance_order, run, Builder, CompileError, Instr, Operand};
use crate::ir::{BinOp, Expr, Func, Model};

/// The partial derivatives of one register: `(column, value)` by increasing column.
type Partials = Vec<(usize, Operand)>;

/// Values of expressions and their derivatives with respect to chosen slots.
#[derive(Debug, Clone, PartialEq)]
pub struct JacobianProgram {
    code: Vec<Instr>,
    values: Vec<Operand>,
    /// `(row, column, value)` of every entry that is not structurally zero.
    entries: Vec<(usize, usize, Operand)>,
    columns: usize,
}

impl JacobianProgram {
    /// Compiles `exprs` and their derivatives with respect to the slots `wrt` (column `c`
    /// of the Jacobian is the derivative with respect to slot `wrt[c]`).
    pub fn compile<'e>(
        exprs: impl IntoIterator<Item = &'e Expr>,
        layout: &Layout,
        wrt: &[usize],
    ) -> Result<Self, CompileError> {
        let mut builder = Builder::new(layout);
        let values = exprs
            .into_iter()
            .map(|expr| builder.lower(expr))
            .collect::<Result<Vec<_>, _>>()?;
        let mut differentiator = Differentiator {
            builder,
            wrt,
            partials: Vec::new(),
        };
        differentiator.sweep();
        let mut entries = Vec::new();
        for (row, value) in values.iter().enumerate() {
            for (column, partial) in differentiator.partials_of(*value) {
                entries.push((row, column, partial));
            }
        }
        Ok(JacobianProgram {
            code: differentiator.builder.code,
            values,
            entries,
            columns: wrt.len(),
        })
    }

    /// The balances of `model` (state order of [`Layout::state_range`]) and their
    /// derivatives with respect to the slots `wrt`.
    pub fn balances(model: &Model, layout: &Layout, wrt: &[usize]) -> Result<Self, CompileError> {
        JacobianProgram::compile(balance_order(model, layout)?, layout, wrt)
    }

    /// Number of slots differentiated by (columns).
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// The `(row, column)` of every entry that is not structurally zero: which expression
    /// reads which slot.
    pub fn structure(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.entries.iter().map(|&(row, column, _)| (row, column))
    }

    /// Number of entries that are not structurally zero.
    #[cfg(test)]
    pub fn nonzeros(&self) -> usize {
        self.entries.len()
    }

    /// Evaluates on `slots` the product of the Jacobian with a matrix: `out = J[:, ..k] m +
    /// J[:, k..]` padded with zero columns to `width`, where `k` = the rows of `m` (`k x
    /// width`, row-major) and `out` is `rows x width`: the derivative of forward
    /// sensitivities `m` by the first `k` slots (the states), the rest (params) added as
    /// they are. Only the entries that are not structurally zero are visited.
    pub fn eval_product(
        &self,
        slots: &[f64],
        scratch: &mut Vec<f64>,
        m: &[f64],
        width: usize,
        out: &mut [f64],
    ) {
        if width == 0 {
            // No sensitivity is carried (nothing is fitted): the product has no column.
            return;
        }
        run(&self.code, slots, scratch);
        let k = m.len() / width;
        out[..self.values.len() * width].fill(0.0);
        for &(row, column, operand) in &self.entries {
            let value = operand.fetch(slots, scratch);
            let target = &mut out[row * width..(row + 1) * width];
            if column < k {
                for (o, &x) in target
                    .iter_mut()
                    .zip(&m[column * width..(column + 1) * width])
                {
                    *o += value * x;
                }
            } else {
                target[column - k] += value;
            }
        }
    }

    /// Evaluates on `slots`: the values into `values` (length [`JacobianProgram::rows`]) and
    /// the Jacobian into `jacobian` (`rows x columns`, row-major; structural zeros written
    /// as zero).
    ///
    /// Panics if an output is shorter than that or `slots` than the layout.
    pub fn eval(
        &self,
        slots: &[f64],
        scratch: &mut Vec<f64>,
        values: &mut [f64],
        jacobian: &mut [f64],
    ) {
        run(&self.code, slots, scratch);
        for (value, operand) in values.iter_mut().zip(&self.values) {
            *value = operand.fetch(slots, scratch);
        }
        jacobian[..self.values.len() * self.columns].fill(0.0);
        for &(row, column, operand) in &self.entries {
            jacobian[row * self.columns + column] = operand.fetch(slots, scratch);
        }
    }
}

/// Forward differentiation of a builder's code.
struct Differentiator<'a, 'w> {
    builder: Builder<'a>,
    wrt: &'w [usize],
    /// Partials of every register of the original code.
    partials: Vec<Partials>,
}

impl Differentiator<'_, '_> {
    /// Differentiates every instruction of the original code, in order.
    fn sweep(&mut self) {
        let original = self.builder.code.len();
        for register in 0..original {
            let instr = self.builder.code[register];
            let partials = self.instruction(instr, Operand::Register(register));
            self.partials.push(partials);
        }
    }

    /// The partials of an operand.
    fn partials_of(&self, operand: Operand) -> Partials {
        match operand {
            Operand::Value(_) => Vec::new(),
            Operand::Slot(slot) => (self.wrt.iter().position(|&w| w == slot))
                .map(|column| vec![(column, Operand::Value(1.0))])
                .unwrap_or_default(),
            Operand::Register(register) => self.partials[register].clone(),
        }
    }

    /// The partials of `instr`, whose value is in `result`.
    fn instruction(&mut self, instr: Instr, result: Operand) -> Partials {
        match instr {
            Instr::Neg(a) => self.chain(&[(a, Operand::Value(-1.0))]),
            Instr::Square(a) => {
                let twice = self.mul(Operand::Value(2.0), a);
                self.chain(&[(a, twice)])
            }
            Instr::Binary(op, a, b) => self.binary(op, a, b, result),
            Instr::Call(func, a, b) => self.call(func, a, b, result),
            Instr::Exceeds(..) => Vec::new(),
            // A product (its strong zero aside): only derivative code holds it.
            Instr::Chain(a, b) => self.chain(&[(a, b), (b, a)]),
        }
    }

    fn binary(&mut self, op: BinOp, a: Operand, b: Operand, result: Operand) -> Partials {
        let one = Operand::Value(1.0);
        match op {
            BinOp::Add => self.chain(&[(a, one), (b, one)]),
            BinOp::Sub => self.chain(&[(a, one), (b, Operand::Value(-1.0))]),
            BinOp::Mul => self.chain(&[(a, b), (b, a)]),
            BinOp::Div => {
                let inverse = self.div(one, b);
                let ratio = self.mul(result, inverse);
                let slope = self.neg(ratio);
                self.chain(&[(a, inverse), (b, slope)])
            }
            BinOp::Pow => self.power(a, b, result),
        }
    }

    /// `d(a^b) = b a^(b-1) da + a^b ln(a) db`, each term only where its operand varies.
    fn power(&mut self, a: Operand, b: Operand, result: Operand) -> Partials {
        let mut terms = Vec::new();
        if !self.partials_of(a).is_empty() {
            let exponent = self.sub(b, Operand::Value(1.0));
            let lowered = self.builder.emit(Instr::Binary(BinOp::Pow, a, exponent));
            terms.push((a, self.mul(b, lowered)));
        }
        // A literal zero base gives `0^b`, constant where it is defined (`ln 0` would
        // make the term NaN). A negative base takes `ln |a|`: `a^b` is real there only
        // where `b` is held at an integer, so the term is `0 * finite` where `b` does not
        // move (`(-2)^max(2, u)` below `u = 2`), not `0 * NaN`.
        // A base that evaluates to zero (`(2 - 2) * u`) takes `ln` of the smallest normal
        // number, so the term is `0^b * finite = 0`, not `0 * -inf`.
        if !self.partials_of(b).is_empty() && !is(a, 0.0) {
            let size = self
                .builder
                .emit(Instr::Call(Func::Abs, a, Operand::Value(0.0)));
            let floored = (self.builder).emit(Instr::Call(
                Func::Max,
                size,
                Operand::Value(f64::MIN_POSITIVE),
            ));
            let log = self
                .builder
                .emit(Instr::Call(Func::Log, floored, Operand::Value(0.0)));
            terms.push((b, self.mul(result, log)));
        }
        self.chain(&terms)
    }

    fn call(&mut self, func: Func, a: Operand, b: Operand, result: Operand) -> Partials {
        let one = Operand::Value(1.0);
        let slope = match func {
            Func::Exp => result,
            Func::Log => self.div(one, a),
            Func::Sqrt => self.div(Operand::Value(0.5), result),
            Func::Abs => {
                let up = self.builder.emit(Instr::Exceeds(a, Operand::Value(0.0)));
                let down = self.builder.emit(Instr::Exceeds(Operand::Value(0.0), a));
                self.sub(up, down)
            }
            Func::Tanh => {
                let square = self.mul(result, result);
                self.sub(one, square)
            }
            Func::Sigmoid => {
                let complement = self.sub(one, result);
                self.mul(result, complement)
            }
            Func::Softplus => self
                .builder
                .emit(Instr::Call(Func::Sigmoid, a, Operand::Value(0.0))),
            Func::Min | Func::Max => {
                // `min` follows `b` unless `a <= b`, `max` unless `a >= b` (as `f64::min`
                // and `f64::max`, which also take `b` where `a` is NaN).
                let (first, second) = if func == Func::Min { (a, b) } else { (b, a) };
                let follows_b = self.builder.emit(Instr::Exceeds(first, second));
                let follows_a = self.sub(one, follows_b);
                return self.chain(&[(a, follows_a), (b, follows_b)]);
            }
            Func::Pow => return self.power(a, b, result),
        };
        self.chain(&[(a, slope)])
    }

    /// `sum_k coefficient_k * partials(operand_k)`, merged by column.
    fn chain(&mut self, terms: &[(Operand, Operand)]) -> Partials {
        let mut merged: Partials = Vec::new();
        for &(operand, coefficient) in terms {
            for (column, partial) in self.partials_of(operand) {
                let term = self.scale(coefficient, partial);
                match merged.iter_mut().find(|(c, _)| *c == column) {
                    Some((_, sum)) => *sum = self.add(*sum, term),
                    None => merged.push((column, term)),
                }
            }
        }
        merged.retain(|(_, value)| *value != Operand::Value(0.0));
        merged.sort_by_key(|(column, _)| *column);
        merged
    }

    fn add(&mut self, a: Operand, b: Operand) -> Operand {
        if is(a, 0.0) {
            b
        } else if is(b, 0.0) {
            a
        } else {
            self.builder.emit(Instr::Binary(BinOp::Add, a, b))
        }
    }

    fn sub(&mut self, a: Operand, b: Operand) -> Operand {
        if is(b, 0.0) {
            a
        } else if is(a, 0.0) {
            self.neg(b)
        } else {
            self.builder.emit(Instr::Binary(BinOp::Sub, a, b))
        }
    }

    fn mul(&mut self, a: Operand, b: Operand) -> Operand {
        if is(a, 0.0) || is(b, 0.0) {
            Operand::Value(0.0)
        } else if is(a, 1.0) {
            b
        } else if is(b, 1.0) {
            a
        } else if is(a, -1.0) {
            self.neg(b)
        } else if is(b, -1.0) {
            self.neg(a)
        } else {
            self.builder.emit(Instr::Binary(BinOp::Mul, a, b))
        }
    }

    /// `slope * partial` of the chain rule, `0` where `partial` is `0` at run time
    /// ([`Instr::Chain`]); immediates fold as in [`Self::mul`].
    fn scale(&mut self, slope: Operand, partial: Operand) -> Operand {
        let folds = |o: Operand| matches!(o, Operand::Value(_));
        if folds(slope) || folds(partial) {
            self.mul(slope, partial)
        } else {
            self.builder.emit(Instr::Chain(slope, partial))
        }
    }

    fn div(&mut self, a: Operand, b: Operand) -> Operand {
        if is(a, 0.0) {
            Operand::Value(0.0)
        } else if is(b, 1.0) {
            a
        } else {
            self.builder.emit(Instr::Binary(BinOp::Div, a, b))
        }
    }

    fn neg(&mut self, a: Operand) -> Operand {
        self.builder.emit(Instr::Neg(a))
    }
}

/// Whether `operand` is the immediate `value`.
fn is(operand: Operand, value: f64) -> bool {
    matches!(operand, Operand::Value(v) if v == value)
}
