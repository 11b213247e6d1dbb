//! `nonnegative` states: the sign analysis that proves a learned term cannot drive a state
//! below zero (`docs/language.md`, "Non-negative states").
//!
//! A state `X` stays non-negative when, wherever `X = 0`, its balance is not negative. The
//! check asks this of every additive term of `der X` that involves a closure output: the
//! term's value at `X = 0` must be provably `>= 0` (or exactly 0) for *any* value of the
//! networks' raw outputs, every other quantity ranging over what its declaration allows.
//! Terms without a closure output are the modeller's own mechanism and are not judged.
//!
//! The analysis is structural: each expression gets the set of signs its value can take
//! ([`Signs`]: negative, zero, positive, and "may not be finite"), computed bottom-up with
//! `X` zero, a `nonnegative` state `>= 0`, inputs, params and closure outputs within their
//! declared bounds or constraints, consts and numbers by value. So a product vanishes with
//! a factor that vanishes, `X / (K + X)` vanishes for a positive `K`, `X^c` for `c > 0`, a
//! closure output under a `*=` prior vanishes where its prior does, and a `positive` output
//! without a prior is `> 0` but does not vanish. Values are taken to be finite except where
//! the analysis itself finds a division by something that may be zero, a logarithm of
//! something that may be zero or negative, and the like: a zero factor does not make such
//! a term vanish.

use super::model::{ClosureOutput, Constraint, Expr, Model, PriorKind, Var};
use crate::ast::BinOp;
use crate::vocabulary::Func;

/// The signs a value can take: a set of negative, zero, positive, plus whether it may fail
/// to be finite (infinite or NaN).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Signs(u8);

const NEG: u8 = 1;
const ZERO: u8 = 2;
const POS: u8 = 4;
const ANY: u8 = NEG | ZERO | POS;
const NONFINITE: u8 = 8;

impl Signs {
    /// Exactly zero.
    pub const ZERO: Signs = Signs(ZERO);
    /// Strictly positive.
    pub const POSITIVE: Signs = Signs(POS);
    /// Zero or positive.
    pub const NONNEGATIVE: Signs = Signs(ZERO | POS);
    /// Any finite value.
    pub const ANY: Signs = Signs(ANY);
    /// Nothing known, not even finiteness.
    pub const UNKNOWN: Signs = Signs(ANY | NONFINITE);

    /// Whether the value is provably finite and `>= 0`.
    pub fn is_nonnegative(self) -> bool {
        self.0 & (NEG | NONFINITE) == 0
    }

    /// Whether the value is provably exactly zero.
    pub fn is_zero(self) -> bool {
        self.0 == ZERO
    }

    fn has(self, bits: u8) -> bool {
        self.0 & bits != 0
    }

    /// Whether the value is provably finite.
    pub fn is_finite(self) -> bool {
        !self.has(NONFINITE)
    }

    /// The signs of a number.
    pub fn of(value: f64) -> Signs {
        if !value.is_finite() {
            Signs::UNKNOWN
        } else if value > 0.0 {
            Signs(POS)
        } else if value < 0.0 {
            Signs(NEG)
        } else {
            Signs(ZERO)
        }
    }

