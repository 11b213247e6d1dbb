//! What a correct model's held-out error would be: not the noise alone. A free run scored
//! on held-out cells carries two more spreads a correct model has too: its params were
//! fitted on a few noisy training cells, and it starts from a measured first row that is
//! as noisy as any other cell.
//!
//! The params' spread is the one they would have were the model correct: every training
//! residual its cell's noise ([`crate::numeric::lm::sandwich`]; the residuals of a misfit
//! would take the misfit for noise), plus what the noise of the measured first rows the
//! training runs start from moves the fit by (`G = -(J'J)^-1 J' S` per start, for `S` the
//! residuals' derivatives by it; over the starts' noise, `G diag(sigma^2) G'`). The params
//! are then drawn (Gaussian in the fit's transformed coordinates, the training starts' noise
//! drawn with them), the scored runs' measured first cells from their noise, and the drawn
//! runs compared with the fitted ones: the mean squared
//! z-scored deviation over the scored cells is the *spread* a correct model adds to the
//! noise floor. Drawn rather than linearised: near a switch (a sugar running out) a start
//! moves a run far more than its derivative says. A tail scored after its own training part
//! starts from the same drawn first cells the drawn fit was fitted from (drawn jointly:
//! counted once); fitted starts keep their fitted values, as declared starts keep theirs.

