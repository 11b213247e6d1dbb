//! Fitting a mechanistic model's params (and the starts of measured states that no cell or
//! declaration gives, [`super::split::Start::Fitted`]) to the training parts of every
//! experiment: Levenberg–Marquardt on the z-scored free-run residuals at the measured
//! training cells, with the exact Jacobian from the free runs' forward sensitivities
//! ([`super::sensitivity`]; the experiments in parallel) through the shared driver
//! ([`crate::numeric::lm`]), in transformed coordinates so that constraints always
//! hold (`positive`: `p = exp(theta)`; `in [lo, hi]`: `p = lo + (hi - lo) sigmoid(theta)`;
//! fitted starts are free).
//!
//! **Starts until no new ground.** The first start is the given one (declared values, or a
//! warm start); random starts around it follow in rounds run side by side, and the search
//! stops, after [`MIN_STARTS`], at the first round that neither lowers the best training
//! gap nor leaves it reached by fewer than two starts (within [`AGREE`]); the budget caps
//! it. Two starts agreeing is not enough on its own: two can agree on a poor basin. A
//! landscape with one basin costs [`MIN_STARTS`] fits, a rugged one gets the whole budget.
//! Unknowns can be held fixed (a direction the data leave free, pinned).

use super::simulate::Simulator;
use super::split::Split;
use crate::eval::sigmoid;
use crate::ir::Constraint;
use crate::numeric::lm::{Function, Jacobian};
use crate::numeric::{Damping, Settings};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

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
/// The refinement of a free correction stops earlier: at most 20 Jacobians, converged when a
/// step gains at most `1e-5` of the cost (it is a polish of a one-step fit).
const POLISH: Settings = Settings {
    max_linearisations: 20,
    tolerance: 1e-5,
    ..SETTINGS
};
/// Marquardt's scaling, with floors for a coordinate no residual sees.
const DAMPING: Damping = Damping {
    min_diagonal: 1e-12,
    jitter: 1e-14,
    relative_jitter: 0.0,
};
/// Forward-difference step in transformed coordinates.
pub const JACOBIAN_STEP: f64 = 1e-6;
/// Spread of the random restarts in transformed coordinates.
const RESTART_SPREAD: f64 = 0.7;
/// Two starts agree when their training gaps differ by at most this fraction.
pub const AGREE: f64 = 1e-3;

/// A training experiment: its index in the split, the record and its training rows.
type Training<'a> = (usize, &'a crate::record::Record, std::ops::Range<usize>);

/// The free-run error of a model at the training cells of a split.
#[derive(Debug, Clone, Copy)]
pub struct Objective<'a> {
    /// The compiled model.
    pub simulator: &'a Simulator,
    /// The experiments and their training parts.
    pub split: &'a Split,
}