    /// The signs of a value in the closed interval `[lo, hi]`.
    pub fn within(lo: f64, hi: f64) -> Signs {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return Signs::UNKNOWN;
        }
        let mut bits = 0;
        if lo < 0.0 {
            bits |= NEG;
        }
        if lo <= 0.0 && hi >= 0.0 {
            bits |= ZERO;
        }
        if hi > 0.0 {
            bits |= POS;
        }
        Signs(bits)
    }

    /// `-a`.
    pub fn negate(self) -> Signs {
        let swapped = (self.0 & ZERO) | ((self.0 & NEG) << 2) | ((self.0 & POS) >> 2);
        Signs(swapped | (self.0 & NONFINITE))
    }

    /// Every sign `f(a, b)` can take for `a` in `self` and `b` in `other`, with `f` given on
    /// single signs; not finite when either operand may not be.
    fn pairwise(self, other: Signs, f: fn(u8, u8) -> u8) -> Signs {
        let mut bits = 0;
        for a in [NEG, ZERO, POS].into_iter().filter(|&a| self.has(a)) {
            for b in [NEG, ZERO, POS].into_iter().filter(|&b| other.has(b)) {
                bits |= f(a, b);
            }
        }
        if !(self.is_finite() && other.is_finite()) {
            return Signs::UNKNOWN;
        }
        Signs(bits)
    }

    /// `a + b`.
    pub fn plus(self, other: Signs) -> Signs {
        self.pairwise(other, |a, b| match (a, b) {
            (ZERO, x) | (x, ZERO) => x,
            (x, y) if x == y => x,
            _ => ANY,
        })
    }

    /// `a * b` (of finite values: a zero factor gives zero).
    pub fn times(self, other: Signs) -> Signs {
        self.pairwise(other, |a, b| match (a, b) {
            (ZERO, _) | (_, ZERO) => ZERO,
            (x, y) if x == y => POS,
            _ => NEG,
        })
    }

    /// `a / b`: not finite where `b` may be zero.
    pub fn over(self, other: Signs) -> Signs {
        if other.has(ZERO) {
            return Signs::UNKNOWN;
        }
        self.times(other)
    }

    /// `min(a, b)` (`max` is `-min(-a, -b)`): the sign of a minimum is the smaller sign.
    pub fn min(self, other: Signs) -> Signs {
        self.pairwise(other, |a, b| a.min(b))
    }

    /// `max(a, b)`.
    pub fn max(self, other: Signs) -> Signs {
        self.negate().min(other.negate()).negate()
    }

    /// `a ^ b`, with `exponent` the value of `b` where it is a constant.
    pub fn pow(self, other: Signs, exponent: Option<f64>) -> Signs {
        if !(self.is_finite() && other.is_finite()) {
            return Signs::UNKNOWN;
        }
        if let Some(c) = exponent {
            return self.pow_constant(c);
        }
        if !self.has(NEG | ZERO) {
            // A positive base to any finite power is positive (or underflows to zero).
            return Signs::NONNEGATIVE;
        }
        if !self.has(NEG) && !other.has(NEG | ZERO) {
            // `0^b = 0` for `b > 0`.
            return Signs(self.0 & (ZERO | POS));
        }
        Signs::UNKNOWN
    }

    fn pow_constant(self, c: f64) -> Signs {
        if c == 0.0 {
            return Signs::POSITIVE;
        }
        if c < 0.0 && self.has(ZERO) {
            return Signs::UNKNOWN;
        }
        let integer = c == c.trunc() && c.abs() < 2f64.powi(53);
        if self.has(NEG) && !integer {
            return Signs::UNKNOWN;
        }
        let even = integer && (c / 2.0) == (c / 2.0).trunc();
        let mut bits = self.0 & (ZERO | POS);
        if self.has(NEG) {
            bits |= if even { POS } else { NEG };
        }
        Signs(bits)
    }

    /// `f(a)` for a function of one argument.
    fn apply(self, func: Func) -> Signs {
        if !self.is_finite() {
            return Signs::UNKNOWN;
        }
        match func {
            // Positive, but may underflow to zero.
            Func::Exp | Func::Sigmoid | Func::Softplus => Signs::NONNEGATIVE,
            Func::Tanh => self,
            Func::Abs => Signs((self.0 & ZERO) | if self.has(NEG | POS) { POS } else { 0 }),
            Func::Sqrt if !self.has(NEG) => self,
            Func::Log if !self.has(NEG | ZERO) => Signs::ANY,
            _ => Signs::UNKNOWN,
        }
    }
}

/// The value of `expr` where it is a constant (numbers and consts), for exponents.
fn constant(model: &Model, expr: &Expr) -> Option<f64> {
    match expr {
        Expr::Num(value) => Some(*value),
        Expr::Var(Var::Const(i)) => model.consts.get(*i).map(|c| c.value),
        Expr::Neg(inner) => constant(model, inner).map(|v| -v),
        Expr::Bin(op, a, b) => Some(op.apply(constant(model, a)?, constant(model, b)?)),
        _ => None,
    }
}

/// The signs of `expr` where the state `zero` is 0 (module documentation); with `None`,
/// every state in its declared range.
pub fn signs(model: &Model, zero: Option<Var>, expr: &Expr) -> Signs {
    Analysis { model, zero }.signs(expr)
}

/// The closure outputs of `expr` that keep it from being proven: those that do not
/// provably vanish where `zero` is 0 (with `None`: that are not provably `>= 0`), in order
/// of first use.
pub fn culprits(model: &Model, zero: Option<Var>, expr: &Expr) -> Vec<Var> {
    let analysis = Analysis { model, zero };
    let mut found = Vec::new();
    analysis.collect(expr, &mut found);
    found
}

struct Analysis<'a> {
    model: &'a Model,
    zero: Option<Var>,
}

