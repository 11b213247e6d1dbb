//! One Levenberg–Marquardt driver for every nonlinear least-squares fit in gbc: the
//! param polish after training, the params from the balances, and the diagnosis's fits
//! through the simulator.
//!
//! It minimises `|r(x)|^2`. At the current point the [`Problem`] linearises (a Jacobian, or
//! whatever structured normal equations it has); each trial solves the damped system
//! `(J'J + lambda D) d = -J'r` ([`Linearisation::step`]) and is kept only when it lowers the
//! cost. An accepted step divides the damping by [`Settings::accept_factor`] and asks for a
//! new linearisation; a rejected one multiplies it by [`Settings::reject_factor`] and retries
//! at the same linearisation (a singular system by [`Settings::singular_factor`]). The fit
//! stops when an accepted step gains no more than [`Settings::tolerance`] of the cost, the
//! cost is zero, the damping passes [`Settings::max_damping`], or a budget of trials or
//! linearisations is spent.
//!
//! [`GaussNewton`] is the dense linearisation from Jacobian columns; [`Function`] wraps a
//! residual closure with an analytic or forward-difference Jacobian; [`standard_errors`] is
//! the linearised (Gauss–Newton) uncertainty `s^2 (J'J)^-1` at the end.

use rayon::prelude::*;
use std::convert::Infallible;

use super::linalg::{dot, gauss_newton_system, Cholesky};

/// The damping schedule and stopping rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Damping of the first trial.
    pub initial_damping: f64,
    /// An accepted step divides the damping by this ...
    pub accept_factor: f64,
    /// ... down to this.
    pub min_damping: f64,
    /// A rejected step (higher or non-finite cost, or residuals that fail) multiplies it.
    pub reject_factor: f64,
    /// A damped system that is not positive definite multiplies it.
    pub singular_factor: f64,
    /// The fit stops when the damping exceeds this (no step lowers the cost).
    pub max_damping: f64,
    /// Most trial steps (accepted, rejected and singular).
    pub max_trials: usize,
    /// Most linearisations (one at the start and one after each accepted step).
    pub max_linearisations: usize,
    /// The fit stops after an accepted step that lowers the cost by no more than this
    /// fraction of it.
    pub tolerance: f64,
    /// Largest change of one unknown in one step (each coordinate of a step is clipped).
    pub max_move: f64,
}

impl Settings {
    /// Damping from `1e-3`, divided by 3 on success (down to `1e-12`), multiplied by 4 on
    /// failure and 10 on a singular system, stopping beyond `1e12`; 100 trials; relative
    /// tolerance `1e-9`; no step limit.
    pub const DEFAULT: Settings = Settings {
        initial_damping: 1e-3,
        accept_factor: 3.0,
        min_damping: 1e-12,
        reject_factor: 4.0,
        singular_factor: 10.0,
        max_damping: 1e12,
        max_trials: 100,
        max_linearisations: 100,
        tolerance: 1e-9,
        max_move: f64::INFINITY,
    };
}

impl Default for Settings {
    fn default() -> Self {
        Settings::DEFAULT
    }
}

/// A least-squares problem in unknowns `x`.
pub trait Problem {
    /// What can go wrong evaluating it (besides residuals that cannot be computed).
    type Error;
    /// The local model at a point, which solves damped steps.
    type Linear: Linearisation;

    /// The residuals at `x`; `Ok(None)` where they cannot be computed (a simulation that
    /// fails): a trial step there is rejected.
    fn residuals(&mut self, x: &[f64]) -> Result<Option<Vec<f64>>, Self::Error>;

    /// The linearisation at `x`, whose residuals are `residuals`.
    fn linearise(&mut self, x: &[f64], residuals: &[f64]) -> Result<Self::Linear, Self::Error>;
}

/// The normal equations at one point.
pub trait Linearisation {
    /// The step `d` of the damped system `(J'J + damping D) d = -J'r`; `None` when it is not
    /// numerically positive definite.
    fn step(&self, damping: f64) -> Option<Vec<f64>>;
}

