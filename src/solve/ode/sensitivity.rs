//! Forward sensitivities `S = dy/dp` carried through the integrators' own steps, so that
//! they are the derivatives of the computed solution (step sizes held fixed), not of some
//! other discretisation: `dS/dt = (df/dy) S + df/dp`.
//!
//! - Explicit steps ([`Explicit`]): every Dormand–Prince stage `Y_i = y + h sum_j a_ij k_j`,
//!   `k_i = f(Y_i)` is differentiated, `dY_i = S + h sum_j a_ij dk_j`,
//!   `dk_i = J(Y_i) dY_i + f_p(Y_i)`, with the same weights, and the dense output applies
//!   to the `dk` as to the `k`.
//! - Implicit steps ([`Implicit`]): the Radau IIA stage equations of the sensitivities
//!   are solved exactly (they are linear in `S`), with the Jacobian at every stage.
//!
//! Sensitivities are `n x p` row-major: entry `(i, k)` is `dy_i/dp_k`.

// Index loops below mirror the method's formulas (stage s, component i).
#![allow(clippy::needless_range_loop)]

use super::dopri_tableau::{combine, dense, Stages};
use super::radau_tableau::{polynomial, A, C, P};
use super::system::{OdeSystem, Stats};
use crate::numeric::Lu;

pub use super::system::multiply_add;

/// Sensitivities through explicit Dormand–Prince steps.
#[derive(Debug, Clone)]
pub struct Explicit {
    current: Vec<f64>,
    stages: Stages,
    stage: Vec<f64>,
    next: Vec<f64>,
    sample: Vec<f64>,
}

impl Explicit {
    /// Work arrays for `n` states and `params` params, sensitivities zero.
    pub fn new(n: usize, params: usize) -> Self {
        let work = || vec![0.0; n * params];
        Explicit {
            current: work(),
            stages: std::array::from_fn(|_| work()),
            stage: work(),
            next: work(),
            sample: work(),
        }
    }

    /// Sets the current sensitivities (`n x p`).
    pub fn set(&mut self, sensitivities: &[f64]) {
        self.current.copy_from_slice(sensitivities);
    }

    /// The current sensitivities.
    pub fn current(&self) -> &[f64] {
        &self.current
    }

    /// The last interpolated sensitivities.
    pub fn sample(&self) -> &[f64] {
        &self.sample
    }

    /// `dk_1 = J(y) S + f_p(y)` at the start of a stretch.
    pub(super) fn first_stage<S: OdeSystem>(
        &mut self,
        system: &mut S,
        t: f64,
        y: &[f64],
        stats: &mut Stats,
    ) {
        self.derivative(system, t, y, 0, stats, false);
    }

    /// Stage `index` at state `y_stage`: `dY = S + h sum_j w_j dk_j` (at `index` 6, the
    /// step's end, that is the new `S`) and `dk = J dY + f_p`.
    pub(super) fn stage<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t, h): (f64, f64),
        y_stage: &[f64],
        index: usize,
        weights: &[(usize, f64)],
        stats: &mut Stats,
    ) {
        combine(&mut self.stage, &self.current, h, &self.stages, weights);
        if index == 6 {
            self.next.copy_from_slice(&self.stage);
        }
        self.derivative(system, t, y_stage, index, stats, true);
    }

    /// `stages[index] = J(y) X + f_p(y)` with `X` the stage sensitivities (`from_stage`)
    /// or the current ones.
    fn derivative<S: OdeSystem>(
        &mut self,
        system: &mut S,
        t: f64,
        y: &[f64],
        index: usize,
        stats: &mut Stats,
        from_stage: bool,
    ) {
        stats.jacobians += 1;
        let source = if from_stage {
            &self.stage
        } else {
            &self.current
        };
        system.sensitivity_derivative(t, y, source, &mut self.stages[index]);
    }

    /// Moves to the end of an accepted step (first stage of the next one: FSAL).
    pub(super) fn accept(&mut self) {
        std::mem::swap(&mut self.current, &mut self.next);
        self.stages.swap(0, 6);
    }

    /// The sensitivities at fraction `theta` of the step of size `h` just taken (before
    /// [`Explicit::accept`]), into [`Explicit::sample`].
    pub(super) fn interpolate(&mut self, theta: f64, h: f64) {
        if theta >= 1.0 {
            self.sample.copy_from_slice(&self.next);
        } else {
            dense(
                theta,
                h,
                &self.current,
                &self.next,
                &self.stages,
                &mut self.sample,
            );
        }
    }
}

