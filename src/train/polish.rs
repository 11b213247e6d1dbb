//! The params after training: a Levenberg-Marquardt polish with the network frozen, and
//! each param's standard error, so that a poorly identified constant is flagged.
//!
//! Both work on the normalised one-step residuals `r = (x_pred(t + h) - x(t + h)) / std`
//! of every measured target cell of every training pair (times the square root of its
//! loss weight), in double precision (a copy of the network), with the Jacobian
//! by central differences in the raw (unconstrained) params.
//!
//! - **Polish**: damped Gauss-Newton steps `(J'J + lambda diag(J'J)) d = -J'r` in the raw
//!   params alone, a step kept only when it lowers `|r|^2`.
//! - **Uncertainty**: the linearised covariance `s^2 (J'J)^-1`, `s^2 = |r|^2 / (n - q)`,
//!   with `J` over the raw params *and* the output-layer biases of every closure (nuisance
//!   parameters: a constant shift of each closure output that could absorb a change of a
//!   param is allowed for). A param's standard error is its marginal one, mapped through
//!   its transform; [`ParamEstimate::well_identified`] says whether it is below
//!   [`IDENTIFIABILITY_LIMIT`] of the value. The residuals of a fitted model are model
//!   error more than noise and are correlated in time, so the error is a measure of how
//!   sharply the data pin the param given the network, not a confidence interval.

use crate::backend::{NamedTensor, Network, Precision, Setup};
use crate::ir;

use super::pairs::PairTable;
use super::TrainError;

/// Relative standard error above which a param counts as poorly identified.
pub const IDENTIFIABILITY_LIMIT: f64 = 0.05;
/// Most Levenberg-Marquardt iterations of the polish.
const MAX_ITERATIONS: usize = 30;
/// Pairs per prediction batch.
const CHUNK: usize = 512;

/// A trained param with its uncertainty.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParamEstimate {
    /// Param name.
    pub name: String,
    /// Trained value.
    pub value: f64,
    /// Linearised standard error (infinite when the data do not determine it).
    pub std_error: f64,
    /// `std_error / |value|`.
    pub relative_error: f64,
    /// Whether `relative_error` is below [`IDENTIFIABILITY_LIMIT`].
    pub well_identified: bool,
}

/// What the polish did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PolishSummary {
    /// Accepted Levenberg-Marquardt steps.
    pub steps: usize,
    /// Mean squared normalised one-step residual before.
    pub loss_before: f64,
    /// And after.
    pub loss_after: f64,
    /// Param values before, in declaration order.
    pub params_before: Vec<f64>,
}

/// The frozen network in double precision and the coordinates varied.
struct Probe<'a> {
    network: Network,
    weights: Vec<NamedTensor>,
    /// `(tensor, index)` of every coordinate: the raw params first, then nuisances.
    coordinates: Vec<(usize, usize)>,
    params: usize,
    table: &'a PairTable,
    inverse_std: Vec<f64>,
    measured: usize,
    state_width: usize,
}

/// Polishes the params of `network` (when `polish`) and estimates their uncertainty on
/// the training pairs `table`.
pub fn polish_and_estimate(
    network: &mut Network,
    model: &ir::Model,
    table: &PairTable,
    setup: &Setup,
    polish: bool,
) -> Result<(Option<PolishSummary>, Vec<ParamEstimate>), TrainError> {
    if model.params.is_empty() || table.is_empty() {
        return Ok((None, Vec::new()));
    }
    let mut probe = Probe::new(network, model, table, setup)?;
    let summary = if polish {
        let summary = probe.polish()?;
        let polished = probe.weights.last().cloned();
        let mut weights = network.weights();
        if let (Some(target), Some(source)) = (weights.last_mut(), polished) {
            *target = source;
        }
        network.set_weights(&weights)?;
        Some(summary)
    } else {
        None
    };
    let estimates = probe.estimates(model, network.param_values())?;
    Ok((summary, estimates))
}

