//! Fitting a mechanistic model's params to a record: Levenberg–Marquardt on the z-scored
//! free-run residuals of the training rows, with a forward-difference Jacobian through the
//! simulator, in transformed coordinates so that constraints always hold (`positive`:
//! `p = exp(theta)`; `in [lo, hi]`: `p = lo + (hi - lo) sigmoid(theta)`), from the given
//! start and a few random restarts.

use super::linalg::solve_spd;
use super::record::{Normalisation, Record};
use super::simulate::Simulator;
use crate::eval::sigmoid;
use crate::ir::Constraint;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::ops::Range;

/// Most Levenberg–Marquardt iterations per start.
const MAX_ITERATIONS: usize = 60;
/// Relative cost decrease below which a start has converged.
const CONVERGED: f64 = 1e-7;
/// Forward-difference step in transformed coordinates.
const JACOBIAN_STEP: f64 = 1e-6;
/// Largest change of a transformed coordinate in one iteration.
const MAX_MOVE: f64 = 3.0;
/// Spread of the random restarts in transformed coordinates.
const RESTART_SPREAD: f64 = 0.7;

/// The free-run error of a model on some rows of a record.
#[derive(Debug, Clone)]
pub struct Objective<'a> {
    /// The compiled model.
    pub simulator: &'a Simulator,
    /// The record (the free run starts at its row 0).
    pub record: &'a Record,
    /// Rows whose errors count.
    pub rows: Range<usize>,
    /// The z-scoring.
    pub normalisation: &'a Normalisation,
}

impl Objective<'_> {
    /// Z-scored residuals `(sim - data) / std`, divided by `sqrt(rows * states)` so that
    /// their squares sum to the gap; `None` if the free run fails.
    pub fn residuals(&self, params: &[f64]) -> Option<Vec<f64>> {
        let mut simulator = self.simulator.clone();
        simulator.set_params(params);
        let run = simulator.free_run(self.record, self.rows.end).ok()?;
        let measured = simulator.measured();
        let scale = ((self.rows.len() * measured).max(1) as f64).sqrt();
        let mut residuals = Vec::with_capacity(self.rows.len() * measured);
        for row in self.rows.clone() {
            let state = run.row(row);
            for (k, column) in self.record.states.iter().enumerate() {
                let r = (state[k] - column[row]) / self.normalisation.std[k] / scale;
                residuals.push(r);
            }
        }
        residuals.iter().all(|r| r.is_finite()).then_some(residuals)
    }

    /// The gap (normalised mean squared error) at `params`, infinite if the run fails.
    pub fn gap(&self, params: &[f64]) -> f64 {
        self.residuals(params)
            .map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum())
    }
}

/// The result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// The params (constrained values).
    pub params: Vec<f64>,
    /// The gap on the fitted rows.
    pub gap: f64,
}

