//! The simplified Newton iterations of a Radau IIA step (SciPy's
//! `solve_collocation_system`): the Jacobian they use, the two linear systems the
//! eigenvalues of the method's matrix decouple them into (one real, one complex, each of
//! the state's size) with their LU factors, and the iterations themselves.

// Index loops below mirror the method's formulas (stage s, component i).
#![allow(clippy::needless_range_loop)]

use crate::numeric::{Complex, Lu};
use crate::solve::ode::radau_tableau::{C, MU_COMPLEX, MU_REAL, T, TI};
use crate::solve::ode::system::{all_finite, rms, OdeSystem, Stats};

/// Most Newton iterations of one step.
pub(super) const NEWTON_MAXITER: usize = 6;

/// The outcome of the Newton iterations.
pub(super) struct Iterations {
    /// Whether the iterations converged.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
    /// The last contraction rate (infinite before the second iteration).
    pub rate: f64,
    /// Whether a stage's right-hand side was not finite.
    pub non_finite: bool,
}

impl Iterations {
    /// No iteration run (yet).
    fn none() -> Self {
        Iterations {
            converged: false,
            iterations: 0,
            rate: f64::INFINITY,
            non_finite: false,
        }
    }
}

/// Where a step starts: the time, the state and each state's error scale.
pub(super) struct Start<'a> {
    /// The step's start time.
    pub t: f64,
    /// The state there.
    pub y: &'a [f64],
    /// The error scale of each state (`atol + rtol |y|`).
    pub scale: &'a [f64],
}

/// The simplified Newton solver of the collocation system (owns its work arrays).
#[derive(Debug, Clone)]
pub(super) struct Newton {
    n: usize,
    /// The convergence tolerance of the scaled increments.
    tolerance: f64,
    jacobian: Vec<f64>,
    /// Whether the Jacobian was taken at the current state.
    current: bool,
    lu_real: Option<Lu<f64>>,
    lu_complex: Option<Lu<Complex>>,
    /// The stage increments in the eigenbasis of the method's matrix (`T^-1 Z`).
    w: [Vec<f64>; 3],
    stage_rhs: [Vec<f64>; 3],
    stage: Vec<f64>,
}

impl Newton {
    /// A solver for systems of `n` equations at relative tolerance `rtol`.
    pub fn new(n: usize, rtol: f64) -> Self {
        let work = || vec![0.0; n];
        Newton {
            n,
            tolerance: (10.0 * f64::EPSILON / rtol).max(0.03f64.min(rtol.sqrt())),
            jacobian: vec![0.0; n * n],
            current: false,
            lu_real: None,
            lu_complex: None,
            w: std::array::from_fn(|_| work()),
            stage_rhs: std::array::from_fn(|_| work()),
            stage: work(),
        }
    }

    /// The Jacobian the iterations use (`n x n`, row-major).
    pub fn jacobian(&self) -> &[f64] {
        &self.jacobian
    }

    /// The factors of the real system, where factored and not singular.
    pub fn real_factor(&self) -> Option<&Lu<f64>> {
        self.lu_real.as_ref()
    }

    /// Takes a fresh Jacobian at `(t, y)` (the factors go with the old one).
    pub fn refresh<S: OdeSystem>(&mut self, system: &mut S, t: f64, y: &[f64], stats: &mut Stats) {
        system.jacobian(t, y, &mut self.jacobian);
        stats.jacobians += 1;
        self.current = true;
        self.forget_factors();
    }

    /// Drops the factors (the step size changed).
    pub fn forget_factors(&mut self) {
        self.lu_real = None;
        self.lu_complex = None;
    }

    /// Notes that the state moved on since the Jacobian was taken.
    pub fn age(&mut self) {
        self.current = false;
    }

    /// The simplified Newton iterations on the collocation system for a step of size `h`
    /// from `start`, from the predictor in `z` (left with the stage increments), factoring
    /// the two systems first where needed and retrying once with a fresh Jacobian.
    pub fn solve<S: OdeSystem>(
        &mut self,
        system: &mut S,
        start: &Start,
        h: f64,
        z: &mut [Vec<f64>; 3],
        stats: &mut Stats,
    ) -> Iterations {
        let guess = z.clone();
        loop {
            if self.lu_real.is_none() || self.lu_complex.is_none() {
                self.factor(h, stats);
            }
            let newton = match (&self.lu_real, &self.lu_complex) {
                (Some(_), Some(_)) => self.iterate(system, start, h, z, stats),
                _ => Iterations::none(),
            };
            if newton.converged || self.current {
                return newton;
            }
            self.refresh(system, start.t, start.y, stats);
            z.clone_from(&guess);
        }
    }

    /// Factors `MU_REAL / h - J` and `MU_COMPLEX / h - J` (`None` where singular).
    fn factor(&mut self, h: f64, stats: &mut Stats) {
        let n = self.n;
        let mut real = vec![0.0; n * n];
        let mut complex = vec![Complex::default(); n * n];
        let (m_real, m_complex) = shifts(h);
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
        stats.factorisations += 2;
    }