impl Objective<'_> {
    /// Z-scored residuals `(sim - data) / std` at every measured training cell, divided by
    /// the square root of their number so that their squares sum to the training gap;
    /// `None` if a free run fails. `x` holds the params, then the fitted starts. The
    /// experiments run in parallel; the residuals are in training order whatever the
    /// threads do.
    pub fn residuals(&self, x: &[f64]) -> Option<Vec<f64>> {
        let per_record = self.per_record(x, |simulator, (_, record, rows), overrides| {
            let run = simulator.free_run(record, overrides, rows.end).ok()?;
            let deviation = |row: usize, k: usize| {
                run.column(row, k) - record.column(k)[row].unwrap_or(f64::NAN)
            };
            Some(self.record_residuals(record, rows, deviation))
        })?;
        let residuals: Vec<f64> = per_record.into_iter().flatten().collect();
        residuals.iter().all(|r| r.is_finite()).then_some(residuals)
    }

    /// The Jacobian of [`Objective::residuals`] at `x`, one column per unknown, from the
    /// forward sensitivities of every free run (exact to the integration tolerance);
    /// `None` if a run fails.
    pub fn jacobian(&self, x: &[f64]) -> Option<Vec<Vec<f64>>> {
        let params = self.simulator.params().min(x.len());
        let hidden = self.simulator.hidden_count();
        let per_record = self.per_record(x, |simulator, (index, record, rows), overrides| {
            // The sensitivity column of each unknown: a param's own, or the initial value
            // of the state a fitted start belongs to (none: this experiment has no such).
            let fitted = self.split.fitted_indices(index, hidden);
            let initial: Vec<usize> = (0..fitted.len()).filter(|&k| fitted[k].is_some()).collect();
            let run = simulator.sensitive_run(record, overrides, rows.end, &initial);
            let (_, sensitivities) = run.ok()?;
            let column = |unknown: usize| match unknown.checked_sub(params) {
                None => Some(unknown),
                Some(start) => (initial.iter().position(|&k| fitted[k] == Some(start)))
                    .map(|position| params + position),
            };
            let columns: Vec<Vec<f64>> = (0..x.len())
                .map(|unknown| {
                    let column = column(unknown);
                    self.record_residuals(record, rows.clone(), |row, k| {
                        column.map_or(0.0, |c| sensitivities.column_at(row, k)[c])
                    })
                })
                .collect();
            Some(columns)
        })?;
        let mut columns = vec![Vec::new(); x.len()];
        for record in per_record {
            for (column, part) in columns.iter_mut().zip(record) {
                column.extend(part);
            }
        }
        let finite = columns.iter().flatten().all(|v| v.is_finite());
        finite.then_some(columns)
    }

    /// `value(row, k) * weight / std_k / sqrt(cells)` at every measured training cell of `record`
    /// in `rows` (the residuals' order: row by row, column by column: the measured states,
    /// then the observables); with `value` the
    /// simulation's deviation that gives the residuals, and its derivative their Jacobian.
    pub(super) fn record_residuals(
        &self,
        record: &crate::record::Record,
        rows: std::ops::Range<usize>,
        value: impl Fn(usize, usize) -> f64,
    ) -> Vec<f64> {
        let norm = &self.split.normalisation;
        let scale = (self.split.training_cells().max(1) as f64).sqrt();
        let mut out = Vec::new();
        for row in rows {
            for (k, cells) in record.columns().enumerate() {
                if let Some(measured) = cells[row] {
                    let weight = self.split.weight(k, measured);
                    out.push(value(row, k) * weight / norm.column_std(k) / scale);
                }
            }
        }
        out
    }

    /// `work` on every training experiment in parallel (each with its own copy of the
    /// simulator, params set from `x`), in training order; `None` if any fails.
    fn per_record<T: Send>(
        &self,
        x: &[f64],
        work: impl Fn(&mut Simulator, Training, &[Option<f64>]) -> Option<T> + Sync,
    ) -> Option<Vec<T>> {
        use rayon::prelude::*;
        let mut base = self.simulator.clone();
        base.set_params(x);
        let fitted = &x[base.params().min(x.len())..];
        let hidden = base.hidden_count();
        let training: Vec<_> = self.split.training().collect();
        (training.into_par_iter())
            .map(|(index, record, rows)| {
                let mut simulator = base.clone();
                let overrides = self.split.overrides(index, fitted, hidden);
                work(&mut simulator, (index, record, rows), &overrides)
            })
            .collect()
    }

    /// The Jacobian of the residuals in the transformed coordinates `theta` of unknowns
    /// under `constraints`: [`Objective::jacobian`] times each transform's slope; forward
    /// differences where a sensitivity run fails.
    pub fn theta_jacobian(&self, constraints: &[Constraint], theta: &[f64]) -> Vec<Vec<f64>> {
        let x = values(constraints, theta);
        if let Some(mut columns) = self.jacobian(&x) {
            for ((column, &constraint), &t) in columns.iter_mut().zip(constraints).zip(theta) {
                let slope = slope(constraint, t);
                column.iter_mut().for_each(|v| *v *= slope);
            }
            return columns;
        }
        if crate::stop::requested() {
            // Asked to stop: no differences (the fit ends at its next trial).
            return vec![Vec::new(); theta.len()];
        }
        let residuals = |theta: &[f64]| self.residuals(&values(constraints, theta));
        let r = residuals(theta).unwrap_or_default();
        crate::numeric::lm::forward_differences(&residuals, theta, &r, JACOBIAN_STEP)
    }

    /// The training gap at `x`, infinite if a run fails.
    pub fn gap(&self, x: &[f64]) -> f64 {
        self.residuals(x)
            .map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum())
    }
}

