//! What the data cannot decide about a fit: a standard error for every fitted unknown, an
//! identifiability flag, and the direction in which the fit is free.
//!
//! At the fit's minimum, with `J` the Jacobian of the training residuals in transformed
//! coordinates (`theta`, from the free runs' forward sensitivities), the linearised covariance
//! is the sandwich `(J'J)^-1 (J' D J) (J'J)^-1`: `D` each cell's noise variance, its
//! state's residual variance `s_k^2` (with its share of the degrees of freedom; each
//! state's cells are z-scored by its spread, not by its noise, so one pooled `s^2` would
//! mis-state every error) spread over the state's cells as `a + b v^2` for `v` what a cell
//! reads, fitted to the squared residuals ([`crate::numeric::lm::variance_shapes`]:
//! relative noise puts most of it on the largest cells, which carry most of the weight);
//! the measured first cells the training runs start from are taken as exact and their
//! noise is not counted (fitted starts, [`super::split::Start::CellFitted`], are unknowns
//! with their noise in the sandwich). An
//! unknown's standard
//! error is its marginal one times the slope of its transform. It is *identified* when the
//! error is below [`super::IDENTIFIABILITY_LIMIT`] of its value (the rule `gbc train` applies to
//! its params). When an unknown is not identified, the eigenvector of `J'J` (scaled to unit
//! diagonal) with the smallest eigenvalue is the direction along which the training error
//! barely changes: moving the params that way (e.g. two params up and down together, in log
//! units) gives the same trajectory. Free-run residuals are correlated in time, so the
//! errors measure how sharply the data pin the fit, not confidence intervals.

use super::fitter::{slope, thetas, values, Objective};
use super::summary::{FitSummary, ParamEstimate};
use crate::ir::Constraint;
use crate::numeric::linalg::gauss_newton_system;
use crate::numeric::lm::{marginal_errors, shaped_covariance, variance_shapes};
use crate::numeric::symmetric_eigen;

/// Components of the free direction below this (of the largest) are left out.
const SMALL_COMPONENT: f64 = 0.05;

/// The uncertainty of the fit at `x` (constrained values; `names` one per unknown) and its
/// information criteria, into a [`FitSummary`] (starts and seconds left at 0). Unknowns
/// where `fixed` is set were held (pinned): they count in neither the criteria nor the
/// uncertainty, are listed in `pinned`, and their estimates are `held` with no standard
/// error.
pub fn summarise(
    objective: &Objective,
    constraints: &[Constraint],
    x: &[f64],
    (names, fixed): (&[String], &[bool]),
) -> FitSummary {
    let is_fixed = |i: usize| fixed.get(i).copied().unwrap_or(false);
    let free: Vec<usize> = (0..x.len()).filter(|&i| !is_fixed(i)).collect();
    let pinned: Vec<(String, f64)> = (0..x.len())
        .filter(|&i| is_fixed(i))
        .map(|i| (names[i].clone(), x[i]))
        .collect();
    let cells = objective.split.training_cells();
    let theta = thetas(constraints, x);
    let residuals = |theta: &[f64]| objective.residuals(&values(constraints, theta));
    let Some(r) = residuals(&theta) else {
        return FitSummary {
            gap_train: f64::INFINITY,
            aic: f64::INFINITY,
            bic: f64::INFINITY,
            unknowns: free.len(),
            pinned,
            ..FitSummary::default()
        };
    };
    let gap: f64 = r.iter().map(|v| v * v).sum();
    let (aic, bic) = criteria(gap, cells, free.len());
    let all = objective.theta_jacobian(constraints, &theta);
    let columns: Vec<Vec<f64>> = free.iter().map(|&i| all[i].clone()).collect();
    let free_errors = standard_errors(objective, (&columns, &r));
    let mut errors = vec![f64::NAN; x.len()];
    for (&i, &e) in free.iter().zip(&free_errors) {
        errors[i] = e;
    }
    let free_names: Vec<String> = free.iter().map(|&i| names[i].clone()).collect();
    let estimates: Vec<ParamEstimate> = (0..x.len())
        .map(|i| {
            if is_fixed(i) {
                return ParamEstimate::held_at(names[i].clone(), x[i]);
            }
            let std_error = errors[i] * slope(constraints[i], theta[i]).abs();
            ParamEstimate::fitted(names[i].clone(), x[i], std_error)
        })
        .collect();
    let free_direction = if (estimates.iter()).all(|e| e.held || e.identified) {
        Vec::new()
    } else {
        free_direction(&columns, &free_names)
    };
    FitSummary {
        estimates,
        free_direction,
        gap_train: gap,
        aic,
        bic,
        unknowns: free.len(),
        starts: 0,
        seconds: 0.0,
        pinned,
    }
}