/// How damping enters the diagonal of `J'J`: `a_ii + damping * max(a_ii, min_diagonal) +
/// jitter + relative_jitter * mean(diag)`. The jitters keep the system invertible where an
/// unknown moves no residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    /// The least diagonal entry the damping scales.
    pub min_diagonal: f64,
    /// Added to every diagonal entry.
    pub jitter: f64,
    /// Added to every diagonal entry, times the mean diagonal entry (at least `1e-300`).
    pub relative_jitter: f64,
}

impl Damping {
    /// `matrix` (`n x n`, row-major) with the damping on its diagonal.
    pub fn apply(&self, matrix: &[f64], n: usize, damping: f64) -> Vec<f64> {
        let mut jitter = self.jitter;
        if self.relative_jitter != 0.0 {
            let trace = (0..n).map(|i| matrix[i * n + i]).sum::<f64>() / n.max(1) as f64;
            jitter += self.relative_jitter * trace.max(1e-300);
        }
        let mut damped = matrix.to_vec();
        for i in 0..n {
            damped[i * n + i] += damping * matrix[i * n + i].max(self.min_diagonal) + jitter;
        }
        damped
    }
}

/// Dense normal equations `J'J`, `J'r` from the columns of a Jacobian.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussNewton {
    n: usize,
    /// `J'J`, row-major.
    normal: Vec<f64>,
    /// `J'r`.
    gradient: Vec<f64>,
    damping: Damping,
}

impl GaussNewton {
    /// The system of Jacobian `columns` (one per unknown) and `residuals`.
    pub fn new(columns: &[Vec<f64>], residuals: &[f64], damping: Damping) -> Self {
        let (normal, gradient) = gauss_newton_system(columns, residuals);
        GaussNewton {
            n: columns.len(),
            normal,
            gradient,
            damping,
        }
    }
}

impl Linearisation for GaussNewton {
    fn step(&self, damping: f64) -> Option<Vec<f64>> {
        let damped = self.damping.apply(&self.normal, self.n, damping);
        let minus_gradient: Vec<f64> = self.gradient.iter().map(|g| -g).collect();
        Some(Cholesky::factor(&damped, self.n)?.solve(&minus_gradient))
    }
}

/// Where a fit ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The minimiser found (the start when no step was accepted).
    pub x: Vec<f64>,
    /// The residuals there (empty when they could not be computed at the start).
    pub residuals: Vec<f64>,
    /// `|r|^2` there (infinite when the residuals could not be computed at the start).
    pub cost: f64,
    /// `|r|^2` at the start.
    pub initial_cost: f64,
    /// Accepted steps.
    pub steps: usize,
    /// Linearisations (Jacobians) computed.
    pub linearisations: usize,
}

/// Minimises `|r(x)|^2` from `x` (see the module documentation).
pub fn minimise<P: Problem + ?Sized>(
    problem: &mut P,
    x: Vec<f64>,
    settings: &Settings,
) -> Result<Outcome, P::Error> {
    let Some(residuals) = problem.residuals(&x)? else {
        return Ok(Outcome {
            x,
            residuals: Vec::new(),
            cost: f64::INFINITY,
            initial_cost: f64::INFINITY,
            steps: 0,
            linearisations: 0,
        });
    };
    let cost = dot(&residuals, &residuals);
    let mut state = Outcome {
        x,
        residuals,
        cost,
        initial_cost: cost,
        steps: 0,
        linearisations: 0,
    };
    let mut damping = settings.initial_damping;
    let mut linear: Option<P::Linear> = None;
    for _ in 0..settings.max_trials {
        // Asked to stop (Ctrl-C, SIGTERM): the best point so far is the outcome.
        if crate::stop::requested() {
            break;
        }
        if linear.is_none() {
            if state.linearisations >= settings.max_linearisations {
                break;
            }
            state.linearisations += 1;
            linear = Some(problem.linearise(&state.x, &state.residuals)?);
        }
        let Some(system) = &linear else { break };
        let Some(step) = system.step(damping) else {
            damping *= settings.singular_factor;
            if damping > settings.max_damping {
                break;
            }
            continue;
        };
        let trial: Vec<f64> = (state.x.iter().zip(&step))
            .map(|(x, d)| x + d.clamp(-settings.max_move, settings.max_move))
            .collect();
        let improved = problem
            .residuals(&trial)?
            .map(|r| (dot(&r, &r), r))
            .filter(|(cost, _)| cost.is_finite() && *cost < state.cost);
        let Some((cost, residuals)) = improved else {
            damping *= settings.reject_factor;
            if damping > settings.max_damping {
                break;
            }
            continue;
        };
        let decrease = state.cost - cost;
        let converged = decrease <= settings.tolerance * state.cost || cost == 0.0;
        (state.x, state.residuals, state.cost) = (trial, residuals, cost);
        state.steps += 1;
        linear = None;
        damping = (damping / settings.accept_factor).max(settings.min_damping);
        if converged {
            break;
        }
    }
    Ok(state)
}

