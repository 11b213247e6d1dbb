//! Radau IIA of order 5: the implicit, L-stable integrator for stiff stretches, after
//! Hairer and Wanner, *Solving Ordinary Differential Equations II*, section IV.8 (their
//! code RADAU5), as SciPy's `Radau` implements it: simplified Newton iterations on the
//! collocation system, decoupled by the eigenvalues of the method's matrix into one real
//! and one complex linear system of the state's size; an error estimate from an embedded
//! third-order formula, with one extra solve after a rejection (stiff-accurate estimate);
//! Gustafsson's predictive step-size control; the collocation polynomial as the dense
//! output and as the next step's Newton predictor.
//!
//! The Jacobian is the system's own ([`OdeSystem::jacobian`]: for a model, the exact
//! derivative of its balances, `eval::JacobianProgram`), refreshed where Newton converges
//! slowly; the LU factors are kept while the step size does not change.

// Index loops below mirror the method's formulas (stage s, component i).
#![allow(clippy::needless_range_loop)]

mod newton;

use super::error::{IntegrationError, Stuck};
use super::radau_tableau::{polynomial, C, E, P};
use super::sensitivity::Implicit;
use super::system::{all_finite, rms, OdeSystem, Stats, Tolerances};
use newton::{Iterations, Newton, Start, NEWTON_MAXITER};

const MIN_FACTOR: f64 = 0.2;
const MAX_FACTOR: f64 = 10.0;

/// The step just taken, for the dense output and the next predictor.
#[derive(Debug, Clone)]
struct Taken {
    t_old: f64,
    h: f64,
    y_old: Vec<f64>,
    /// `q[j][i] = sum_s Z_s[i] P[s][j]`.
    q: [Vec<f64>; 3],
}

/// A reusable Radau IIA integrator (owns its work arrays).
#[derive(Debug, Clone)]
pub struct Radau {
    n: usize,
    tolerances: Tolerances,
    t: f64,
    end: f64,
    y: Vec<f64>,
    f: Vec<f64>,
    h_abs: f64,
    h_abs_old: Option<f64>,
    error_norm_old: Option<f64>,
    newton: Newton,
    /// The stage increments of the step being taken.
    z: [Vec<f64>; 3],
    /// Work space: a state, and a right-hand side there.
    stage: Vec<f64>,
    stage_rhs: Vec<f64>,
    scale: Vec<f64>,
    taken: Option<Taken>,
    stats: Stats,
}

impl Radau {
    /// An integrator for systems of `dim` equations.
    pub fn new(dim: usize, tolerances: Tolerances) -> Self {
        let work = || vec![0.0; dim];
        Radau {
            n: dim,
            tolerances,
            t: 0.0,
            end: 0.0,
            y: work(),
            f: work(),
            h_abs: 0.0,
            h_abs_old: None,
            error_norm_old: None,
            newton: Newton::new(dim, tolerances.rtol),
            z: std::array::from_fn(|_| work()),
            stage: work(),
            stage_rhs: work(),
            scale: work(),
            taken: None,
            stats: Stats::default(),
        }
    }

    /// Work done since the integrator was made.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// The current time.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The current state.
    pub fn state(&self) -> &[f64] {
        &self.y
    }

    /// The last step size proposed (0 before the first start).
    pub fn step_size(&self) -> f64 {
        self.h_abs
    }

    /// The size of the last accepted step (0 before one).
    pub fn last_step(&self) -> f64 {
        self.taken.as_ref().map_or(0.0, |taken| taken.h)
    }