/// The result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// The params and fitted starts (constrained values).
    pub x: Vec<f64>,
    /// The training gap there.
    pub gap: f64,
    /// Starts run (the given one and the random ones).
    pub starts: usize,
    /// Starts that reached the best gap (within [`AGREE`]).
    pub agreeing: usize,
    /// The distinct training gaps the starts ended at (within [`AGREE`]), best first: the
    /// basins found.
    pub basins: Vec<f64>,
}

/// Where a fit's search stands after a round of starts, for a progress line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Round {
    /// Starts run so far.
    pub done: usize,
    /// Starts the budget allows at most (the search may stop sooner).
    pub max: usize,
    /// The best training gap so far (infinite while every start failed).
    pub best: f64,
}

/// Told after every round of starts of a fit.
pub type Watch<'a> = &'a (dyn Fn(Round) + Sync);

/// How many starts a fit spends, and who is told how it goes.
#[derive(Clone, Copy)]
pub struct Starts<'a> {
    /// Starts always run.
    pub min: usize,
    /// Starts at most.
    pub max: usize,
    /// Starts run side by side in one round.
    pub round: usize,
    /// Told after every round (none: nobody asks).
    pub watch: Option<Watch<'a>>,
}

impl std::fmt::Debug for Starts<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Starts")
            .field("min", &self.min)
            .field("max", &self.max)
            .field("round", &self.round)
            .field("watched", &self.watch.is_some())
            .finish()
    }
}

impl<'a> Starts<'a> {
    /// At least four starts, at most `1 + restarts`, rounds of one start per thread (two at
    /// least), told to nobody.
    pub fn new(restarts: usize) -> Self {
        let max = restarts + 1;
        Starts {
            min: MIN_STARTS.min(max),
            max,
            round: rayon::current_num_threads().max(2),
            watch: None,
        }
    }

    /// These starts, each round told to `watch`.
    pub fn watched(self, watch: Watch<'a>) -> Self {
        Starts {
            watch: Some(watch),
            ..self
        }
    }
}

/// Starts every fit runs (when its budget allows).
pub const MIN_STARTS: usize = 4;

/// Fits `x` from `start` (constrained values) and random starts around it drawn from a
/// generator seeded with `seed`, in rounds of `starts.round` run side by side, with the
/// unknowns where `fixed` is set held at their start. The search goes on while it finds
/// new ground: it stops, after `starts.min` starts, at the first round that neither
/// lowers the best training gap nor leaves it reached by fewer than two starts; or after
/// `starts.max`. Returns the best.
pub fn fit(
    objective: &Objective,
    constraints: &[Constraint],
    start: &[f64],
    (starts, fixed): (Starts, &[bool]),
    seed: u64,
) -> Fitted {
    let space = Subspace::new(constraints, start, fixed);
    if space.free.is_empty() {
        let gap = objective.gap(start);
        return Fitted {
            x: start.to_vec(),
            gap,
            starts: 1,
            agreeing: 1,
            basins: vec![gap],
        };
    }
    let residuals = |sub: &[f64]| objective.residuals(&values(constraints, &space.full(sub)));
    let jacobian = |sub: &[f64]| {
        let columns = objective.theta_jacobian(constraints, &space.full(sub));
        (space.free.iter())
            .map(|&i| columns[i].clone())
            .collect::<Vec<_>>()
    };
    let mut draws = Draws::new(objective, &space, seed);
    let results = search(starts, &mut draws, &|theta| {
        levenberg_marquardt(&residuals, &jacobian, theta)
    });
    let best = results
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .cloned()
        .unwrap_or((draws.start, f64::INFINITY));
    Fitted {
        x: values(constraints, &space.full(&best.0)),
        gap: best.1,
        starts: results.len(),
        agreeing: agreeing(&results),
        basins: basins(&results),
    }
}

/// The coordinates a fit moves: the start in transformed coordinates and the unknowns not
/// held fixed.
struct Subspace {
    /// The start, every unknown (transformed).
    theta0: Vec<f64>,
    /// The unknowns that move.
    free: Vec<usize>,
}