use super::fitter::{from_theta, thetas, Objective};
use super::simulate::{Run, Simulator};
use super::split::{Split, Start};
use super::unknowns::Unknowns;
use crate::numeric::linalg::{dot, gauss_newton_system, Cholesky};
use crate::numeric::lm::sandwich;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Draws of the fitted params and the measured starts whose runs give the spread (in
/// antithetic pairs).
pub const DRAWS: usize = 128;

/// The spread a correct model's free runs add to the noise at the scored cells (mean
/// squared z-scored deviation), given the fitted unknowns `x` of `simulator` on `split`
/// (`fixed`: those held, out of the covariance) and each measured state's noise variance
/// in z-scored units (`noise`): the mean over [`DRAWS`] draws (from `seed`) of the params
/// (Gaussian in the fit's transformed coordinates, with their covariance) and of the
/// measured first rows the scored runs start from (each cell plus its noise) of the
/// squared deviation of the drawn runs from the fitted ones. The runs are drawn, not
/// linearised: a start near a switch (a sugar running out) moves a run far more than its
/// derivative says. `None` when it cannot be computed: a fitted run fails, the training
/// data leave the params' covariance undetermined, or every draw's runs fail.
pub fn held_out_spread(
    (split, simulator): (&Split, &Simulator),
    (unknowns, x, fixed): (&Unknowns, &[f64], &[bool]),
    (noise, seed): (&[f64], u64),
) -> Option<f64> {
    let params = simulator.params().min(x.len());
    let free: Vec<usize> = (0..x.len()).filter(|&i| !fixed[i]).collect();
    let (covariance, starts) = params_covariance(split, simulator, (unknowns, x), (&free, noise))?;
    let free_params: Vec<usize> = free.iter().copied().filter(|&i| i < params).collect();
    let block = leading_block(&covariance, free.len(), free_params.len());
    let factor = Cholesky::factor(&block, free_params.len())?;
    let nominal = scored_runs((split, simulator), x, None)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let theta = thetas(&unknowns.constraints, x);
    let measured = split.normalisation.state_std.len();
    let (mut total, mut draws) = (0.0, 0usize);
    let count = free_params.len() + starts.len() + split.records.len() * measured;
    let mut z: Vec<f64> = Vec::new();
    for draw in 0..DRAWS {
        // Antithetic pairs: every second draw is the one before it mirrored, which cancels
        // the odd orders of the runs' response and halves the draws' scatter.
        z = if draw % 2 == 0 {
            (0..count).map(|_| rng.sample(StandardNormal)).collect()
        } else {
            z.iter().map(|v| -v).collect()
        };
        let (params_z, rest) = z.split_at(free_params.len());
        let (starts_z, held_z) = rest.split_at(starts.len());
        let mut shift = factor.times(params_z);
        // The first cells of every run: each training start's noise moves the params (and
        // is where a tail scored on after it starts); a held-out run's own, independently.
        let mut offsets: Vec<f64> = (0..split.records.len() * measured)
            .map(|i| {
                held_z[i] * first_cell_variance(split, i / measured, i % measured, noise).sqrt()
            })
            .collect();
        for (start, &zs) in starts.iter().zip(starts_z) {
            let delta = zs * start.variance.sqrt();
            offsets[start.record * measured + start.state] = delta;
            for (s, g) in shift.iter_mut().zip(&start.response) {
                *s += g * delta;
            }
        }
        let mut drawn = x.to_vec();
        for (&i, shift) in free_params.iter().zip(shift) {
            drawn[i] = from_theta(unknowns.constraints[i], theta[i] + shift);
        }
        let Some(runs) = scored_runs((split, simulator), &drawn, Some(&offsets)) else {
            continue;
        };
        total += squared_deviation(split, &nominal, &runs);
        draws += 1;
    }
    let spread = total / draws as f64;
    (draws > 0 && spread.is_finite()).then_some(spread)
}

/// The free runs of every scored part with the unknowns `x`, the measured first cells they
/// start from moved by `offsets` (in the state's unit, per record and measured state; none:
/// the cells as measured); `None` when a run fails.
fn scored_runs(
    (split, simulator): (&Split, &Simulator),
    x: &[f64],
    offsets: Option<&[f64]>,
) -> Option<Vec<Run>> {
    let mut simulator = simulator.clone();
    simulator.set_params(x);
    let params = simulator.params().min(x.len());
    let hidden = simulator.hidden_count();
    let measured = split.normalisation.state_std.len();
    (split.scored())
        .map(|(index, record, rows)| {
            let mut overrides = split.overrides(index, &x[params..], hidden);
            for (k, start) in overrides.iter_mut().enumerate().take(measured) {
                let offset = offsets.and_then(|o| o.get(index * measured + k)).copied();
                let cell = record.states[k].first().copied().flatten();
                if let (Start::Cell, Some(cell), Some(offset)) =
                    (split.starts[index][k], cell, offset)
                {
                    *start = Some(cell + offset);
                }
            }
            simulator.free_run(record, &overrides, rows.end).ok()
        })
        .collect()
}

/// A measured first cell a training run starts from ([`Start::Cell`]): whose it is, its
/// noise variance, and how its noise moves the fitted free unknowns.
struct TrainingStart {
    /// The record.
    record: usize,
    /// The measured state.
    state: usize,
    /// Its noise variance, in the state's unit squared.
    variance: f64,
    /// The derivative of the fitted free unknowns (transformed) by the cell:
    /// `-(J'J)^-1 J' s` for `s` the training residuals' derivatives by it.
    response: Vec<f64>,
}

/// The covariance of the free unknowns `free` in transformed coordinates (`n x n` for
/// `n = free.len()`, the free params first as `free` lists them) from the noise of the
/// training cells (the sandwich of the training residuals), and the training starts with
/// how their noise moves the fit (`G = -(J'J)^-1 J' S` for `S` the residuals' derivatives
/// by those starts: drawn with the starts, so that a tail scored after its own training
/// part starts where the drawn fit started). `noise` as in [`held_out_spread`].
fn params_covariance(
    split: &Split,
    simulator: &Simulator,
    (unknowns, x): (&Unknowns, &[f64]),
    (free, noise): (&[usize], &[f64]),
) -> Option<(Vec<f64>, Vec<TrainingStart>)> {
    let objective = Objective { simulator, split };
    let theta = thetas(&unknowns.constraints, x);
    let residuals = objective.residuals(x)?;
    let all = objective.theta_jacobian(&unknowns.constraints, &theta);
    let columns: Vec<Vec<f64>> = free.iter().map(|&i| all[i].clone()).collect();
    if columns.iter().any(|c| c.len() != residuals.len()) {
        return None;
    }
    // Under a correct model each residual is its cell's noise (a misfit's residuals would
    // take the misfit for noise and the params for uncertain).
    let variances = residual_variances(&objective, noise);
    if variances.len() != residuals.len() {
        return None;
    }
    let covariance = sandwich(&columns, |j| variances[j])?;
    let n = columns.len();
    let (normal, _) = gauss_newton_system(&columns, &residuals);
    let factor = Cholesky::factor(&normal, n)?;
    let mut starts = start_columns(&objective, x, noise)?;
    for start in &mut starts {
        let projected: Vec<f64> = columns.iter().map(|c| dot(c, &start.response)).collect();
        start.response = factor.solve(&projected).iter().map(|g| -g).collect();
    }
    let finite = covariance
        .iter()
        .chain(starts.iter().flat_map(|s| &s.response));
    finite
        .into_iter()
        .all(|v| v.is_finite())
        .then_some((covariance, starts))
}

/// Per measured first cell a training run starts from ([`Start::Cell`]): the derivatives
/// of the training residuals by it (zero outside its experiment; in
/// [`TrainingStart::response`], until [`params_covariance`] turns them into the fit's) and
/// its noise variance in the state's unit squared.
fn start_columns(objective: &Objective, x: &[f64], noise: &[f64]) -> Option<Vec<TrainingStart>> {
    let split = objective.split;
    let mut simulator = objective.simulator.clone();
    simulator.set_params(x);
    let params = simulator.params().min(x.len());
    let hidden = simulator.hidden_count();
    let total = split.training_cells();
    let (mut offset, mut out) = (0, Vec::new());
    for (index, record, rows) in split.training() {
        let cells = super::split::cells_in(record, rows.clone());
        let from_cells: Vec<usize> = (0..record.states.len())
            .filter(|&k| matches!(split.starts[index][k], Start::Cell))
            .collect();
        let overrides = split.overrides(index, &x[params..], hidden);
        let run = simulator.sensitive_run(record, &overrides, rows.end, &from_cells);
        let (_, s) = run.ok()?;
        for (c, &k) in from_cells.iter().enumerate() {
            let block = objective.record_residuals(record, rows.clone(), |row, j| {
                s.column_at(row, j)[params + c]
            });
            let mut column = vec![0.0; total];
            column[offset..offset + cells].copy_from_slice(&block);
            out.push(TrainingStart {
                record: index,
                state: k,
                variance: first_cell_variance(split, index, k, noise),
                response: column,
            });
        }
        offset += cells;
    }
    Some(out)
}

/// The noise variance of state `k`'s first cell in record `index`, in its unit squared
/// ([`cell_variance`]; an unmeasured first cell is not a start read from the data).
fn first_cell_variance(split: &Split, index: usize, k: usize, noise: &[f64]) -> f64 {
    let cell = split.records[index].states[k].first().copied().flatten();
    cell_variance(split, k, cell.unwrap_or(0.0), noise)
}

/// The noise variance of a cell of column `k` (a measured state or an observable) reading
/// `value`, in its unit squared: the declared noise at that value; else the level estimated from the data (`noise`,
/// z-scored, pooled over the state's training cells) taken as relative: spread over the
/// cells in proportion to their squares (on the training cells it averages the pooled
/// level). An assay's error grows with what it reads: the pooled level taken at an
/// inoculum ten times below the state's typical value would call the inoculum unknown to
/// within several times itself. Where the error is absolute, the model should declare it
/// (`noise X = 0.05`): a pooled level cannot tell the two apart.
fn cell_variance(split: &Split, k: usize, value: f64, noise: &[f64]) -> f64 {
    let norm = &split.normalisation;
    match &split.declared[k] {
        Some((declared, _)) => declared.sigma(value).powi(2),
        None => {
            let (mean, std) = (norm.column_mean(k), norm.column_std(k));
            let pooled = noise[k] * std.powi(2);
            let mean_square = mean.powi(2) + std.powi(2);
            if mean_square > 0.0 {
                pooled * value * value / mean_square
            } else {
                pooled
            }
        }
    }
}

/// Per training residual (in the fits' order), its variance were the model correct: its
/// cell's noise ([`cell_variance`]) weighted and z-scored as the residual is
/// ([`Objective::record_residuals`] of the noise's standard deviation, squared).
fn residual_variances(objective: &Objective, noise: &[f64]) -> Vec<f64> {
    let split = objective.split;
    let sigma = |record: &crate::record::Record, row: usize, k: usize| {
        let value = record.column(k)[row].unwrap_or(0.0);
        cell_variance(split, k, value, noise).sqrt()
    };
    (split.training())
        .flat_map(|(_, record, rows)| {
            objective.record_residuals(record, rows, |row, k| sigma(record, row, k))
        })
        .map(|r| r * r)
        .collect()
}

/// The leading `m x m` block of the `n x n` matrix `c`.
fn leading_block(c: &[f64], n: usize, m: usize) -> Vec<f64> {
    (0..m * m).map(|i| c[(i / m) * n + i % m]).collect()
}

/// The sum over the scored cells of the squared z-scored deviation of `runs` from
/// `nominal`, divided by the number of scored cells.
fn squared_deviation(split: &Split, nominal: &[Run], runs: &[Run]) -> f64 {
    let norm = &split.normalisation;
    let (mut sum, mut cells) = (0.0, 0usize);
    for ((_, record, rows), (nominal, run)) in split.scored().zip(nominal.iter().zip(runs)) {
        for row in rows {
            for (k, column) in record.columns().enumerate() {
                if column[row].is_some() {
                    let deviation = run.column(row, k) - nominal.column(row, k);
                    sum += (deviation / norm.column_std(k)).powi(2);
                    cells += 1;
                }
            }
        }
    }
    sum / cells.max(1) as f64
}

#[cfg(test)]
#[path = "tests_predictive.rs"]
mod tests;
