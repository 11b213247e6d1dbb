//! Predictions of a trained network along a record, as a table: the states (measured and
//! hidden), every closure output and every model output over time.
//!
//! Rows run from the first row with a full embedding history to the end of the record.
//! *Offline*, the state at a row is the one-step prediction from the true history at the
//! row before (the first row repeats the data), and closure outputs are evaluated at the
//! true state. *Online*, everything comes from one free run started at the first row,
//! driven by the data's inputs alone. Hidden states are run in from their initial values
//! at the first data row in both modes.

use crate::backend::{Network, Setup};
use crate::data::Dataset;
use crate::ir;

use super::evaluate::{run_in_hidden, simulate, Feed};
use super::pairs::{first_pair_row, stage_fractions};
use super::{hidden_initial_values, record_of, TrainError};

/// How predictions are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One step from the true history.
    Offline,
    /// A free run from the initial history.
    Online,
}

/// A table of predictions: column names (starting with `t`) and columns.
#[derive(Debug, Clone, PartialEq)]
pub struct PredictionTable {
    /// Column names.
    pub header: Vec<String>,
    /// Columns, each one value per row.
    pub columns: Vec<Vec<f64>>,
}

/// Predicts along `data` with a trained network.
pub fn predict(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    data: &Dataset,
    mode: Mode,
) -> Result<PredictionTable, TrainError> {
    let record = record_of(model, data)?;
    let first = first_pair_row(model, record.step);
    if record.len() < first + 2 {
        return Err(TrainError::TooFewRows {
            file: data.path.display().to_string(),
            needed: first + 2,
            found: record.len(),
            reason: format!("{first} rows of embedding history and one step"),
        });
    }
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let initial = hidden_initial_values(model)?;
    let hidden = run_in_hidden(network, model, &record, &fractions, &initial)?;
    let hidden_start = hidden.get(first).cloned().unwrap_or_default();
    let last = record.len() - 1;
    let feed = match mode {
        Mode::Offline => Feed::Data,
        Mode::Online => Feed::Own,
    };
    let run = simulate(
        network,
        model,
        &record,
        &fractions,
        (first, last),
        &hidden_start,
        feed,
    )?;
    let states: Vec<Vec<f64>> = match mode {
        Mode::Online => run.states.clone(),
        Mode::Offline => std::iter::once(run.states[0].clone())
            .chain(
                run.next_states
                    .iter()
                    .take(run.next_states.len() - 1)
                    .cloned(),
            )
            .collect(),
    };
    let mut header = vec!["t".to_string()];
    header.extend(
        model
            .states
            .iter()
            .chain(&model.hidden)
            .map(|s| s.name.clone()),
    );
    header.extend(
        (model.closures.iter())
            .flat_map(|c| c.outputs.iter())
            .map(|o| o.name.clone()),
    );
    header.extend(model.outputs.iter().map(|o| o.name.clone()));
    let mut columns = vec![record.times[first..].to_vec()];
    columns.extend(transpose(&states));
    columns.extend(transpose(&run.closure_outputs));
    columns.extend(transpose(&run.outputs));
    Ok(PredictionTable { header, columns })
}

/// Rows of equal width into columns.
fn transpose(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let width = rows.first().map_or(0, Vec::len);
    (0..width)
        .map(|column| rows.iter().map(|row| row[column]).collect())
        .collect()
}
