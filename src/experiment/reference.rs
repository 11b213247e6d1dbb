//! What trained models are compared with: free-run errors on a record, and the truth
//! model's rates along a record (the true values of the closures, paper Fig. 3d).

use crate::data::Dataset;
use crate::engine::graph::{Network, Setup};
use crate::ir;
use crate::numeric::mean_std;
use crate::signal::Signal;
use crate::solve::ode::SimOptions;
use crate::train::TrainError;
use crate::trained::predict::{predict_in_range, Mode, PredictionTable};

use super::ExperimentFailure;

/// The rows of a record a prediction table covers: it starts at the first row with a full
/// embedding history and runs to the end.
pub fn first_predicted_row(data: &Dataset, table: &PredictionTable) -> usize {
    data.len() - table.columns.first().map_or(0, Vec::len)
}

/// A free run along `data`: driven by its inputs alone from its first full history, never
/// stopped (the paper's online run; `gbc train` stops a run that leaves the training data's
/// physical range, which would end the run and make its error infinite).
pub fn free_run(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    data: &Dataset,
) -> Result<PredictionTable, TrainError> {
    let record = crate::train::record_of(model, data)?;
    let protocol = (Mode::Online, crate::train::History::Measured, None);
    predict_in_range(model, network, setup, &record, protocol)
}

/// MSE of each measured state of a free run against `data` over the rows after its first,
/// z-scored with `scale(state, column)`; infinite where the run did not stay finite.
pub fn free_run_errors(
    model: &ir::Model,
    table: &PredictionTable,
    data: &Dataset,
    scale: &dyn Fn(&str, &[f64]) -> f64,
) -> Vec<(String, f64)> {
    let first = first_predicted_row(data, table);
    let mut errors = Vec::new();
    for (index, state) in model.states.iter().enumerate() {
        let (Some(actual), Some(predicted)) =
            (data.column(&state.name), table.columns.get(1 + index))
        else {
            continue;
        };
        let std = scale(&state.name, actual);
        let squared: f64 = (predicted.iter().zip(&actual[first..]))
            .skip(1)
            .map(|(p, a)| ((p - a) / std).powi(2))
            .sum();
        let mse = squared / (predicted.len().saturating_sub(1)).max(1) as f64;
        errors.push((
            state.name.clone(),
            if mse.is_nan() { f64::INFINITY } else { mse },
        ));
    }
    errors
}

/// Mean of per-state errors (infinite if any is).
pub fn mean_error(errors: &[(String, f64)]) -> f64 {
    errors.iter().map(|(_, e)| e).sum::<f64>() / errors.len().max(1) as f64
}

/// Online error of an unstopped free run over a whole record, each state z-scored with the
/// record's own standard deviation, averaged over states.
pub fn free_run_error(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    data: &Dataset,
) -> Result<f64, TrainError> {
    let table = free_run(model, network, setup, data)?;
    let errors = free_run_errors(model, &table, data, &|_, column| mean_std(column).1);
    Ok(mean_error(&errors))
}

/// The truth model simulated along a record.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRun {
    /// Sample times (the record's).
    pub times: Vec<f64>,
    /// Every output and let of the truth, by name, one value per time.
    pub values: Vec<(String, Vec<f64>)>,
    /// Largest deviation of the truth's measured states from the record over the rows
    /// from `checked_from`, in units of each state's standard deviation: near zero when the
    /// truth reproduces the data.
    pub deviation: f64,
}

impl TruthRun {
    /// The true value of closure output `name`: the truth's output `<name>_true`, else its
    /// let `<name>`.
    pub fn closure_truth(&self, name: &str) -> Option<&[f64]> {
        let find = |wanted: &str| {
            (self.values.iter())
                .find(|(n, _)| n == wanted)
                .map(|(_, v)| v.as_slice())
        };
        find(&format!("{name}_true")).or_else(|| find(name))
    }
}

/// Simulates `truth` along `data`: driven by the record's inputs (held between samples),
/// from the record's first measured states and the truth's declared hidden states, sampled
/// at the record's times. `checked_from` is the first row the deviation is measured over
/// (hidden states start from a guess, so early rows may differ).
pub fn truth_along(
    truth: &ir::Model,
    data: &Dataset,
    checked_from: usize,
) -> Result<TruthRun, ExperimentFailure> {
    let mut signals = Vec::new();
    for input in &truth.inputs {
        let values = data.column(&input.name).unwrap_or_default().to_vec();
        let signal = Signal::new(data.times.clone(), values)
            .map_err(|error| ExperimentFailure::Internal(format!("truth input: {error}")))?;
        signals.push(signal);
    }
    let first_time = data.times.first().copied().unwrap_or(0.0);
    let last_time = data.times.last().copied().unwrap_or(0.0);
    let options = SimOptions {
        t_start: first_time,
        t_end: last_time + 0.5 * data.step,
        dt: data.step,
        initial: (truth.states.iter())
            .map(|s| data.column(&s.name).and_then(|c| c.first().copied()))
            .collect(),
        ..SimOptions::new(last_time, data.step)
    };
    let run = crate::solve::ode::simulate(truth, &signals, &options)?;
    let rows = run.len().min(data.len());
    let mut deviation: f64 = 0.0;
    for (index, state) in truth.states.iter().enumerate() {
        if let Some(actual) = data.column(&state.name) {
            let (_, std) = mean_std(actual);
            let start = checked_from.min(rows);
            let pairs = run.states[index][start..rows]
                .iter()
                .zip(&actual[start..rows]);
            for (simulated, measured) in pairs {
                deviation = deviation.max((simulated - measured).abs() / std);
            }
        }
    }
    let named = |definitions: &[ir::Definition], columns: &[Vec<f64>]| {
        (definitions.iter().zip(columns))
            .map(|(d, c)| (d.name.clone(), c[..rows].to_vec()))
            .collect::<Vec<_>>()
    };
    let mut values = named(&truth.outputs, &run.outputs);
    values.extend(named(&truth.lets, &run.lets));
    Ok(TruthRun {
        times: run.times[..rows].to_vec(),
        values,
        deviation: if deviation.is_nan() {
            f64::INFINITY
        } else {
            deviation
        },
    })
}

/// The true values of the truth's consts named like the params of `model`: `(name, value)`.
pub fn true_params(truth: &ir::Model, model: &ir::Model) -> Vec<(String, f64)> {
    (model.params.iter())
        .filter_map(|param| {
            (truth.consts.iter())
                .find(|c| c.name == param.name)
                .map(|c| (c.name.clone(), c.value))
        })
        .collect()
}
