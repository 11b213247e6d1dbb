//! What the integrators integrate: a system of ordinary differential equations with its
//! Jacobian (and, for forward sensitivities, its derivatives with respect to params), the
//! error tolerances, and the work counters.

/// A system of ordinary differential equations `dy/dt = f(t, y)`.
///
/// Only [`OdeSystem::dim`] and [`OdeSystem::rhs`] are required. The implicit integrator
/// needs `df/dy` ([`OdeSystem::jacobian`]: forward differences unless the system gives it
/// exactly); forward sensitivities need `df/dp` too ([`OdeSystem::sensitivity_jacobians`],
/// for the [`OdeSystem::sensitivity_params`] params the system is differentiated by).
pub trait OdeSystem {
    /// Number of equations.
    fn dim(&self) -> usize;

    /// Writes `f(t, y)` into `dydt` (both of length [`OdeSystem::dim`]).
    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]);

    /// Writes `df/dy` at `(t, y)` into `jacobian` (`dim x dim`, row-major: entry `(i, j)` is
    /// `df_i/dy_j`). The default takes forward differences of [`OdeSystem::rhs`].
    fn jacobian(&mut self, t: f64, y: &[f64], jacobian: &mut [f64]) {
        forward_difference_jacobian(self, t, y, jacobian);
    }

    /// Number of params forward sensitivities are taken with respect to (0: none).
    fn sensitivity_params(&self) -> usize {
        0
    }

    /// Writes `df/dy` (`dim x dim`) and `df/dp` (`dim x sensitivity_params`, row-major) at
    /// `(t, y)`. The default gives [`OdeSystem::jacobian`] and no params.
    fn sensitivity_jacobians(
        &mut self,
        t: f64,
        y: &[f64],
        states: &mut [f64],
        _params: &mut [f64],
    ) {
        self.jacobian(t, y, states);
    }

    /// Writes the derivative of the sensitivities, `(df/dy) s + df/dp` (`dim x p`,
    /// row-major, `p` = [`OdeSystem::sensitivity_params`]), at `(t, y)` with sensitivities
    /// `s`. The default multiplies out [`OdeSystem::sensitivity_jacobians`]; a system with
    /// a sparse Jacobian does better.
    fn sensitivity_derivative(&mut self, t: f64, y: &[f64], s: &[f64], out: &mut [f64]) {
        let (n, p) = (y.len(), self.sensitivity_params());
        let (mut states, mut params) = (vec![0.0; n * n], vec![0.0; n * p]);
        self.sensitivity_jacobians(t, y, &mut states, &mut params);
        multiply_add(&states, s, &params, n, p, out);
    }
}

/// `out = a b + c` for `a` (`n x n`), `b` and `c` (`n x p`), row-major: the derivative of
/// forward sensitivities, `(df/dy) S + df/dp` (public as
/// [`super::sensitivity::multiply_add`]).
pub fn multiply_add(a: &[f64], b: &[f64], c: &[f64], n: usize, p: usize, out: &mut [f64]) {
    for i in 0..n {
        let row = &mut out[i * p..(i + 1) * p];
        row.copy_from_slice(&c[i * p..(i + 1) * p]);
        for (j, &entry) in a[i * n..(i + 1) * n].iter().enumerate() {
            if entry != 0.0 {
                for (value, &b_jk) in row.iter_mut().zip(&b[j * p..(j + 1) * p]) {
                    *value += entry * b_jk;
                }
            }
        }
    }
}

/// `df/dy` by forward differences with steps `sqrt(eps) max(|y_j|, 1e-8)`.
fn forward_difference_jacobian<S: OdeSystem + ?Sized>(
    system: &mut S,
    t: f64,
    y: &[f64],
    jacobian: &mut [f64],
) {
    let n = y.len();
    let (mut base, mut shifted) = (vec![0.0; n], vec![0.0; n]);
    system.rhs(t, y, &mut base);
    let mut moved = y.to_vec();
    for j in 0..n {
        let step = f64::EPSILON.sqrt() * y[j].abs().max(1e-8);
        moved[j] = y[j] + step;
        system.rhs(t, &moved, &mut shifted);
        moved[j] = y[j];
        for i in 0..n {
            jacobian[i * n + j] = (shifted[i] - base[i]) / step;
        }
    }
}

/// Error tolerances: the local error of component `i` is kept below
/// `atol + rtol * |y_i|` in the root-mean-square sense.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance (in the units of the states).
    pub atol: f64,
}

impl Default for Tolerances {
    /// `rtol = 1e-9`, `atol = 1e-12`: tight enough that simulated data carry no visible
    /// integration error at the magnitudes of the paper's models.
    fn default() -> Self {
        Tolerances {
            rtol: 1e-9,
            atol: 1e-12,
        }
    }
}

/// Work counters of an integration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Accepted steps.
    pub accepted: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Evaluations of the right-hand side.
    pub evaluations: usize,
    /// Evaluations of the Jacobian (implicit steps and sensitivities).
    pub jacobians: usize,
    /// LU factorisations (implicit steps and sensitivities).
    pub factorisations: usize,
    /// Accepted steps taken by the implicit method.
    pub implicit: usize,
    /// Switches between the explicit and the implicit method.
    pub switches: usize,
}

impl Stats {
    /// Adds another integration's work.
    pub fn add(&mut self, other: &Stats) {
        self.accepted += other.accepted;
        self.rejected += other.rejected;
        self.evaluations += other.evaluations;
        self.jacobians += other.jacobians;
        self.factorisations += other.factorisations;
        self.implicit += other.implicit;
        self.switches += other.switches;
    }
}

/// `sqrt(mean(x_i^2))`, 0 for no entries.
pub(super) fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if count == 0 {
        0.0
    } else {
        (sum / count as f64).sqrt()
    }
}

/// Whether every value is finite.
pub(super) fn all_finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}
