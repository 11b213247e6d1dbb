//! Fitting a mechanistic model's params to a record: Levenberg–Marquardt on the z-scored
//! free-run residuals of the training rows, with a forward-difference Jacobian through the
//! simulator (the shared driver, [`crate::numeric::lm`]), in transformed coordinates so
//! that constraints always hold (`positive`: `p = exp(theta)`; `in [lo, hi]`:
//! `p = lo + (hi - lo) sigmoid(theta)`), from the given start and a few random restarts.

use super::record::{Normalisation, Record};
use super::simulate::Simulator;
use crate::eval::sigmoid;
use crate::ir::Constraint;
use crate::numeric::lm::{Function, Jacobian};
use crate::numeric::{Damping, Settings};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::ops::Range;

/// The damping schedule: from `1e-3`, divided by 3 on success (down to `1e-9`) and
/// multiplied by 4 on failure, retried at the same Jacobian until the damping reaches
/// `1e10`; at most 60 Jacobians per start; converged when a step gains at most `1e-7` of the
/// cost; a transformed coordinate moves at most 3 in one step.
const SETTINGS: Settings = Settings {
    min_damping: 1e-9,
    singular_factor: 4.0,
    max_damping: 1e10,
    max_trials: usize::MAX,
    max_linearisations: 60,
    tolerance: 1e-7,
    max_move: 3.0,
    ..Settings::DEFAULT
};
/// Marquardt's scaling, with floors for a coordinate no residual sees.
const DAMPING: Damping = Damping {
    min_diagonal: 1e-12,
    jitter: 1e-14,
    relative_jitter: 0.0,
};
/// Forward-difference step in transformed coordinates.
const JACOBIAN_STEP: f64 = 1e-6;
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

/// Minimises `|r(theta)|^2` from `theta` with the diagnosis's settings (forward-difference
/// Jacobian, columns in parallel); returns the minimiser and the minimum (infinite when `r`
/// fails at the start).
pub fn levenberg_marquardt(
    residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    theta: Vec<f64>,
) -> (Vec<f64>, f64) {
    let function = Function {
        residuals,
        jacobian: Jacobian::ForwardDifferences {
            step: JACOBIAN_STEP,
        },
        damping: DAMPING,
    };
    let outcome = function.minimise(theta, &SETTINGS);
    (outcome.x, outcome.cost)
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
}
