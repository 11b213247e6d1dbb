//! A held constant made a param: what the diagnosis fits when it asks whether a constant the
//! modeller fixed (a literature value, a guessed inoculum) is what the data say.

use super::model::{Constraint, Expr, Model, Param, Var};

/// `model` with the const `name` fitted as a param that starts at the const's value
/// (positive when the value is, else free); every reference to the const (balances, `let`s,
/// `output`s, starts, priors) reads the param instead. `None` when the model has no such
/// const, its value is zero or not finite (nothing to scale), or nothing refers to it.
pub fn release(model: &Model, name: &str) -> Option<Model> {
    let index = model.consts.iter().position(|c| c.name == name)?;
    let value = model.consts[index].value;
    if value == 0.0 || !value.is_finite() {
        return None;
    }
    let mut released = model.clone();
    let param = Var::Param(released.params.len());
    let mut references = 0;
    each_expr(&mut released, &mut |expr| {
        references += replace(expr, Var::Const(index), param);
    });
    if references == 0 {
        return None;
    }
    released.params.push(Param {
        name: name.to_string(),
        init: value,
        constraint: if value > 0.0 {
            Constraint::Positive
        } else {
            Constraint::Free
        },
    });
    Some(released)
}

/// The consts of `model` that [`release`] can make params, in declaration order.
pub fn releasable(model: &Model) -> Vec<String> {
    (model.consts.iter())
        .filter(|c| release(model, &c.name).is_some())
        .map(|c| c.name.clone())
        .collect()
}

/// Calls `visit` on every expression of `model` that a free run evaluates.
fn each_expr(model: &mut Model, visit: &mut dyn FnMut(&mut Expr)) {
    model.balances.iter_mut().for_each(|b| visit(&mut b.expr));
    model.lets.iter_mut().for_each(|d| visit(&mut d.expr));
    model.outputs.iter_mut().for_each(|d| visit(&mut d.expr));
    let states = model.states.iter_mut().chain(model.hidden.iter_mut());
    states.filter_map(|s| s.init.as_mut()).for_each(&mut *visit);
    let outputs = model.closures.iter_mut().flat_map(|c| c.outputs.iter_mut());
    (outputs.filter_map(|o| o.prior.as_mut())).for_each(|p| visit(&mut p.expr));
}

/// Replaces `from` by `to` in `expr`; returns how many it replaced.
fn replace(expr: &mut Expr, from: Var, to: Var) -> usize {
    match expr {
        Expr::Num(_) => 0,
        Expr::Var(var) if *var == from => {
            *var = to;
            1
        }
        Expr::Var(_) => 0,
        Expr::Neg(inner) => replace(inner, from, to),
        Expr::Bin(_, left, right) => replace(left, from, to) + replace(right, from, to),
        Expr::Call(_, args) => args.iter_mut().map(|a| replace(a, from, to)).sum(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::interpret;

    fn model(source: &str) -> Model {
        crate::driver::compile("m.gbm", source, &[]).unwrap().model
    }

    const SOURCE: &str = "model m\nstate X = X0\nstate S = 10\nconst X0 = 0.5\n\
        const mu = 0.3\nconst unused = 2\nconst zero = 0\nparam K = 1 positive\n\
        let g = mu * S / (K + S)\nder X = g * X\nder S = -g * X / 0.5 + zero\n";

    #[test]
    fn a_released_const_is_a_param_every_reference_reads() {
        let base = model(SOURCE);
        let released = release(&base, "mu").expect("mu is used");
        assert_eq!(released.params.len(), base.params.len() + 1);
        let param = released.params.last().unwrap();
        assert_eq!((param.name.as_str(), param.init), ("mu", 0.3));
        assert_eq!(param.constraint, Constraint::Positive);
        // Every balance evaluates alike at the param's start, and scales with it after.
        let index = Var::Param(released.params.len() - 1);
        for (before, after) in base.balances.iter().zip(&released.balances) {
            let value = |expr: &Expr, mu: f64| {
                interpret(expr, &|var| match var {
                    Var::State(0) => 0.2,
                    Var::State(1) => 4.0,
                    Var::Param(0) => 1.0,
                    v if v == index => mu,
                    Var::Const(i) => base.consts[i].value,
                    _ => f64::NAN,
                })
            };
            assert_eq!(value(&before.expr, 0.0), value(&after.expr, 0.3));
            let doubled = value(&after.expr, 0.6) - value(&before.expr, 0.0);
            assert!((doubled - value(&before.expr, 0.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_start_const_is_released_and_unused_or_zero_consts_are_not() {
        let base = model(SOURCE);
        let released = release(&base, "X0").expect("X0 sets a start");
        let start = released.states[0].init.as_ref().expect("X has a start");
        assert_eq!(*start, Expr::Var(Var::Param(1)));
        assert!(release(&base, "unused").is_none());
        assert!(release(&base, "zero").is_none());
        assert!(release(&base, "nothing").is_none());
        assert_eq!(releasable(&base), ["X0", "mu"]);
    }
}