/// A Jacobian for a [`Function`].
#[derive(Clone, Copy)]
pub enum Jacobian<'a> {
    /// Forward differences with step `step * max(|x_j|, 1)`, columns in parallel; a column
    /// whose shifted residuals fail tries the backward difference, then is zero.
    ForwardDifferences {
        /// Relative step.
        step: f64,
    },
    /// The analytic Jacobian: its columns (one per unknown) at `x`.
    Analytic(&'a (dyn Fn(&[f64]) -> Vec<Vec<f64>> + Sync)),
}

/// A least-squares problem given by a residual closure (`None` where the residuals cannot
/// be computed) and its Jacobian, with dense Gauss–Newton steps.
#[derive(Clone, Copy)]
pub struct Function<'a> {
    /// The residuals.
    pub residuals: &'a (dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    /// Their Jacobian.
    pub jacobian: Jacobian<'a>,
    /// How damping enters the normal equations.
    pub damping: Damping,
}

impl Function<'_> {
    /// [`minimise`] from `x`.
    pub fn minimise(&self, x: Vec<f64>, settings: &Settings) -> Outcome {
        let mut problem = *self;
        match minimise(&mut problem, x, settings) {
            Ok(outcome) => outcome,
            Err(never) => match never {},
        }
    }
}

impl Problem for Function<'_> {
    type Error = Infallible;
    type Linear = GaussNewton;

    fn residuals(&mut self, x: &[f64]) -> Result<Option<Vec<f64>>, Infallible> {
        Ok((self.residuals)(x))
    }

    fn linearise(&mut self, x: &[f64], residuals: &[f64]) -> Result<GaussNewton, Infallible> {
        let columns = match self.jacobian {
            Jacobian::ForwardDifferences { step } => {
                forward_differences(self.residuals, x, residuals, step)
            }
            Jacobian::Analytic(jacobian) => jacobian(x),
        };
        Ok(GaussNewton::new(&columns, residuals, self.damping))
    }
}

/// The difference step for an unknown at `x`: `relative * max(|x|, 1)`.
pub fn difference_step(x: f64, relative: f64) -> f64 {
    relative * x.abs().max(1.0)
}