/// Akaike's and Schwarz's criteria of a fit with training gap `gap` (mean squared
/// normalised residual) over `cells` cells and `unknowns` fitted unknowns.
pub fn criteria(gap: f64, cells: usize, unknowns: usize) -> (f64, f64) {
    let n = cells.max(1) as f64;
    let k = unknowns as f64;
    let fit = n * gap.max(f64::MIN_POSITIVE).ln();
    (fit + 2.0 * k, fit + k * n.ln())
}

/// The eigenvector of the scaled `J'J` with the smallest eigenvalue, mapped back to
/// transformed coordinates and normalised to a largest component of 1 (sign: the largest
/// positive), components below [`SMALL_COMPONENT`] left out, largest first.
pub fn free_direction(columns: &[Vec<f64>], names: &[String]) -> Vec<(String, f64)> {
    let n = columns.len();
    if n == 0 {
        return Vec::new();
    }
    let (normal, _) = gauss_newton_system(columns, &vec![0.0; columns[0].len()]);
    let scale: Vec<f64> = (0..n)
        .map(|i| normal[i * n + i].sqrt().max(1e-300))
        .collect();
    let scaled: Vec<f64> = (0..n * n)
        .map(|index| normal[index] / (scale[index / n] * scale[index % n]))
        .collect();
    let (_, vectors) = symmetric_eigen(&scaled, n);
    let Some(vector) = vectors.first() else {
        return Vec::new();
    };
    let raw: Vec<f64> = (0..n).map(|i| vector[i] / scale[i]).collect();
    let largest = raw
        .iter()
        .copied()
        .fold(0.0_f64, |m, v| if v.abs() > m.abs() { v } else { m });
    if largest == 0.0 || !largest.is_finite() {
        return Vec::new();
    }
    let mut direction: Vec<(String, f64)> = (names.iter().zip(&raw))
        .map(|(name, v)| (name.clone(), v / largest))
        .filter(|(_, v)| v.abs() >= SMALL_COMPONENT)
        .collect();
    direction.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    direction
}

/// The standard errors of the free unknowns (transformed coordinates) at `x`: the sandwich
/// of the training residuals `r` with Jacobian `columns` (each measured state's residual
/// variance spread over its cells as their noise grows with what they read where it is not
/// declared, [`variance_shapes`]: relative, absolute or a mix, as the residuals say);
/// infinite where the covariance is undetermined.
fn standard_errors(objective: &Objective, (columns, r): (&[Vec<f64>], &[f64])) -> Vec<f64> {
    let split = objective.split;
    let states = split.training_cell_states();
    let cells: Vec<(usize, usize, usize, f64)> = (split.training())
        .flat_map(|(index, record, rows)| {
            rows.flat_map(move |row| {
                (record.columns().enumerate())
                    .filter_map(move |(k, cells)| cells[row].map(|v| (index, row, k, v)))
            })
        })
        .collect();
    let values: Vec<Option<f64>> = (cells.iter())
        .map(|&(_, _, k, v)| split.declared[k].is_none().then_some(v))
        .collect();
    let shapes = variance_shapes(r, &states, &values);
    let covariance = shaped_covariance(columns, r, (&states, &shapes));
    marginal_errors(covariance.as_deref(), columns.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Residuals that see only `a + b` leave the direction `(1, -1)` free.
    #[test]
    fn a_sum_seen_alone_leaves_its_difference_free() {
        let columns = vec![vec![1.0, 2.0, 3.0], vec![1.0, 2.0, 3.0 + 1e-9]];
        let names = vec!["a".to_string(), "b".to_string()];
        let direction = free_direction(&columns, &names);
        assert_eq!(direction.len(), 2);
        assert!((direction[0].1.abs() - 1.0).abs() < 1e-6);
        assert!(
            (direction[0].1 + direction[1].1).abs() < 1e-6,
            "{direction:?}"
        );
    }

    #[test]
    fn criteria_penalise_unknowns() {
        let (aic, bic) = criteria(0.01, 1000, 3);
        let fit = 1000.0 * 0.01f64.ln();
        assert!((aic - (fit + 6.0)).abs() < 1e-9);
        assert!((bic - (fit + 3.0 * 1000f64.ln())).abs() < 1e-9);
    }
}
