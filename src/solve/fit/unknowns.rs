//! The unknowns of a fit by free runs: a model's params, the fitted starts of its measured
//! states, then (with `--fit-initial`) those of its hidden states in every training
//! experiment, each named, constrained and with its default value.

use super::simulate::Simulator;
use super::split::Split;
use crate::ir::{Constraint, Model};
use std::collections::BTreeMap;

/// The unknowns of a fit, in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Unknowns {
    /// Names: params, then `STATE@EXPERIMENT` for fitted starts.
    pub names: Vec<String>,
    /// Constraints (a fitted start is bounded by its cell's noise, [`Split::start_bounds`],
    /// else free).
    pub constraints: Vec<Constraint>,
    /// Default values.
    pub defaults: Vec<f64>,
}

impl Unknowns {
    /// The unknowns of a fit of `model` (compiled as `simulator`) on `split`: its params,
    /// the fitted starts of measured states, then (with `--fit-initial`) of its hidden
    /// states in every training experiment; named `STATE@EXPERIMENT`, with default values
    /// (declared params, first measured values, declared initial values).
    pub fn of(split: &Split, model: &Model, simulator: &Simulator) -> Unknowns {
        let mut unknowns = Unknowns::default();
        for param in &model.params {
            unknowns.push(param.name.clone(), param.constraint, param.init);
        }
        let guesses = initial_guesses(split);
        for (i, (&(record, state), guess)) in split.fitted_starts.iter().zip(guesses).enumerate() {
            let name = format!(
                "{}@{}",
                model.states[state].name, split.records[record].name
            );
            let constraint = match split.start_bounds.get(i).copied().flatten() {
                Some((lo, hi)) => Constraint::Bounds(lo, hi),
                None => Constraint::Free,
            };
            unknowns.push(name, constraint, guess);
        }
        if split.fit_hidden {
            unknowns.push_hidden_starts(split, model, simulator);
        }
        unknowns
    }

    /// The hidden states' starts of every training experiment, at the values a run from
    /// the declared params gives them.
    fn push_hidden_starts(&mut self, split: &Split, model: &Model, simulator: &Simulator) {
        let mut simulator = simulator.clone();
        let declared: Vec<f64> = model.params.iter().map(|p| p.init).collect();
        simulator.set_params(&declared);
        for (_, record, _) in split.training() {
            let start = simulator.start_state(record, &[]);
            for (h, state) in model.hidden.iter().enumerate() {
                let name = format!("{}@{}", state.name, record.name);
                self.push(name, Constraint::Free, start[model.states.len() + h]);
            }
        }
    }

    fn push(&mut self, name: String, constraint: Constraint, default: f64) {
        self.names.push(name);
        self.constraints.push(constraint);
        self.defaults.push(default);
    }

    /// Values from `start` by name, defaults elsewhere.
    pub fn values(&self, start: &BTreeMap<String, f64>) -> Vec<f64> {
        (self.names.iter().zip(&self.defaults))
            .map(|(name, default)| start.get(name).copied().unwrap_or(*default))
            .collect()
    }
}

/// First guesses of the fitted starts: the state's first measured value in the
/// experiment's training part, else its training mean.
fn initial_guesses(split: &Split) -> Vec<f64> {
    (split.fitted_starts.iter())
        .map(|&(record, state)| {
            let rows = split.parts[record].train.clone();
            let cells = &split.records[record].states[state][rows];
            (cells.iter().flatten().next().copied())
                .unwrap_or(split.normalisation.state_mean[state])
        })
        .collect()
}
