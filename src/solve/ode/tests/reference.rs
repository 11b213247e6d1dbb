//! An independent reference solution: classical RK4 with a fixed step, evaluated through
//! the tree-walking interpreter, improved by Richardson extrapolation.

use crate::eval::interpret;
use crate::ir::{Model, Var};
use crate::signal::Signal;
use crate::solve::ode::tableau::RK4;

/// The balances of `model` at state `y` with inputs `u`, in state order.
fn rhs(model: &Model, u: &[f64], y: &[f64]) -> Vec<f64> {
    let measured = model.states.len();
    let value_of = |var: Var| match var {
        Var::Input(i) => u[i],
        Var::State(i) => y[i],
        Var::Hidden(i) => y[measured + i],
        Var::Const(i) => model.consts[i].value,
        Var::Param(i) => model.params[i].init,
        Var::ClosureOutput { .. } => f64::NAN,
    };
    let mut dydt = vec![f64::NAN; y.len()];
    for balance in &model.balances {
        let index = match balance.state {
            Var::State(i) => i,
            Var::Hidden(i) => measured + i,
            _ => continue,
        };
        dydt[index] = interpret(&balance.expr, &value_of);
    }
    dydt
}

/// RK4 with step `h` from `(0, y0)`; returns the state at each time in `samples`.
///
/// Every sample and every input switch must be a multiple of `h`, so inputs are constant
/// over each step.
pub fn rk4(
    model: &Model,
    signals: &[Signal],
    y0: &[f64],
    samples: &[f64],
    h: f64,
) -> Vec<Vec<f64>> {
    let mut y = y0.to_vec();
    let mut out = Vec::with_capacity(samples.len());
    let mut step = 0usize;
    for &sample in samples {
        let target = (sample / h).round() as usize;
        while step < target {
            let t = step as f64 * h;
            let u: Vec<f64> = signals.iter().map(|s| s.value_at(t)).collect();
            y = RK4.step(&mut |_, state| rhs(model, &u, state), t, &y, h);
            step += 1;
        }
        out.push(y.clone());
    }
    out
}

/// `(16 y_{h/2} - y_h) / 15`: RK4's leading error term cancelled.
pub fn richardson(
    model: &Model,
    signals: &[Signal],
    y0: &[f64],
    samples: &[f64],
    h: f64,
) -> Vec<Vec<f64>> {
    let coarse = rk4(model, signals, y0, samples, h);
    let fine = rk4(model, signals, y0, samples, h / 2.0);
    fine.iter()
        .zip(&coarse)
        .map(|(f, c)| {
            f.iter()
                .zip(c)
                .map(|(f, c)| (16.0 * f - c) / 15.0)
                .collect()
        })
        .collect()
}