    /// Starts a stretch ending at `t_end` from `(t, y)`: a fresh right-hand side and
    /// Jacobian; the step is `step` where given (continuing after an input switch or a
    /// hand-over), else chosen as SciPy's `select_initial_step` does for order 3.
    pub fn start<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t, t_end): (f64, f64),
        y: &[f64],
        step: Option<f64>,
    ) -> Result<(), IntegrationError> {
        (self.t, self.end) = (t, t_end);
        self.y.copy_from_slice(y);
        system.rhs(t, y, &mut self.f);
        self.stats.evaluations += 1;
        if !all_finite(&self.f) {
            return Err(IntegrationError::non_finite(t));
        }
        self.h_abs = match step.filter(|h| *h > 0.0 && h.is_finite()) {
            Some(h) => h.min(t_end - t),
            None => self.initial_step(system, t_end - t),
        };
        (self.h_abs_old, self.error_norm_old, self.taken) = (None, None, None);
        self.newton.refresh(system, t, &self.y, &mut self.stats);
        Ok(())
    }

    /// SciPy's `select_initial_step` with error order 3, at most `interval`.
    fn initial_step<S: OdeSystem>(&mut self, system: &mut S, interval: f64) -> f64 {
        let Tolerances { rtol, atol } = self.tolerances;
        let scale = |v: f64| atol + v.abs() * rtol;
        let d0 = rms(self.y.iter().map(|&v| v / scale(v)));
        let d1 = rms(self.y.iter().zip(&self.f).map(|(&v, &f)| f / scale(v)));
        let h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        }
        .min(interval);
        for i in 0..self.n {
            self.stage[i] = self.y[i] + h0 * self.f[i];
        }
        system.rhs(self.t + h0, &self.stage, &mut self.stage_rhs);
        self.stats.evaluations += 1;
        let d2 = rms((0..self.n).map(|i| (self.stage_rhs[i] - self.f[i]) / scale(self.y[i]))) / h0;
        let h1 = if d1 <= 1e-15 && d2 <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / d1.max(d2)).powf(0.25)
        };
        let h = (100.0 * h0).min(h1).min(interval);
        if h.is_finite() && h > 0.0 {
            h
        } else {
            interval.min(1e-6)
        }
    }

    /// One accepted step towards the end of the stretch; `attempts` counts every step
    /// tried, and the step fails once it passes `budget`.
    pub fn step<S: OdeSystem>(
        &mut self,
        system: &mut S,
        attempts: &mut usize,
        budget: usize,
    ) -> Result<(), IntegrationError> {
        let t_end = self.end;
        let Tolerances { rtol, atol } = self.tolerances;
        let min_step = 10.0 * (next_up(self.t) - self.t);
        let (mut h_abs, h_abs_old, error_norm_old) = if self.h_abs < min_step {
            (min_step, None, None)
        } else {
            (self.h_abs, self.h_abs_old, self.error_norm_old)
        };
        let mut rejected = false;
        let mut non_finite = false;
        loop {
            *attempts += 1;
            if *attempts > budget {
                return Err(IntegrationError::TooManySteps {
                    t: self.t,
                    steps: budget,
                    stuck: self.stuck(h_abs),
                });
            }
            if h_abs < min_step {
                return Err(if non_finite {
                    IntegrationError::non_finite(self.t)
                } else {
                    IntegrationError::StepSizeUnderflow {
                        t: self.t,
                        step: h_abs,
                        stuck: self.stuck(h_abs),
                    }
                });
            }
            let t_new = (self.t + h_abs).min(t_end);
            let h = t_new - self.t;
            h_abs = h;
            self.predict(h);
            for i in 0..self.n {
                self.scale[i] = atol + self.y[i].abs() * rtol;
            }
            let start = Start {
                t: self.t,
                y: &self.y,
                scale: &self.scale,
            };
            let newton = self
                .newton
                .solve(system, &start, h, &mut self.z, &mut self.stats);
            if !newton.converged {
                non_finite = newton.non_finite;
                h_abs *= 0.5;
                self.newton.forget_factors();
                self.stats.rejected += 1;
                continue;
            }
            let error_norm = self.error_norm(system, h, rejected);
            let safety = 0.9 * (2 * NEWTON_MAXITER + 1) as f64
                / (2 * NEWTON_MAXITER + newton.iterations) as f64;
            if error_norm.is_nan() || error_norm > 1.0 {
                non_finite = !error_norm.is_finite();
                let factor = predict_factor(h_abs, h_abs_old, error_norm, error_norm_old);
                h_abs *= MIN_FACTOR.max(safety * factor);
                self.newton.forget_factors();
                rejected = true;
                self.stats.rejected += 1;
                continue;
            }
            let previous = (h_abs_old, error_norm_old);
            self.accept(system, (h, t_new), (newton, safety), error_norm, previous);
            return Ok(());
        }
    }

    /// Moves to the end of an accepted step of size `h` and proposes the next step from
    /// the step and error before it (`previous`).
    fn accept<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (h, t_new): (f64, f64),
        (newton, safety): (Iterations, f64),
        error_norm: f64,
        (h_abs_old, error_norm_old): (Option<f64>, Option<f64>),
    ) {
        let recompute_jacobian = newton.iterations > 2 && newton.rate > 1e-3;
        let factor = predict_factor(h, h_abs_old, error_norm, error_norm_old);
        let mut factor = MAX_FACTOR.min(safety * factor);
        if !recompute_jacobian && factor < 1.2 {
            factor = 1.0;
        } else {
            self.newton.forget_factors();
        }
        self.record_step(h);
        for i in 0..self.n {
            self.y[i] += self.z[2][i];
        }
        self.t = t_new;
        system.rhs(t_new, &self.y, &mut self.f);
        self.stats.evaluations += 1;
        if recompute_jacobian {
            self.newton.refresh(system, t_new, &self.y, &mut self.stats);
        } else {
            self.newton.age();
        }
        self.h_abs_old = Some(self.h_abs);
        self.error_norm_old = Some(error_norm);
        self.h_abs = h * factor;
        self.stats.accepted += 1;
        self.stats.implicit += 1;
    }

    /// Keeps the step about to be taken (from the current state, size `h`, stage
    /// increments `z`) for the dense output and the next predictor.
    fn record_step(&mut self, h: f64) {
        let n = self.n;
        let mut taken = self.taken.take().unwrap_or_else(|| Taken {
            t_old: 0.0,
            h: 0.0,
            y_old: vec![0.0; n],
            q: std::array::from_fn(|_| vec![0.0; n]),
        });
        taken.t_old = self.t;
        taken.h = h;
        taken.y_old.copy_from_slice(&self.y);
        for (j, column) in taken.q.iter_mut().enumerate() {
            for (i, value) in column.iter_mut().enumerate() {
                *value = (0..3).map(|s| self.z[s][i] * P[s][j]).sum();
            }
        }
        self.taken = Some(taken);
    }

    /// The Newton starting guess for a step of size `h`: the last step's collocation
    /// polynomial extrapolated to the new stage times, or zero increments.
    fn predict(&mut self, h: f64) {
        match &self.taken {
            Some(taken) => {
                for s in 0..3 {
                    let x = (self.t + C[s] * h - taken.t_old) / taken.h;
                    for i in 0..self.n {
                        let value = polynomial(&taken.q, i, x);
                        self.z[s][i] = taken.y_old[i] + value - self.y[i];
                    }
                }
            }
            None => self.z.iter_mut().for_each(|z| z.fill(0.0)),
        }
    }

    /// The state at `t` inside the last step, into `out`.
    pub fn interpolate(&self, t: f64, out: &mut [f64]) {
        let Some(taken) = &self.taken else {
            out.copy_from_slice(&self.y);
            return;
        };
        if t >= self.t {
            out.copy_from_slice(&self.y);
            return;
        }
        let x = (t - taken.t_old) / taken.h;
        for (i, value) in out.iter_mut().enumerate() {
            *value = taken.y_old[i] + polynomial(&taken.q, i, x);
        }
    }

    /// Carries `sensitivity` over the step just taken.
    pub fn step_sensitivities<S: OdeSystem>(&mut self, system: &mut S, sensitivity: &mut Implicit) {
        if let Some(taken) = &self.taken {
            let span = (taken.t_old, taken.h, self.t);
            sensitivity.step(system, span, &taken.y_old, &self.z, &mut self.stats);
        }
    }

    /// The scaled norm of the embedded error estimate of a converged step of size `h`
    /// (after a rejection, the stiff-accurate one with one more solve); NaN where a value
    /// is not finite.
    fn error_norm<S: OdeSystem>(&mut self, system: &mut S, h: f64, rejected: bool) -> f64 {
        let Tolerances { rtol, atol } = self.tolerances;
        let Some(lu_real) = self.newton.real_factor() else {
            return f64::NAN;
        };
        let n = self.n;
        let correction: Vec<f64> = (0..n)
            .map(|i| (0..3).map(|s| self.z[s][i] * E[s]).sum::<f64>() / h)
            .collect();
        let mut error: Vec<f64> = (0..n).map(|i| self.f[i] + correction[i]).collect();
        lu_real.solve_in_place(&mut error);
        for i in 0..n {
            let y_new = self.y[i] + self.z[2][i];
            self.scale[i] = atol + self.y[i].abs().max(y_new.abs()) * rtol;
        }
        let norm = |error: &[f64], scale: &[f64]| rms((0..n).map(|i| error[i] / scale[i]));
        let mut value = norm(&error, &self.scale);
        if rejected && value > 1.0 {
            for i in 0..n {
                self.stage[i] = self.y[i] + error[i];
            }
            system.rhs(self.t, &self.stage, &mut error);
            self.stats.evaluations += 1;
            for i in 0..n {
                error[i] += correction[i];
            }
            lu_real.solve_in_place(&mut error);
            value = norm(&error, &self.scale);
        }
        let finite = (0..n).all(|i| (self.y[i] + self.z[2][i]).is_finite());
        if finite {
            value
        } else {
            f64::NAN
        }
    }

    /// Where the integration is stuck, from the Newton Jacobian.
    fn stuck(&self, step: f64) -> Stuck {
        Stuck::from_jacobian(self.newton.jacobian(), self.n, step, true)
    }
}

/// The smallest double above `t` (`t` itself at infinity).
fn next_up(t: f64) -> f64 {
    if t == 0.0 {
        return f64::from_bits(1);
    }
    let bits = t.to_bits();
    let next = f64::from_bits(if t > 0.0 { bits + 1 } else { bits - 1 });
    if next.is_finite() {
        next
    } else {
        t
    }
}

/// Gustafsson's predictive factor for the next step (Hairer and Wanner IV.8).
fn predict_factor(
    h_abs: f64,
    h_abs_old: Option<f64>,
    error_norm: f64,
    error_norm_old: Option<f64>,
) -> f64 {
    let multiplier = match (h_abs_old, error_norm_old) {
        (Some(h_old), Some(e_old)) if error_norm != 0.0 => {
            h_abs / h_old * (e_old / error_norm).powf(0.25)
        }
        _ => 1.0,
    };
    multiplier.min(1.0) * error_norm.powf(-0.25)
}