/// Sensitivities through implicit Radau IIA steps: the stage equations
/// `W_s = S + h sum_r a_sr (J(Y_r) W_r + f_p(Y_r))` are linear in the `W`, solved at once
/// (`3n x 3n`, one column per param); the new `S` is the last stage's (the method is
/// stiffly accurate) and the collocation polynomial of the `W` is their dense output.
#[derive(Debug, Clone)]
pub struct Implicit {
    n: usize,
    params: usize,
    current: Vec<f64>,
    old: Vec<f64>,
    span: (f64, f64, f64),
    q: [Vec<f64>; 3],
    states_jacobians: [Vec<f64>; 3],
    params_jacobians: [Vec<f64>; 3],
    stage: Vec<f64>,
    sample: Vec<f64>,
}

impl Implicit {
    /// Work arrays for `n` states and `params` params, sensitivities zero.
    pub fn new(n: usize, params: usize) -> Self {
        let work = || vec![0.0; n * params];
        Implicit {
            n,
            params,
            current: work(),
            old: work(),
            span: (0.0, 0.0, 0.0),
            q: std::array::from_fn(|_| work()),
            states_jacobians: std::array::from_fn(|_| vec![0.0; n * n]),
            params_jacobians: std::array::from_fn(|_| work()),
            stage: vec![0.0; n],
            sample: work(),
        }
    }

    /// Sets the current sensitivities (`n x p`).
    pub fn set(&mut self, sensitivities: &[f64]) {
        self.current.copy_from_slice(sensitivities);
    }

    /// The current sensitivities.
    pub fn current(&self) -> &[f64] {
        &self.current
    }

    /// The last interpolated sensitivities.
    pub fn sample(&self) -> &[f64] {
        &self.sample
    }

    /// Carries the sensitivities over the step from `(t, y)` of size `h`, ending at
    /// `t_end`, with stage increments `z`.
    pub(super) fn step<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t, h, t_end): (f64, f64, f64),
        y: &[f64],
        z: &[Vec<f64>; 3],
        stats: &mut Stats,
    ) {
        let n = self.n;
        for s in 0..3 {
            for i in 0..n {
                self.stage[i] = y[i] + z[s][i];
            }
            let at = t + C[s] * h;
            let (states, params) = (&mut self.states_jacobians[s], &mut self.params_jacobians[s]);
            system.sensitivity_jacobians(at, &self.stage, states, params);
        }
        stats.jacobians += 3;
        stats.factorisations += 1;
        let stages = self.solve_stages(h);
        std::mem::swap(&mut self.old, &mut self.current);
        self.current.copy_from_slice(&stages[2]);
        for (j, column) in self.q.iter_mut().enumerate() {
            for (e, value) in column.iter_mut().enumerate() {
                *value = (0..3).map(|s| (stages[s][e] - self.old[e]) * P[s][j]).sum();
            }
        }
        self.span = (t, h, t_end);
    }

    /// The stage sensitivities `W_s` of a step of size `h` (NaN where the stage system is
    /// singular).
    fn solve_stages(&self, h: f64) -> [Vec<f64>; 3] {
        let (n, p) = (self.n, self.params);
        let size = 3 * n;
        let mut matrix = vec![0.0; size * size];
        for s in 0..3 {
            for r in 0..3 {
                let weight = h * A[s][r];
                for a in 0..n {
                    let row = (s * n + a) * size + r * n;
                    for b in 0..n {
                        matrix[row + b] = -weight * self.states_jacobians[r][a * n + b];
                    }
                    if s == r {
                        matrix[row + a] += 1.0;
                    }
                }
            }
        }
        let mut stages: [Vec<f64>; 3] = std::array::from_fn(|_| vec![f64::NAN; n * p]);
        let Some(lu) = Lu::factor(matrix, size) else {
            return stages;
        };
        let mut column = vec![0.0; size];
        for k in 0..p {
            for s in 0..3 {
                for a in 0..n {
                    let forcing: f64 = (0..3)
                        .map(|r| A[s][r] * self.params_jacobians[r][a * p + k])
                        .sum();
                    column[s * n + a] = self.current[a * p + k] + h * forcing;
                }
            }
            lu.solve_in_place(&mut column);
            for s in 0..3 {
                for a in 0..n {
                    stages[s][a * p + k] = column[s * n + a];
                }
            }
        }
        stages
    }

    /// The sensitivities at `t` inside the last step (its end or later: the current ones),
    /// into [`Implicit::sample`].
    pub(super) fn interpolate(&mut self, t: f64) {
        let (t_old, h, t_end) = self.span;
        if h <= 0.0 || t >= t_end {
            self.sample.copy_from_slice(&self.current);
            return;
        }
        let x = (t - t_old) / h;
        for e in 0..self.sample.len() {
            self.sample[e] = self.old[e] + polynomial(&self.q, e, x);
        }
    }
}
