//! The Newton iterations of a Radau IIA step and its error estimate.

// Index loops below mirror the method's formulas (stage s, component i).
#![allow(clippy::needless_range_loop)]

use super::{Radau, C, E, MU_COMPLEX, MU_REAL, NEWTON_MAXITER, T, TI};
use crate::numeric::{Complex, Lu};
use crate::solve::ode::error::IntegrationError;
use crate::solve::ode::system::{all_finite, rms, OdeSystem, Tolerances};

/// The outcome of the Newton iterations.
pub(super) struct Newton {
    /// Whether the iterations converged.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
    /// The last contraction rate (infinite before the second iteration).
    pub rate: f64,
    /// Whether a stage's right-hand side was not finite.
    pub non_finite: bool,
}

impl Radau {
    /// The simplified Newton iterations on the collocation system for a step of size `h`
    /// from the predictor in `z` (SciPy's `solve_collocation_system`), factoring the two
    /// systems first where needed and retrying once with a fresh Jacobian.
    pub(super) fn solve_collocation<S: OdeSystem>(
        &mut self,
        system: &mut S,
        h: f64,
    ) -> Result<Newton, IntegrationError> {
        let guess = self.z.clone();
        loop {
            if self.lu_real.is_none() || self.lu_complex.is_none() {
                self.factor(h);
            }
            let newton = match (&self.lu_real, &self.lu_complex) {
                (Some(_), Some(_)) => self.newton(system, h),
                _ => Newton {
                    converged: false,
                    iterations: 0,
                    rate: f64::INFINITY,
                    non_finite: false,
                },
            };
            if newton.converged || self.current_jacobian {
                return Ok(newton);
            }
            self.refresh_jacobian(system, self.t);
            self.z.clone_from(&guess);
        }
    }

    /// Factors `MU_REAL / h - J` and `MU_COMPLEX / h - J` (`None` where singular).
    fn factor(&mut self, h: f64) {
        let n = self.n;
        let mut real = vec![0.0; n * n];
        let mut complex = vec![Complex::default(); n * n];
        let (m_real, m_complex) = (
            MU_REAL / h,
            Complex::new(MU_COMPLEX.re / h, MU_COMPLEX.im / h),
        );
        for i in 0..n {
            for j in 0..n {
                let entry = -self.jacobian[i * n + j];
                real[i * n + j] = entry;
                complex[i * n + j] = Complex::new(entry, 0.0);
            }
            real[i * n + i] += m_real;
            complex[i * n + i] = complex[i * n + i] + m_complex;
        }
        self.lu_real = Lu::factor(real, n);
        self.lu_complex = Lu::factor(complex, n);
        self.stats.factorisations += 2;
    }

    /// The iterations themselves, with both factors at hand.
    fn newton<S: OdeSystem>(&mut self, system: &mut S, h: f64) -> Newton {
        let n = self.n;
        let (Some(lu_real), Some(lu_complex)) = (self.lu_real.take(), self.lu_complex.take())
        else {
            return Newton {
                converged: false,
                iterations: 0,
                rate: f64::INFINITY,
                non_finite: false,
            };
        };
        let (m_real, m_complex) = (
            MU_REAL / h,
            Complex::new(MU_COMPLEX.re / h, MU_COMPLEX.im / h),
        );
        for r in 0..3 {
            for i in 0..n {
                self.w[r][i] = (0..3).map(|s| TI[r][s] * self.z[s][i]).sum();
            }
        }
        let mut real = vec![0.0; n];
        let mut complex = vec![Complex::default(); n];
        let mut previous_norm: Option<f64> = None;
        let mut outcome = Newton {
            converged: false,
            iterations: 0,
            rate: f64::INFINITY,
            non_finite: false,
        };
        for k in 0..NEWTON_MAXITER {
            outcome.iterations = k + 1;
            for s in 0..3 {
                for i in 0..n {
                    self.stage[i] = self.y[i] + self.z[s][i];
                }
                system.rhs(self.t + C[s] * h, &self.stage, &mut self.stage_rhs[s]);
            }
            self.stats.evaluations += 3;
            if !self.stage_rhs.iter().all(|f| all_finite(f)) {
                outcome.non_finite = true;
                break;
            }
            for i in 0..n {
                let f = [
                    self.stage_rhs[0][i],
                    self.stage_rhs[1][i],
                    self.stage_rhs[2][i],
                ];
                real[i] =
                    TI[0][0] * f[0] + TI[0][1] * f[1] + TI[0][2] * f[2] - m_real * self.w[0][i];
                let re = TI[1][0] * f[0] + TI[1][1] * f[1] + TI[1][2] * f[2];
                let im = TI[2][0] * f[0] + TI[2][1] * f[1] + TI[2][2] * f[2];
                complex[i] =
                    Complex::new(re, im) - m_complex * Complex::new(self.w[1][i], self.w[2][i]);
            }
            lu_real.solve_in_place(&mut real);
            lu_complex.solve_in_place(&mut complex);
            let norm = rms((0..n).flat_map(|i| {
                let scale = self.scale[i];
                [
                    real[i] / scale,
                    complex[i].re / scale,
                    complex[i].im / scale,
                ]
            }));
            let rate = previous_norm.map(|old| norm / old);
            if let Some(rate) = rate {
                outcome.rate = rate;
                let remaining = (NEWTON_MAXITER - k) as i32;
                if rate >= 1.0 || rate.powi(remaining) / (1.0 - rate) * norm > self.newton_tol {
                    break;
                }
            }
            for i in 0..n {
                self.w[0][i] += real[i];
                self.w[1][i] += complex[i].re;
                self.w[2][i] += complex[i].im;
            }
            for s in 0..3 {
                for i in 0..n {
                    self.z[s][i] = (0..3).map(|r| T[s][r] * self.w[r][i]).sum();
                }
            }
            if norm == 0.0 || rate.is_some_and(|rate| rate / (1.0 - rate) * norm < self.newton_tol)
            {
                outcome.converged = true;
                break;
            }
            previous_norm = Some(norm);
        }
        self.lu_real = Some(lu_real);
        self.lu_complex = Some(lu_complex);
        outcome
    }

    /// The scaled norm of the embedded error estimate of a converged step of size `h`
    /// (after a rejection, the stiff-accurate one with one more solve); NaN where a value
    /// is not finite.
    pub(super) fn error_norm<S: OdeSystem>(
        &mut self,
        system: &mut S,
        h: f64,
        rejected: bool,
    ) -> f64 {
        let Tolerances { rtol, atol } = self.tolerances;
        let Some(lu_real) = &self.lu_real else {
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
}