impl<'a> Probe<'a> {
    fn new(
        network: &Network,
        model: &ir::Model,
        table: &'a PairTable,
        setup: &Setup,
    ) -> Result<Self, TrainError> {
        let double = Setup {
            precision: Precision::F64,
            ..setup.clone()
        };
        let mut copy = Network::build(model, &double)?;
        let weights = network.weights();
        copy.set_weights(&weights)?;
        let params = model.params.len();
        let param_tensor = weights.len() - 1;
        let mut coordinates: Vec<(usize, usize)> = (0..params).map(|i| (param_tensor, i)).collect();
        for tensor in output_biases(&weights) {
            coordinates.extend((0..weights[tensor].values.len()).map(|i| (tensor, i)));
        }
        Ok(Probe {
            network: copy,
            weights,
            coordinates,
            params,
            table,
            inverse_std: setup
                .normalisation
                .state_std
                .iter()
                .map(|s| 1.0 / s)
                .collect(),
            measured: model.states.len(),
            state_width: model.states.len() + model.hidden.len(),
        })
    }

    /// Normalised one-step residuals of every pair at the current weights.
    fn residuals(&mut self) -> Result<Vec<f64>, TrainError> {
        self.network.set_weights(&self.weights)?;
        let mut residuals = Vec::with_capacity(self.table.len() * self.measured);
        let indices: Vec<usize> = (0..self.table.len()).collect();
        for chunk in indices.chunks(CHUNK) {
            let batch = self.table.batch(chunk);
            let prediction = self.network.predict(&batch)?;
            for row in 0..chunk.len() {
                for state in 0..self.measured {
                    let weight = batch.weights[row * self.measured + state];
                    if weight <= 0.0 {
                        continue;
                    }
                    let error = prediction.next_states[row * self.state_width + state]
                        - batch.targets[row * self.measured + state];
                    residuals.push(error * self.inverse_std[state] * weight.sqrt());
                }
            }
        }
        Ok(residuals)
    }

    fn coordinate(&mut self, index: usize) -> &mut f64 {
        let (tensor, entry) = self.coordinates[index];
        &mut self.weights[tensor].values[entry]
    }

    /// Columns `0..count` of the Jacobian of the residuals, column-major.
    fn jacobian(&mut self, count: usize) -> Result<Vec<Vec<f64>>, TrainError> {
        let mut columns = Vec::with_capacity(count);
        for index in 0..count {
            let centre = *self.coordinate(index);
            let delta = 1e-6 * centre.abs().max(1.0);
            *self.coordinate(index) = centre + delta;
            let up = self.residuals()?;
            *self.coordinate(index) = centre - delta;
            let down = self.residuals()?;
            *self.coordinate(index) = centre;
            columns.push(
                (up.iter().zip(&down))
                    .map(|(u, d)| (u - d) / (2.0 * delta))
                    .collect(),
            );
        }
        Ok(columns)
    }

    fn polish(&mut self) -> Result<PolishSummary, TrainError> {
        let params_before = self.network_param_values()?;
        let mut residuals = self.residuals()?;
        let loss_before = mean_square(&residuals);
        let mut cost = loss_before;
        let mut damping = 1e-3;
        let mut steps = 0;
        for _ in 0..MAX_ITERATIONS {
            let jacobian = self.jacobian(self.params)?;
            let (mut normal, gradient) = normal_equations(&jacobian, &residuals);
            let n = self.params;
            for i in 0..n {
                normal[i * n + i] *= 1.0 + damping;
                normal[i * n + i] += 1e-300;
            }
            let Some(step) = solve(&normal, &gradient, n) else {
                damping *= 10.0;
                continue;
            };
            let saved: Vec<f64> = (0..n).map(|i| *self.coordinate(i)).collect();
            for (i, d) in step.iter().enumerate() {
                *self.coordinate(i) -= d;
            }
            let trial = self.residuals()?;
            let trial_cost = mean_square(&trial);
            if trial_cost.is_finite() && trial_cost < cost {
                let gain = (cost - trial_cost) / cost.max(1e-300);
                (residuals, cost) = (trial, trial_cost);
                damping = (damping / 3.0).max(1e-12);
                steps += 1;
                if gain < 1e-9 {
                    break;
                }
            } else {
                for (i, value) in saved.into_iter().enumerate() {
                    *self.coordinate(i) = value;
                }
                damping *= 4.0;
                if damping > 1e12 {
                    break;
                }
            }
        }
        self.network.set_weights(&self.weights)?;
        Ok(PolishSummary {
            steps,
            loss_before,
            loss_after: cost,
            params_before,
        })
    }

    fn network_param_values(&mut self) -> Result<Vec<f64>, TrainError> {
        self.network.set_weights(&self.weights)?;
        Ok(self.network.param_values())
    }