    /// The iterations themselves, with both factors at hand.
    fn iterate<S: OdeSystem>(
        &mut self,
        system: &mut S,
        start: &Start,
        h: f64,
        z: &mut [Vec<f64>; 3],
        stats: &mut Stats,
    ) -> Iterations {
        let n = self.n;
        let (Some(lu_real), Some(lu_complex)) = (self.lu_real.take(), self.lu_complex.take())
        else {
            return Iterations::none();
        };
        self.transform(z);
        let mut real = vec![0.0; n];
        let mut complex = vec![Complex::default(); n];
        let mut previous_norm: Option<f64> = None;
        let mut outcome = Iterations::none();
        for k in 0..NEWTON_MAXITER {
            outcome.iterations = k + 1;
            if !self.evaluate_stages(system, start, h, z, stats) {
                outcome.non_finite = true;
                break;
            }
            self.increment(h, (&mut real, &mut complex));
            lu_real.solve_in_place(&mut real);
            lu_complex.solve_in_place(&mut complex);
            let norm = scaled_norm(start.scale, &real, &complex);
            let rate = previous_norm.map(|old| norm / old);
            if let Some(rate) = rate {
                outcome.rate = rate;
                if self.diverges(rate, norm, k) {
                    break;
                }
            }
            self.apply(&real, &complex, z);
            if norm == 0.0 || rate.is_some_and(|rate| rate / (1.0 - rate) * norm < self.tolerance) {
                outcome.converged = true;
                break;
            }
            previous_norm = Some(norm);
        }
        self.lu_real = Some(lu_real);
        self.lu_complex = Some(lu_complex);
        outcome
    }

    /// `w = T^-1 z`, stage by stage.
    fn transform(&mut self, z: &[Vec<f64>; 3]) {
        for r in 0..3 {
            for i in 0..self.n {
                self.w[r][i] = (0..3).map(|s| TI[r][s] * z[s][i]).sum();
            }
        }
    }

    /// The right-hand side at each stage `y + z_s`; whether all are finite.
    fn evaluate_stages<S: OdeSystem>(
        &mut self,
        system: &mut S,
        start: &Start,
        h: f64,
        z: &[Vec<f64>; 3],
        stats: &mut Stats,
    ) -> bool {
        for s in 0..3 {
            for i in 0..self.n {
                self.stage[i] = start.y[i] + z[s][i];
            }
            system.rhs(start.t + C[s] * h, &self.stage, &mut self.stage_rhs[s]);
        }
        stats.evaluations += 3;
        self.stage_rhs.iter().all(|f| all_finite(f))
    }

    /// The right-hand sides of the real and the complex system (before their solves).
    fn increment(&self, h: f64, (real, complex): (&mut [f64], &mut [Complex])) {
        let (m_real, m_complex) = shifts(h);
        let w = &self.w;
        for i in 0..self.n {
            let f = [
                self.stage_rhs[0][i],
                self.stage_rhs[1][i],
                self.stage_rhs[2][i],
            ];
            real[i] = TI[0][0] * f[0] + TI[0][1] * f[1] + TI[0][2] * f[2] - m_real * w[0][i];
            let re = TI[1][0] * f[0] + TI[1][1] * f[1] + TI[1][2] * f[2];
            let im = TI[2][0] * f[0] + TI[2][1] * f[1] + TI[2][2] * f[2];
            complex[i] = Complex::new(re, im) - m_complex * Complex::new(w[1][i], w[2][i]);
        }
    }

    /// Whether iteration `k` (from 0), at contraction `rate` and increment `norm`, cannot
    /// converge within the iterations left.
    fn diverges(&self, rate: f64, norm: f64, k: usize) -> bool {
        let remaining = (NEWTON_MAXITER - k) as i32;
        rate >= 1.0 || rate.powi(remaining) / (1.0 - rate) * norm > self.tolerance
    }

    /// Adds the solved increment to `w` and carries it back to the stage increments `z`.
    fn apply(&mut self, real: &[f64], complex: &[Complex], z: &mut [Vec<f64>; 3]) {
        let n = self.n;
        for i in 0..n {
            self.w[0][i] += real[i];
            self.w[1][i] += complex[i].re;
            self.w[2][i] += complex[i].im;
        }
        for s in 0..3 {
            for i in 0..n {
                z[s][i] = (0..3).map(|r| T[s][r] * self.w[r][i]).sum();
            }
        }
    }
}

/// The shifts `MU_REAL / h` and `MU_COMPLEX / h` of the two systems.
fn shifts(h: f64) -> (f64, Complex) {
    (
        MU_REAL / h,
        Complex::new(MU_COMPLEX.re / h, MU_COMPLEX.im / h),
    )
}

/// The root-mean-square of the increment relative to each state's error scale.
fn scaled_norm(scale: &[f64], real: &[f64], complex: &[Complex]) -> f64 {
    rms((0..real.len()).flat_map(|i| {
        let scale = scale[i];
        [
            real[i] / scale,
            complex[i].re / scale,
            complex[i].im / scale,
        ]
    }))
}