/// Forward-difference Jacobian columns of `residuals` at `x` (whose residuals are `r`), one
/// per unknown, computed in parallel: steps [`difference_step`]`(x_j, step)`; a column whose
/// shifted residuals fail tries the backward difference, then is zero.
pub fn forward_differences(
    residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    x: &[f64],
    r: &[f64],
    step: f64,
) -> Vec<Vec<f64>> {
    (0..x.len())
        .into_par_iter()
        .map(|j| {
            let h = difference_step(x[j], step);
            let shifted = |sign: f64| {
                let mut moved = x.to_vec();
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

/// The central difference `(f(delta) - f(-delta)) / (2 delta)`, entry by entry, of a
/// vector function of a shift.
pub fn central_difference<E>(
    mut shifted: impl FnMut(f64) -> Result<Vec<f64>, E>,
    delta: f64,
) -> Result<Vec<f64>, E> {
    let up = shifted(delta)?;
    let down = shifted(-delta)?;
    Ok(up
        .iter()
        .zip(&down)
        .map(|(u, d)| (u - d) / (2.0 * delta))
        .collect())
}

/// Linearised (Gauss–Newton) standard errors of the first `count` unknowns of a fit with
/// Jacobian `columns` (one per unknown; every unknown counts, the rest as nuisances) and
/// residuals `residuals` at its minimum: `sqrt(s^2 [(J'J)^-1]_ii)` with
/// `s^2 = |r|^2 / max(m - q, 1)` for `m` residuals and `q` unknowns. Every error is
/// infinite when `J'J` is not numerically positive definite (some direction is not
/// determined by the data), and an error is infinite where its variance is not a finite
/// non-negative number.
pub fn standard_errors(columns: &[Vec<f64>], residuals: &[f64], count: usize) -> Vec<f64> {
    let unknowns = columns.len();
    let (normal, _) = gauss_newton_system(columns, residuals);
    let freedom = residuals.len().saturating_sub(unknowns).max(1) as f64;
    let variance = dot(residuals, residuals) / freedom;
    let factor = Cholesky::factor(&normal, unknowns);
    (0..count.min(unknowns))
        .map(|i| {
            factor
                .as_ref()
                .map(|f| f.inverse_column(i)[i] * variance)
                .filter(|v| v.is_finite() && *v >= 0.0)
                .map_or(f64::INFINITY, f64::sqrt)
        })
        .collect()
}

/// [`standard_errors`] where the residuals fall into groups of their own noise level (the
/// measured states of a fit, each z-scored by its spread, not by its noise): each group's
/// variance `s_g^2 = |r_g|^2 / max(m_g - q m_g / m, 1)` (its share of the degrees of
/// freedom), and the covariance the sandwich `(J'J)^-1 (sum_g s_g^2 J_g'J_g) (J'J)^-1`.
/// With one group it is [`standard_errors`]. `groups[i]` is residual `i`'s group.
#[cfg(test)]
pub fn grouped_standard_errors(
    columns: &[Vec<f64>],
    residuals: &[f64],
    groups: &[usize],
    count: usize,
) -> Vec<f64> {
    let covariance = grouped_covariance(columns, residuals, groups);
    let mut errors = marginal_errors(covariance.as_deref(), columns.len());
    errors.truncate(count);
    errors
}

/// The square roots of the diagonal of an `n x n` covariance (row-major): the marginal
/// standard errors; infinite where the covariance is missing (undetermined) or an entry is
/// not a finite non-negative number.
pub fn marginal_errors(covariance: Option<&[f64]>, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            covariance
                .map(|c| c[i * n + i])
                .filter(|v| v.is_finite() && *v >= 0.0)
                .map_or(f64::INFINITY, f64::sqrt)
        })
        .collect()
}

/// The covariance of the unknowns whose standard errors [`grouped_standard_errors`] gives:
/// the sandwich `(J'J)^-1 (sum_g s_g^2 J_g'J_g) (J'J)^-1` (`n x n`, row-major, for `n`
/// columns); `None` when `J'J` is not numerically positive definite.
#[cfg(test)]
pub fn grouped_covariance(
    columns: &[Vec<f64>],
    residuals: &[f64],
    groups: &[usize],
) -> Option<Vec<f64>> {
    let variances = group_variances(residuals, groups, columns.len());
    sandwich(columns, |j| variances[groups[j]])
}

/// [`grouped_covariance`] where the noise within a group may grow with what a cell reads:
/// residual `j`'s variance is its group's `s_g^2` times `shapes[j]` ([`variance_shapes`],
/// mean 1 over each group).
pub fn shaped_covariance(
    columns: &[Vec<f64>],
    residuals: &[f64],
    (groups, shapes): (&[usize], &[f64]),
) -> Option<Vec<f64>> {
    let variances = group_variances(residuals, groups, columns.len());
    sandwich(columns, |j| variances[groups[j]] * shapes[j])
}

/// Per residual, the share of its group's variance its cell carries when the variance
/// within a group is `a + b v^2` for `v` what the cell reads (`values[j]`): `a, b >= 0`
/// fitted to the squared residuals by least squares, so the data decide between absolute
/// noise (`b = 0`), relative noise (`a = 0`) and a mix; scaled to mean 1 over the group.
/// Residuals without a value (`None`: noise declared and already weighted out) and groups
/// whose fit leaves no variance get 1.
pub fn variance_shapes(residuals: &[f64], groups: &[usize], values: &[Option<f64>]) -> Vec<f64> {
    let count = groups.iter().copied().max().map_or(0, |g| g + 1);
    let mut shapes = vec![1.0; residuals.len()];
    for group in 0..count {
        let members: Vec<usize> = (0..residuals.len())
            .filter(|&j| groups[j] == group && values[j].is_some_and(f64::is_finite))
            .collect();
        let points: Vec<(f64, f64)> = (members.iter())
            .map(|&j| (values[j].unwrap_or(0.0).powi(2), residuals[j].powi(2)))
            .collect();
        let (a, b) = variance_line(&points);
        let raw: Vec<f64> = points.iter().map(|(x, _)| a + b * x).collect();
        let mean = raw.iter().sum::<f64>() / raw.len().max(1) as f64;
        if mean > 0.0 && mean.is_finite() {
            for (&j, v) in members.iter().zip(raw) {
                shapes[j] = v / mean;
            }
        }
    }
    shapes
}

/// The line `y = a + b x` through `(x, y)` points by least squares with `a, b >= 0` (the
/// better of the two one-sided fits where the free fit breaks a bound).
fn variance_line(points: &[(f64, f64)]) -> (f64, f64) {
    let n = points.len() as f64;
    if points.len() < 3 {
        return (1.0, 0.0);
    }
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let sxx: f64 = points.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let a = my - b * mx;
    if a >= 0.0 && b >= 0.0 {
        return (a, b);
    }
    let cost =
        |(a, b): (f64, f64)| -> f64 { points.iter().map(|(x, y)| (y - a - b * x).powi(2)).sum() };
    let x4: f64 = points.iter().map(|(x, _)| x * x).sum();
    let through_zero = (
        0.0,
        points.iter().map(|(x, y)| x * y).sum::<f64>().max(0.0) / x4.max(f64::MIN_POSITIVE),
    );
    let flat = (my.max(0.0), 0.0);
    if cost(through_zero) < cost(flat) {
        through_zero
    } else {
        flat
    }
}

/// The covariance `(J'J)^-1 (J' D J) (J'J)^-1` of a least-squares fit with Jacobian
/// `columns` whose residual `j` has variance `variance(j)` (`D` diagonal): `n x n`,
/// row-major, for `n` columns; `None` when `J'J` is not numerically positive definite.
pub fn sandwich(columns: &[Vec<f64>], variance: impl Fn(usize) -> f64) -> Option<Vec<f64>> {
    let n = columns.len();
    let rows = columns.first().map_or(0, Vec::len);
    let (normal, _) = gauss_newton_system(columns, &vec![0.0; rows]);
    let factor = Cholesky::factor(&normal, n)?;
    // Column `i` of `(J'J)^-1` (symmetric: also its row `i`).
    let inverse: Vec<Vec<f64>> = (0..n).map(|i| factor.inverse_column(i)).collect();
    let mut covariance = vec![0.0; n * n];
    for j in 0..rows {
        // Row `j` of `J (J'J)^-1`, weighted by its residual's variance.
        let lever: Vec<f64> = (inverse.iter())
            .map(|row| (columns.iter().zip(row)).map(|(c, d)| c[j] * d).sum())
            .collect();
        let weight = variance(j);
        for a in 0..n {
            for b in 0..n {
                covariance[a * n + b] += weight * lever[a] * lever[b];
            }
        }
    }
    Some(covariance)
}

/// Per group, `|r_g|^2 / max(m_g - q m_g / m, 1)`.
fn group_variances(residuals: &[f64], groups: &[usize], unknowns: usize) -> Vec<f64> {
    let count = groups.iter().copied().max().map_or(0, |g| g + 1);
    let mut sums = vec![(0.0, 0usize); count];
    for (r, &g) in residuals.iter().zip(groups) {
        sums[g].0 += r * r;
        sums[g].1 += 1;
    }
    let m = residuals.len().max(1) as f64;
    (sums.into_iter())
        .map(|(sum, cells)| {
            let freedom = cells as f64 - unknowns as f64 * cells as f64 / m;
            sum / freedom.max(1.0)
        })
        .collect()
}