    /// Standard errors of the params (nuisance biases marginalised).
    fn estimates(
        &mut self,
        model: &ir::Model,
        values: Vec<f64>,
    ) -> Result<Vec<ParamEstimate>, TrainError> {
        let residuals = self.residuals()?;
        let count = self.coordinates.len();
        let jacobian = self.jacobian(count)?;
        let (normal, _) = normal_equations(&jacobian, &residuals);
        let dof = residuals.len().saturating_sub(count).max(1) as f64;
        let variance = residuals.iter().map(|r| r * r).sum::<f64>() / dof;
        let slopes = self.transform_slopes()?;
        let mut estimates = Vec::with_capacity(self.params);
        for (index, (param, value)) in model.params.iter().zip(values).enumerate() {
            let mut unit = vec![0.0; count];
            unit[index] = 1.0;
            let raw_variance = solve(&normal, &unit, count)
                .map(|column| column[index] * variance)
                .filter(|v| v.is_finite() && *v >= 0.0);
            let std_error = raw_variance.map_or(f64::INFINITY, |v| v.sqrt() * slopes[index].abs());
            let relative_error = std_error / value.abs().max(1e-300);
            estimates.push(ParamEstimate {
                name: param.name.clone(),
                value,
                std_error,
                relative_error,
                well_identified: relative_error < IDENTIFIABILITY_LIMIT,
            });
        }
        Ok(estimates)
    }

    /// `d value / d raw` of every param (central differences of the transforms).
    fn transform_slopes(&mut self) -> Result<Vec<f64>, TrainError> {
        let mut slopes = Vec::with_capacity(self.params);
        for index in 0..self.params {
            let centre = *self.coordinate(index);
            let delta = 1e-6 * centre.abs().max(1.0);
            *self.coordinate(index) = centre + delta;
            let up = self.network_param_values()?[index];
            *self.coordinate(index) = centre - delta;
            let down = self.network_param_values()?[index];
            *self.coordinate(index) = centre;
            slopes.push((up - down) / (2.0 * delta));
        }
        self.network.set_weights(&self.weights)?;
        Ok(slopes)
    }
}

/// The tensors of the output-layer biases: each closure's last tensor, the one before the
/// next closure's first or before the params.
fn output_biases(weights: &[NamedTensor]) -> Vec<usize> {
    let closure_of = |name: &str| name.rsplit_once(".layer").map(|(c, _)| c.to_string());
    (0..weights.len())
        .filter(|&i| weights[i].name.ends_with(".bias"))
        .filter(|&i| {
            let own = closure_of(&weights[i].name);
            weights
                .get(i + 1)
                .is_none_or(|next| closure_of(&next.name) != own)
        })
        .collect()
}

fn mean_square(values: &[f64]) -> f64 {
    values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64
}

/// `J'J` (row-major) and `J'r` from column-major `J`.
fn normal_equations(jacobian: &[Vec<f64>], residuals: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = jacobian.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut normal = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let value = dot(&jacobian[i], &jacobian[j]);
            normal[i * n + j] = value;
            normal[j * n + i] = value;
        }
    }
    let gradient = jacobian.iter().map(|c| dot(c, residuals)).collect();
    (normal, gradient)
}

/// Solves the symmetric positive definite system `a x = b` by Cholesky; `None` when `a` is
/// not numerically positive definite.
pub(super) fn solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut lower = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut sum = a[i * n + j];
            for k in 0..j {
                sum -= lower[i * n + k] * lower[j * n + k];
            }
            if i == j {
                if !(sum > 1e-14 * a[i * n + i].abs() && sum.is_finite()) {
                    return None;
                }
                lower[i * n + i] = sum.sqrt();
            } else {
                lower[i * n + j] = sum / lower[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let sum: f64 = (0..i).map(|k| lower[i * n + k] * y[k]).sum();
        y[i] = (b[i] - sum) / lower[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let sum: f64 = (i + 1..n).map(|k| lower[k * n + i] * x[k]).sum();
        x[i] = (y[i] - sum) / lower[i * n + i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system_and_refuses_a_singular_one() {
        // a = [[4, 2], [2, 3]], x = [1, -2] -> b = [0, -4].
        let x = solve(&[4.0, 2.0, 2.0, 3.0], &[0.0, -4.0], 2).unwrap();
        assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] + 2.0).abs() < 1e-12);
        assert!(solve(&[1.0, 1.0, 1.0, 1.0], &[1.0, 1.0], 2).is_none());
    }
}