/// Fits the params from `start` (constrained values) plus `restarts` random restarts drawn
/// from a generator seeded with `seed`; returns the best.
pub fn fit(
    objective: &Objective,
    constraints: &[Constraint],
    start: &[f64],
    restarts: usize,
    seed: u64,
) -> Fitted {
    let theta0: Vec<f64> = (constraints.iter().zip(start))
        .map(|(c, &p)| to_theta(*c, p))
        .collect();
    if theta0.is_empty() {
        return Fitted {
            params: Vec::new(),
            gap: objective.gap(&[]),
        };
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut starts = vec![theta0.clone()];
    for _ in 0..restarts {
        starts.push(
            theta0
                .iter()
                .map(|&t| {
                    let noise: f64 = StandardNormal.sample(&mut rng);
                    t + RESTART_SPREAD * noise * t.abs().clamp(1.0, 3.0)
                })
                .collect(),
        );
    }
    let residuals = |theta: &[f64]| objective.residuals(&from_thetas(constraints, theta));
    let results: Vec<(Vec<f64>, f64)> = starts
        .par_iter()
        .map(|theta| levenberg_marquardt(&residuals, theta.clone()))
        .collect();
    let (theta, gap) = results
        .into_iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((theta0, f64::INFINITY));
    Fitted {
        params: from_thetas(constraints, &theta),
        gap,
    }
}

fn from_thetas(constraints: &[Constraint], theta: &[f64]) -> Vec<f64> {
    constraints
        .iter()
        .zip(theta)
        .map(|(c, &t)| from_theta(*c, t))
        .collect()
}

/// The transformed coordinate of a constrained value.
pub fn to_theta(constraint: Constraint, value: f64) -> f64 {
    match constraint {
        Constraint::Free => value,
        Constraint::Positive => value.max(f64::MIN_POSITIVE).ln(),
        Constraint::Bounds(lo, hi) => {
            let p = ((value - lo) / (hi - lo)).clamp(1e-9, 1.0 - 1e-9);
            (p / (1.0 - p)).ln()
        }
    }
}

/// The constrained value of a transformed coordinate.
pub fn from_theta(constraint: Constraint, theta: f64) -> f64 {
    match constraint {
        Constraint::Free => theta,
        Constraint::Positive => theta.exp(),
        Constraint::Bounds(lo, hi) => lo + (hi - lo) * sigmoid(theta),
    }
}

/// Minimises `|r(theta)|^2` from `theta`; returns the minimiser and the minimum (infinite
/// when `r` fails at the start).
pub fn levenberg_marquardt(
    residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    mut theta: Vec<f64>,
) -> (Vec<f64>, f64) {
    let Some(mut r) = residuals(&theta) else {
        return (theta, f64::INFINITY);
    };
    let mut cost = sum_squares(&r);
    let mut damping = 1e-3;
    let n = theta.len();
    for _ in 0..MAX_ITERATIONS {
        let jacobian = jacobian(residuals, &theta, &r);
        let (hessian, gradient) = gauss_newton(&jacobian, &r, n);
        let mut improved = None;
        while damping < 1e10 {
            if let Some(candidate) = damped_step(&hessian, &gradient, &theta, damping) {
                if let Some(r_new) = residuals(&candidate) {
                    let cost_new = sum_squares(&r_new);
                    if cost_new < cost {
                        improved = Some((candidate, r_new, cost_new));
                        damping = (damping / 3.0).max(1e-9);
                        break;
                    }
                }
            }
            damping *= 4.0;
        }
        let Some((candidate, r_new, cost_new)) = improved else {
            break;
        };
        let decrease = cost - cost_new;
        (theta, r, cost) = (candidate, r_new, cost_new);
        if decrease <= CONVERGED * cost + 1e-300 {
            break;
        }
    }
    (theta, cost)
}

fn sum_squares(values: &[f64]) -> f64 {
    values.iter().map(|v| v * v).sum()
}

/// Forward-difference Jacobian, one column per coordinate (columns computed in
/// parallel); a column whose run fails tries the backward difference, then is zero.
fn jacobian(
    residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    theta: &[f64],
    r: &[f64],
) -> Vec<Vec<f64>> {
    (0..theta.len())
        .into_par_iter()
        .map(|j| {
            let h = JACOBIAN_STEP * theta[j].abs().max(1.0);
            let shifted = |sign: f64| {
                let mut moved = theta.to_vec();
                moved[j] += sign * h;
                residuals(&moved)
            };
            if let Some(plus) = shifted(1.0) {
                plus.iter().zip(r).map(|(p, r0)| (p - r0) / h).collect()
            } else if let Some(minus) = shifted(-1.0) {
                r.iter().zip(&minus).map(|(r0, m)| (r0 - m) / h).collect()
            } else {
                vec![0.0; r.len()]
            }
        })
        .collect()
}

/// `J^T J` (row-major) and `J^T r` from Jacobian columns.
fn gauss_newton(columns: &[Vec<f64>], r: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut hessian = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let value: f64 = columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum();
            hessian[i * n + j] = value;
            hessian[j * n + i] = value;
        }
    }
    let gradient = columns
        .iter()
        .map(|c| c.iter().zip(r).map(|(a, b)| a * b).sum())
        .collect();
    (hessian, gradient)
}

/// `theta - (H + damping diag H)^-1 g`, each coordinate's move clipped to [`MAX_MOVE`].
fn damped_step(hessian: &[f64], gradient: &[f64], theta: &[f64], damping: f64) -> Option<Vec<f64>> {
    let n = theta.len();
    let mut a = hessian.to_vec();
    for i in 0..n {
        a[i * n + i] += damping * hessian[i * n + i].max(1e-12) + 1e-14;
    }
    let minus_g: Vec<f64> = gradient.iter().map(|g| -g).collect();
    let step = solve_spd(&a, &minus_g)?;
    Some(
        theta
            .iter()
            .zip(&step)
            .map(|(t, s)| t + s.clamp(-MAX_MOVE, MAX_MOVE))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_invert_each_other_and_respect_constraints() {
        for (constraint, value) in [
            (Constraint::Free, -3.5),
            (Constraint::Positive, 0.02),
            (Constraint::Bounds(0.1, 10.0), 7.0),
        ] {
            let back = from_theta(constraint, to_theta(constraint, value));
            assert!(
                (back - value).abs() < 1e-12 * value.abs().max(1.0),
                "{constraint:?}"
            );
        }
        assert!(from_theta(Constraint::Positive, -50.0) > 0.0);
        let bounded = from_theta(Constraint::Bounds(0.1, 10.0), 40.0);
        assert!((0.1..=10.0).contains(&bounded));
    }

    #[test]
    fn levenberg_marquardt_fits_an_exponential_decay() {
        // y = 2 exp(-0.3 t), fitted from (1, 1): Rosenbrock-like curvature in (a, k).
        let times: Vec<f64> = (0..30).map(|k| k as f64 * 0.5).collect();
        let data: Vec<f64> = times.iter().map(|t| 2.0 * (-0.3 * t).exp()).collect();
        let residuals = |theta: &[f64]| -> Option<Vec<f64>> {
            Some(
                (times.iter().zip(&data))
                    .map(|(t, y)| theta[0] * (-theta[1] * t).exp() - y)
                    .collect(),
            )
        };
        let (theta, cost) = levenberg_marquardt(&residuals, vec![1.0, 1.0]);
        assert!(cost < 1e-16, "cost {cost}");
        assert!((theta[0] - 2.0).abs() < 1e-6 && (theta[1] - 0.3).abs() < 1e-6);
    }
}