impl Subspace {
    /// The unknowns of `start` (constrained values) that `fixed` does not hold.
    fn new(constraints: &[Constraint], start: &[f64], fixed: &[bool]) -> Self {
        let theta0 = thetas(constraints, start);
        let free: Vec<usize> = (0..theta0.len())
            .filter(|&i| !fixed.get(i).copied().unwrap_or(false))
            .collect();
        Subspace { theta0, free }
    }

    /// Every unknown (transformed), the free ones at `sub`, the others at the start.
    fn full(&self, sub: &[f64]) -> Vec<f64> {
        let mut theta = self.theta0.clone();
        for (&i, &value) in self.free.iter().zip(sub) {
            theta[i] = value;
        }
        theta
    }
}

/// The starts of a fit's free coordinates: the given one first, then random ones around it.
struct Draws {
    /// The given start.
    start: Vec<f64>,
    /// Per free coordinate, whether it stays at its start (a start read from a measured
    /// cell stays at its cell in every random start).
    pinned: Vec<bool>,
    rng: ChaCha8Rng,
}

impl Draws {
    /// The starts of `space` for `objective`, drawn from a generator seeded with `seed`.
    fn new(objective: &Objective, space: &Subspace, seed: u64) -> Self {
        let start: Vec<f64> = space.free.iter().map(|&i| space.theta0[i]).collect();
        let params = objective.simulator.params();
        let pinned: Vec<bool> = (space.free.iter())
            .map(|&i| i >= params && objective.split.cell_fitted(i - params))
            .collect();
        Draws {
            start,
            pinned,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// The given start (`first`), or a random one around it.
    fn draw(&mut self, first: bool) -> Vec<f64> {
        if first {
            return self.start.clone();
        }
        (self.start.iter().zip(&self.pinned))
            .map(|(&t, &pinned)| {
                let noise: f64 = StandardNormal.sample(&mut self.rng);
                let spread = if pinned { 0.0 } else { RESTART_SPREAD };
                t + spread * noise * t.abs().clamp(1.0, 3.0)
            })
            .collect()
    }
}

/// Runs `minimise` from `draws` in rounds of `starts.round` side by side while the search
/// finds new ground (see [`fit`]); every start's end and its gap, in the order drawn.
fn search(
    starts: Starts,
    draws: &mut Draws,
    minimise: &(dyn Fn(Vec<f64>) -> (Vec<f64>, f64) + Sync),
) -> Vec<(Vec<f64>, f64)> {
    use rayon::prelude::*;
    let mut results: Vec<(Vec<f64>, f64)> = Vec::new();
    while results.len() < starts.max {
        let count = starts.round.min(starts.max - results.len());
        let thetas: Vec<Vec<f64>> = (0..count)
            .map(|k| draws.draw(results.is_empty() && k == 0))
            .collect();
        let before = best_gap(&results);
        let round: Vec<(Vec<f64>, f64)> = thetas.into_par_iter().map(minimise).collect();
        results.extend(round);
        let best = best_gap(&results);
        if let Some(watch) = starts.watch {
            watch(Round {
                done: results.len(),
                max: starts.max,
                best,
            });
        }
        let improved = best < before - AGREE * before.abs();
        if results.len() >= starts.min && !improved && agreeing(&results) >= 2 {
            break;
        }
        if crate::stop::requested() {
            break;
        }
    }
    results
}

/// The best gap of `results` (infinite for none).
fn best_gap(results: &[(Vec<f64>, f64)]) -> f64 {
    results.iter().map(|r| r.1).fold(f64::INFINITY, f64::min)
}

/// How many of the fits reached the best gap (within [`AGREE`]); 0 when none is finite.
fn agreeing(results: &[(Vec<f64>, f64)]) -> usize {
    let best = best_gap(results);
    if !best.is_finite() {
        return 0;
    }
    (results.iter())
        .filter(|r| r.1 <= best + AGREE * best.abs() + 1e-15)
        .count()
}

/// The distinct finite gaps of `results` (within [`AGREE`] of each other), best first.
fn basins(results: &[(Vec<f64>, f64)]) -> Vec<f64> {
    let mut gaps: Vec<f64> = results
        .iter()
        .map(|r| r.1)
        .filter(|g| g.is_finite())
        .collect();
    gaps.sort_by(f64::total_cmp);
    let mut distinct: Vec<f64> = Vec::new();
    for gap in gaps {
        if distinct
            .last()
            .is_none_or(|&last| gap > last + AGREE * last.abs() + 1e-15)
        {
            distinct.push(gap);
        }
    }
    distinct
}

/// The transformed coordinates of constrained values.
pub fn thetas(constraints: &[Constraint], values: &[f64]) -> Vec<f64> {
    (constraints.iter().zip(values))
        .map(|(c, &p)| to_theta(*c, p))
        .collect()
}

/// The constrained values of transformed coordinates.
pub fn values(constraints: &[Constraint], theta: &[f64]) -> Vec<f64> {
    from_thetas(constraints, theta)
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

/// `d value / d theta` of a constrained value at transformed coordinate `theta`.
pub fn slope(constraint: Constraint, theta: f64) -> f64 {
    match constraint {
        Constraint::Free => 1.0,
        Constraint::Positive => theta.exp(),
        Constraint::Bounds(lo, hi) => {
            let s = sigmoid(theta);
            (hi - lo) * s * (1.0 - s)
        }
    }
}

/// A residual function of transformed coordinates (`None` where a run fails).
pub type Residuals<'a> = dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync + 'a;
/// Its Jacobian columns, one per coordinate.
pub type Columns<'a> = dyn Fn(&[f64]) -> Vec<Vec<f64>> + Sync + 'a;

/// Minimises `|r(theta)|^2` from `theta` with the diagnosis's settings and the Jacobian
/// `jacobian` (exact, from sensitivities); returns the minimiser and the minimum (infinite
/// when `r` fails at the start).
pub fn levenberg_marquardt(
    residuals: &Residuals,
    jacobian: &Columns,
    theta: Vec<f64>,
) -> (Vec<f64>, f64) {
    minimise(residuals, Jacobian::Analytic(jacobian), theta, &SETTINGS)
}

/// [`levenberg_marquardt`] with the looser settings of a refinement (a polish), by
/// forward differences, with at most `linearisations` Jacobians.
pub fn polish_within(
    residuals: &Residuals,
    theta: Vec<f64>,
    linearisations: usize,
) -> (Vec<f64>, f64) {
    let jacobian = Jacobian::ForwardDifferences {
        step: JACOBIAN_STEP,
    };
    let settings = Settings {
        max_linearisations: linearisations,
        ..POLISH
    };
    minimise(residuals, jacobian, theta, &settings)
}

fn minimise(
    residuals: &Residuals,
    jacobian: Jacobian,
    theta: Vec<f64>,
    settings: &Settings,
) -> (Vec<f64>, f64) {
    let function = Function {
        residuals,
        jacobian,
        damping: DAMPING,
    };
    let outcome = function.minimise(theta, settings);
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

    #[test]
    fn slopes_are_the_derivatives_of_the_transforms() {
        for (constraint, theta) in [
            (Constraint::Free, 0.3),
            (Constraint::Positive, -1.2),
            (Constraint::Bounds(0.1, 10.0), 0.7),
        ] {
            let h = 1e-6;
            let numeric =
                (from_theta(constraint, theta + h) - from_theta(constraint, theta - h)) / (2.0 * h);
            assert!((slope(constraint, theta) - numeric).abs() < 1e-8 * numeric.abs().max(1.0));
        }
    }

    #[test]
    fn starts_agree_within_the_tolerance_and_basins_are_distinct_gaps() {
        assert_eq!(agreeing(&[(vec![0.0], 1.0)]), 1);
        let results = [
            (vec![0.0], 1.0),
            (vec![1.0], 2.0),
            (vec![2.0], 1.0000001),
            (vec![3.0], f64::INFINITY),
        ];
        assert_eq!(agreeing(&results), 2);
        assert_eq!(basins(&results), vec![1.0, 2.0]);
        assert_eq!(agreeing(&[(vec![0.0], 1.0), (vec![1.0], 1.1)]), 1);
        assert_eq!(agreeing(&[(vec![0.0], f64::NAN)]), 0);
    }
}
