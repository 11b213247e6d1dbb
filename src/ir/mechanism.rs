//! The mechanism inside a grey box: the model with every closure output replaced by what
//! it is before the network corrects it (its prior, or zero without one). `gbc train`
//! fits this model's params with the one fitter of mechanistic params and starts the grey
//! box from them (`docs/training.md`, "A grey box starts from its mechanism").

use super::model::{Expr, Model, Var};

impl Model {
    /// This model without closures: each closure output becomes its prior (`*=` and `+=`
    /// alike: the network's correction at zero) or `0` without one, in every balance, `let`
    /// and `output`. Effects are dropped (they may name closure outputs).
    pub fn mechanism(&self) -> Model {
        let stand_in = |closure: usize, output: usize| -> Expr {
            (self.closures.get(closure))
                .and_then(|c| c.outputs.get(output))
                .and_then(|o| o.prior.as_ref())
                .map_or(Expr::Num(0.0), |prior| prior.expr.clone())
        };
        self.with_closure_outputs_as(&stand_in)
    }

    /// This model without closures, each closure output replaced by `stand_in(closure,
    /// output)` (an expression free of closure outputs) in every balance, `let` and
    /// `output`; effects dropped. [`Model::mechanism`] is the stand-in of priors or zero.
    pub fn with_closure_outputs_as(&self, stand_in: &dyn Fn(usize, usize) -> Expr) -> Model {
        let replace = |expr: &Expr| without_closures(expr, stand_in);
        let mut mechanism = self.clone();
        mechanism.closures.clear();
        mechanism.effects.clear();
        for balance in &mut mechanism.balances {
            balance.expr = replace(&balance.expr);
        }
        for definition in mechanism.lets.iter_mut().chain(&mut mechanism.outputs) {
            definition.expr = replace(&definition.expr);
        }
        mechanism
    }
}

/// `expr` with every closure output replaced by `stand_in(closure, output)` (itself free of
/// closure outputs: a prior reads states, inputs, consts and params).
fn without_closures(expr: &Expr, stand_in: &dyn Fn(usize, usize) -> Expr) -> Expr {
    let go = |e: &Expr| Box::new(without_closures(e, stand_in));
    match expr {
        Expr::Var(Var::ClosureOutput { closure, output }) => stand_in(*closure, *output),
        Expr::Num(_) | Expr::Var(_) => expr.clone(),
        Expr::Neg(inner) => Expr::Neg(go(inner)),
        Expr::Bin(op, a, b) => Expr::Bin(*op, go(a), go(b)),
        Expr::Call(func, args) => Expr::Call(
            *func,
            args.iter().map(|a| without_closures(a, stand_in)).collect(),
        ),
    }
}

#[cfg(test)]
mod tests {
    fn compile(source: &str) -> crate::ir::Model {
        crate::driver::compile("m.gbm", source, &[]).unwrap().model
    }

    #[test]
    fn closure_outputs_become_their_priors_or_zero() {
        let grey = compile(
            "model m\nstate x = 1\nstate y = 1\nparam k = 0.5\n\
             closure c {\n  outputs r ~ 1, g ~ 1\n  observe x\n  network hidden [4] tanh\n  prior g *= k * x\n}\n\
             der x = -r * x\nder y = g - y\n",
        );
        let plain = compile(
            "model m\nstate x = 1\nstate y = 1\nparam k = 0.5\nder x = -0 * x\nder y = k * x - y\n",
        );
        let mechanism = grey.mechanism();
        assert!(mechanism.closures.is_empty());
        // The same balances as the hand-written mechanism: `r` (no prior) is 0, `g` its prior.
        assert_eq!(mechanism.balances, plain.balances);
        assert!(!format!("{:?}", mechanism).contains("ClosureOutput"));
    }
}