impl Analysis<'_> {
    fn signs(&self, expr: &Expr) -> Signs {
        if let Some(value) = constant(self.model, expr) {
            return Signs::of(value);
        }
        match expr {
            Expr::Num(value) => Signs::of(*value),
            Expr::Var(var) => self.var(*var),
            Expr::Neg(inner) => self.signs(inner).negate(),
            Expr::Bin(op, a, b) => {
                let (left, right) = (self.signs(a), self.signs(b));
                match op {
                    BinOp::Add => left.plus(right),
                    BinOp::Sub => left.plus(right.negate()),
                    BinOp::Mul => left.times(right),
                    BinOp::Div => left.over(right),
                    BinOp::Pow => left.pow(right, constant(self.model, b)),
                }
            }
            Expr::Call(func, args) => self.call(*func, args),
        }
    }

    fn call(&self, func: Func, args: &[Expr]) -> Signs {
        let signs: Vec<Signs> = args.iter().map(|a| self.signs(a)).collect();
        match (func, signs.as_slice()) {
            (Func::Min, [a, b]) => a.min(*b),
            (Func::Max, [a, b]) => a.max(*b),
            (Func::Pow, [a, b]) => a.pow(*b, constant(self.model, &args[1])),
            (_, [a]) => a.apply(func),
            _ => Signs::UNKNOWN,
        }
    }

    fn var(&self, var: Var) -> Signs {
        let model = self.model;
        let declared = |states: &[super::State], i: usize| {
            let nonnegative = states.get(i).is_some_and(|s| s.nonnegative);
            if nonnegative {
                Signs::NONNEGATIVE
            } else {
                Signs::ANY
            }
        };
        match var {
            _ if Some(var) == self.zero => Signs::ZERO,
            Var::State(i) => declared(&model.states, i),
            Var::Hidden(i) => declared(&model.hidden, i),
            Var::Input(i) => match model.inputs.get(i).and_then(|u| u.bounds) {
                Some((lo, hi)) => Signs::within(lo, hi),
                None => Signs::ANY,
            },
            Var::Const(i) => model
                .consts
                .get(i)
                .map_or(Signs::UNKNOWN, |c| Signs::of(c.value)),
            Var::Param(i) => model
                .params
                .get(i)
                .map_or(Signs::UNKNOWN, |p| constrained(p.constraint, Signs::ANY)),
            Var::ClosureOutput { closure, output } => {
                let spec = model
                    .closures
                    .get(closure)
                    .and_then(|c| c.outputs.get(output));
                spec.map_or(Signs::UNKNOWN, |spec| self.output(spec))
            }
        }
    }

    /// A closure output for any raw network output `n` (`src/engine/program/outputs.rs`).
    fn output(&self, spec: &ClosureOutput) -> Signs {
        // A magnitude left out is chosen from the data, and is positive.
        let scale = Signs::of(spec.scale.unwrap_or(1.0));
        match (&spec.prior, spec.constraint) {
            (_, Constraint::Bounds(lo, hi)) => Signs::within(lo, hi),
            // `s softplus(n / s)`.
            (None, Constraint::Positive) if scale == Signs::POSITIVE => Signs::POSITIVE,
            (None, _) => Signs::ANY,
            (Some(prior), constraint) => {
                let p = self.signs(&prior.expr);
                match (prior.kind, constraint) {
                    // `max(p, 0) g(n)` with `g > 0`.
                    (PriorKind::Mul, Constraint::Positive) => p.max(Signs::ZERO),
                    // `p (1 + n)`.
                    (PriorKind::Mul, _) => p.times(Signs::ANY),
                    // `max(p + s n, 0)`.
                    (PriorKind::Add, Constraint::Positive) if p.is_finite() => Signs::NONNEGATIVE,
                    (PriorKind::Add, _) => p.plus(Signs::ANY),
                }
            }
        }
    }

    fn collect(&self, expr: &Expr, found: &mut Vec<Var>) {
        match expr {
            Expr::Var(var @ Var::ClosureOutput { .. }) => {
                let signs = self.var(*var);
                let proven = match self.zero {
                    Some(_) => signs.is_zero(),
                    None => signs.is_nonnegative(),
                };
                if !proven && !found.contains(var) {
                    found.push(*var);
                }
            }
            Expr::Num(_) | Expr::Var(_) => {}
            Expr::Neg(inner) => self.collect(inner, found),
            Expr::Bin(_, a, b) => {
                self.collect(a, found);
                self.collect(b, found);
            }
            Expr::Call(_, args) => args.iter().for_each(|a| self.collect(a, found)),
        }
    }
}

/// The signs of a trainable value under `constraint` (`free` where it has none).
fn constrained(constraint: Constraint, free: Signs) -> Signs {
    match constraint {
        Constraint::Free => free,
        Constraint::Positive => Signs::POSITIVE,
        Constraint::Bounds(lo, hi) => Signs::within(lo, hi),
    }
}

#[cfg(test)]
mod tests;
