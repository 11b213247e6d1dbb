//! The params after training: a Levenberg-Marquardt polish with the network frozen, and
//! each param's standard error, so that a poorly identified constant is flagged.
//!
//! Both work on the normalised one-step residuals `r = (x_pred(t + h) - x(t + h)) / std`
//! of every measured target cell of every training pair (times the square root of its
//! loss weight), in double precision (a copy of the network), with the Jacobian
//! by central differences in the raw (unconstrained) params.
//!
//! - **Polish**: damped Gauss-Newton steps `(J'J + lambda diag(J'J)) d = -J'r` in the raw
//!   params alone, a step kept only when it lowers `|r|^2` (the shared driver,
//!   [`crate::numeric::lm`]).
//! - **Uncertainty**: the linearised covariance `s^2 (J'J)^-1`, `s^2 = |r|^2 / (n - q)`
//!   ([`crate::numeric::lm::standard_errors`]),
//!   with `J` over the raw params *and* the output-layer biases of every closure (nuisance
//!   parameters: a constant shift of each closure output that could absorb a change of a
//!   param is allowed for). A param's standard error is its marginal one, mapped through
//!   its transform; [`ParamEstimate::identified`] says whether it is below
//!   [`IDENTIFIABILITY_LIMIT`] of the value. The residuals of a fitted model are model
//!   error more than noise and are correlated in time, so the error is a measure of how
//!   sharply the data pin the param given the network, not a confidence interval.

use crate::engine::graph::{NamedTensor, Network, Precision, Setup};
use crate::ir;
use crate::numeric::lm::{self, central_difference, difference_step, standard_errors};
use crate::numeric::{Damping, GaussNewton, Settings};

pub use crate::solve::fit::ParamEstimate;

use super::TrainError;
use crate::engine::pairs::PairTable;

/// Most Levenberg-Marquardt trial steps of the polish.
const MAX_ITERATIONS: usize = 30;
/// The polish's damping schedule: from `1e-3`, divided by 3 on success and multiplied by 4
/// on failure (10 on a singular system); it stops when a step gains less than `1e-9` of the
/// cost or the damping passes `1e12`.
const SETTINGS: Settings = Settings {
    max_trials: MAX_ITERATIONS,
    max_linearisations: MAX_ITERATIONS,
    tolerance: 1e-9,
    ..Settings::DEFAULT
};
/// Marquardt's scaling `(J'J + lambda diag(J'J))`, with a floor for a param no residual sees.
const DAMPING: Damping = Damping {
    min_diagonal: 0.0,
    jitter: 1e-300,
    relative_jitter: 0.0,
};
/// Pairs per prediction batch.
const CHUNK: usize = 512;

/// What the polish did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PolishSummary {
    /// Accepted Levenberg-Marquardt steps.
    pub steps: usize,
    /// Mean squared normalised one-step residual before.
    #[serde(with = "crate::json")]
    pub loss_before: f64,
    /// And after.
    #[serde(with = "crate::json")]
    pub loss_after: f64,
    /// Param values before, in declaration order.
    #[serde(with = "crate::json")]
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

    /// Sets the raw params (the first coordinates).
    fn set_params(&mut self, values: &[f64]) {
        for (index, value) in values.iter().enumerate() {
            *self.coordinate(index) = *value;
        }
    }

    /// Columns `0..count` of the Jacobian of the residuals (central differences).
    fn jacobian(&mut self, count: usize) -> Result<Vec<Vec<f64>>, TrainError> {
        (0..count)
            .map(|index| {
                let centre = *self.coordinate(index);
                let column = central_difference(
                    |shift| {
                        *self.coordinate(index) = centre + shift;
                        self.residuals()
                    },
                    difference_step(centre, 1e-6),
                );
                *self.coordinate(index) = centre;
                column
            })
            .collect()
    }

    fn polish(&mut self) -> Result<PolishSummary, TrainError> {
        let params_before = self.network_param_values()?;
        let start: Vec<f64> = (0..self.params).map(|i| *self.coordinate(i)).collect();
        let outcome = lm::minimise(&mut Polish(self), start, &SETTINGS)?;
        self.set_params(&outcome.x);
        self.network.set_weights(&self.weights)?;
        let count = outcome.residuals.len().max(1) as f64;
        Ok(PolishSummary {
            steps: outcome.steps,
            loss_before: outcome.initial_cost / count,
            loss_after: outcome.cost / count,
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
        let jacobian = self.jacobian(self.coordinates.len())?;
        let raw_errors = standard_errors(&jacobian, &residuals, self.params);
        let slopes = self.transform_slopes()?;
        let mut estimates = Vec::with_capacity(self.params);
        for (index, (param, value)) in model.params.iter().zip(values).enumerate() {
            let std_error = raw_errors[index] * slopes[index].abs();
            estimates.push(ParamEstimate::fitted(param.name.clone(), value, std_error));
        }
        Ok(estimates)
    }

    /// `d value / d raw` of every param (central differences of the transforms).
    fn transform_slopes(&mut self) -> Result<Vec<f64>, TrainError> {
        let mut slopes = Vec::with_capacity(self.params);
        for index in 0..self.params {
            let centre = *self.coordinate(index);
            let values = central_difference(
                |shift| {
                    *self.coordinate(index) = centre + shift;
                    self.network_param_values()
                },
                difference_step(centre, 1e-6),
            )?;
            *self.coordinate(index) = centre;
            slopes.push(values[index]);
        }
        self.network.set_weights(&self.weights)?;
        Ok(slopes)
    }
}

/// The polish as a least-squares problem in the raw params (the network frozen).
struct Polish<'p, 'a>(&'p mut Probe<'a>);

impl lm::Problem for Polish<'_, '_> {
    type Error = TrainError;
    type Linear = GaussNewton;

    fn residuals(&mut self, x: &[f64]) -> Result<Option<Vec<f64>>, TrainError> {
        self.0.set_params(x);
        self.0.residuals().map(Some)
    }

    fn linearise(&mut self, x: &[f64], residuals: &[f64]) -> Result<GaussNewton, TrainError> {
        self.0.set_params(x);
        let columns = self.0.jacobian(x.len())?;
        Ok(GaussNewton::new(&columns, residuals, DAMPING))
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

#[cfg(test)]
mod tests {
    use super::ParamEstimate;

    /// One estimate type for training and `diagnose`: runs written under the old field name
    /// still read, and what is written reads back, infinite standard error included.
    #[test]
    fn estimates_read_under_either_name_and_round_trip() {
        let old = r#"{"name":"Y_X","value":0.4,"std_error":"inf","relative_error":"inf","well_identified":false}"#;
        let read: ParamEstimate = serde_json::from_str(old).unwrap();
        assert!(read.std_error == Some(f64::INFINITY) && !read.identified && !read.held);
        let written = serde_json::to_string(&read).unwrap();
        assert!(written.contains(r#""identified":false"#), "{written}");
        assert_eq!(
            serde_json::from_str::<ParamEstimate>(&written).unwrap(),
            read
        );
    }
}
