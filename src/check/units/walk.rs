//! Units through expressions: `push` carries an expected unit down into an expression and
//! infers the units of undeclared names it reaches; `eval` computes an expression's unit
//! bottom-up and, when asked, reports every place inside it where units disagree.

use super::Checker;
use crate::ast::{BinOp, Expr, SExpr};
use crate::check::Scope;
use crate::units::Unit;
use crate::vocabulary::Func;

/// The largest exponent magnitude a unit is raised to (beyond it the unit is unknown).
const MAX_POWER: f64 = 64.0;

impl Checker<'_> {
    /// Pushes `expected` into `expr`, inferring the units of the names it fixes.
    pub(super) fn push(&mut self, expr: &SExpr, scope: Scope, expected: Option<&Unit>) {
        match &expr.node {
            Expr::Num(_) => {}
            Expr::Name(name) => {
                if let Some(unit) = expected {
                    let key = self.key(scope, name);
                    self.infer(key, unit.clone(), expr.span);
                }
            }
            Expr::Neg(inner) => self.push(inner, scope, expected),
            Expr::Binary(BinOp::Add | BinOp::Sub, a, b) => self.push_same(&[a, b], scope, expected),
            Expr::Binary(BinOp::Mul, a, b) => {
                let (ua, ub) = (self.eval(a, scope, false), self.eval(b, scope, false));
                let for_a = expected.zip(ub.as_ref()).map(|(e, u)| e.div(u));
                let for_b = expected.zip(ua.as_ref()).map(|(e, u)| e.div(u));
                self.push(a, scope, for_a.as_ref());
                self.push(b, scope, for_b.as_ref());
            }
            Expr::Binary(BinOp::Div, a, b) => {
                let (ua, ub) = (self.eval(a, scope, false), self.eval(b, scope, false));
                let for_a = expected.zip(ub.as_ref()).map(|(e, u)| e.mul(u));
                let for_b = expected.zip(ua.as_ref()).map(|(e, u)| u.div(e));
                self.push(a, scope, for_a.as_ref());
                self.push(b, scope, for_b.as_ref());
            }
            Expr::Binary(BinOp::Pow, base, exponent) => {
                self.push_power(base, exponent, scope, expected)
            }
            Expr::Call(function, args) => match Func::from_name(&function.node) {
                Some(Func::Min | Func::Max) => {
                    let args: Vec<&SExpr> = args.iter().collect();
                    self.push_same(&args, scope, expected)
                }
                Some(Func::Abs) => args.iter().for_each(|a| self.push(a, scope, expected)),
                Some(Func::Sqrt) => {
                    let squared = expected.map(|e| e.powi(2));
                    args.iter()
                        .for_each(|a| self.push(a, scope, squared.as_ref()));
                }
                Some(Func::Pow) => {
                    if let [base, exponent] = args.as_slice() {
                        self.push_power(base, exponent, scope, expected);
                    }
                }
                _ => {
                    let one = Unit::dimensionless();
                    args.iter().for_each(|a| self.push(a, scope, Some(&one)));
                }
            },
        }
    }

    /// Operands that must share one unit: the expected one, else the first known.
    fn push_same(&mut self, operands: &[&SExpr], scope: Scope, expected: Option<&Unit>) {
        let known = match expected {
            Some(unit) => Some(unit.clone()),
            None => operands.iter().find_map(|o| self.eval(o, scope, false)),
        };
        for operand in operands {
            self.push(operand, scope, known.as_ref());
        }
    }

    fn push_power(
        &mut self,
        base: &SExpr,
        exponent: &SExpr,
        scope: Scope,
        expected: Option<&Unit>,
    ) {
        self.push(exponent, scope, Some(&Unit::dimensionless()));
        let root = match (expected, self.exponent(exponent, scope)) {
            (Some(unit), Some(n)) if n != 0.0 => unit.powf(1.0 / n),
            _ => None,
        };
        self.push(base, scope, root.as_ref());
    }

    /// The value of a constant exponent.
    fn exponent(&mut self, exponent: &SExpr, scope: Scope) -> Option<f64> {
        self.evaluator
            .eval(exponent, scope)
            .filter(|n| n.is_finite() && n.abs() <= MAX_POWER)
    }

    /// The unit of `expr`, or `None` when it is not determined. With `report`, every
    /// disagreement inside `expr` is reported.
    pub(super) fn eval(&mut self, expr: &SExpr, scope: Scope, report: bool) -> Option<Unit> {
        match &expr.node {
            Expr::Num(_) => None,
            Expr::Name(name) => {
                let key = self.key(scope, name);
                self.unit_of(&key)
            }
            Expr::Neg(inner) => self.eval(inner, scope, report),
            Expr::Binary(op @ (BinOp::Add | BinOp::Sub), a, b) => {
                let context = format!("operands of `{}`", op.symbol());
                self.eval_same(&context, &[a, b], scope, report)
            }
            Expr::Binary(BinOp::Mul, a, b) => {
                let (ua, ub) = (self.eval(a, scope, report), self.eval(b, scope, report));
                Some(ua?.mul(&ub?))
            }
            Expr::Binary(BinOp::Div, a, b) => {
                let (ua, ub) = (self.eval(a, scope, report), self.eval(b, scope, report));
                Some(ua?.div(&ub?))
            }
            Expr::Binary(BinOp::Pow, base, exponent) => {
                self.eval_power(base, exponent, scope, report)
            }
            Expr::Call(function, args) => self.eval_call(&function.node, args, scope, report),
        }
    }

    fn eval_call(
        &mut self,
        name: &str,
        args: &[SExpr],
        scope: Scope,
        report: bool,
    ) -> Option<Unit> {
        match Func::from_name(name)? {
            Func::Min | Func::Max => {
                let operands: Vec<&SExpr> = args.iter().collect();
                self.eval_same(&format!("arguments of `{name}`"), &operands, scope, report)
            }
            Func::Abs => self.eval(args.first()?, scope, report),
            Func::Sqrt => self.eval(args.first()?, scope, report)?.powf(0.5),
            Func::Pow => match args {
                [base, exponent] => self.eval_power(base, exponent, scope, report),
                _ => None,
            },
            Func::Exp | Func::Log | Func::Tanh | Func::Sigmoid | Func::Softplus => {
                for arg in args {
                    let unit = self.eval(arg, scope, report);
                    if let (Some(unit), true) = (unit, report) {
                        self.dimensionless(&format!("the argument of `{name}`"), arg.span, &unit);
                    }
                }
                Some(Unit::dimensionless())
            }
        }
    }

    /// Operands that must share one unit; reports the first that differs from the first
    /// known one.
    fn eval_same(
        &mut self,
        context: &str,
        operands: &[&SExpr],
        scope: Scope,
        report: bool,
    ) -> Option<Unit> {
        let units: Vec<Option<Unit>> = operands
            .iter()
            .map(|o| self.eval(o, scope, report))
            .collect();
        let (first_index, first) = units
            .iter()
            .enumerate()
            .find_map(|(i, u)| Some((i, u.clone()?)))?;
        for (operand, unit) in operands.iter().zip(&units).skip(first_index + 1) {
            let Some(unit) = unit else { continue };
            if !unit.same(&first) {
                if report {
                    let origin = Some(operands[first_index].span);
                    self.mismatch(context, &first, origin, unit, operand.span);
                }
                return None;
            }
        }
        Some(first)
    }

    fn eval_power(
        &mut self,
        base: &SExpr,
        exponent: &SExpr,
        scope: Scope,
        report: bool,
    ) -> Option<Unit> {
        let exponent_unit = self.eval(exponent, scope, report);
        if let (Some(unit), true) = (exponent_unit, report) {
            self.dimensionless("an exponent", exponent.span, &unit);
        }
        let base_unit = self.eval(base, scope, report)?;
        if base_unit.is_one() {
            return Some(base_unit);
        }
        base_unit.powf(self.exponent(exponent, scope)?)
    }
}
