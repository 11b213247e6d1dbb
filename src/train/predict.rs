//! Predictions of a trained network along a record, as a table: the states (measured and
//! hidden), every closure output and every model output over time.
//!
//! Rows run from the first row with a full embedding history to the end of the record.
//! *Offline*, the state at a row is the one-step prediction from the true history at the
//! row before (the first row repeats the data), and closure outputs are evaluated at the
//! true state. *Online*, everything comes from one free run started at the first row,
//! driven by the data's inputs alone. Hidden states are run in from their initial values
//! at the first data row in both modes.
//!
//! An online run stops where a measured state leaves the physical range of the training
//! data ([`PhysicalRange`]): the table keeps every row, the offending state at its row and
//! `NaN` everywhere after it, and [`PredictionTable::divergence`] says where and why.

use crate::backend::{Network, Setup};
use crate::data::Dataset;
use crate::ir;

use super::evaluate::{run_in_hidden, simulate, Divergence, Feed, PhysicalRange};
use super::pairs::{first_pair_row, stage_fractions};
use super::recipe::DEFAULT_RANGE_FACTOR;
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
    /// Where an online run left the physical range (rows after it are `NaN`).
    pub divergence: Option<Divergence>,
}

/// Predicts along `data` with a trained network; online runs stop outside the default
/// physical range of the training data.
pub fn predict(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    data: &Dataset,
    mode: Mode,
) -> Result<PredictionTable, TrainError> {
    let range = PhysicalRange::new(&setup.normalisation, DEFAULT_RANGE_FACTOR);
    predict_in_range(model, network, setup, data, (mode, range.as_ref()))
}

/// Predicts along `data`; an online run stops when it leaves `range` (none: never).
pub fn predict_in_range(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    data: &Dataset,
    (mode, range): (Mode, Option<&PhysicalRange>),
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
        (feed, range),
    )?;
    let states: Vec<Vec<f64>> = match mode {
        Mode::Online => stopped_states(&run, last + 1 - first),
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
    let rows = last + 1 - first;
    let mut columns = vec![record.times[first..].to_vec()];
    columns.extend(transpose(&states));
    columns.extend(transpose(&pad(&run.closure_outputs, rows)));
    columns.extend(transpose(&pad(&run.outputs, rows)));
    Ok(PredictionTable {
        header,
        columns,
        divergence: run.divergence,
    })
}

/// The states of a free run at each of `rows` rows: the offending state at the row where
/// it stopped, `NaN` after.
fn stopped_states(run: &super::evaluate::Trajectory, rows: usize) -> Vec<Vec<f64>> {
    let mut states = run.states.clone();
    if run.divergence.is_some() {
        if let Some(last) = run.next_states.last() {
            states.push(last.clone());
        }
    }
    pad(&states, rows)
}

/// `rows` rows: the given ones, then rows of `NaN` of the same width.
fn pad(given: &[Vec<f64>], rows: usize) -> Vec<Vec<f64>> {
    let width = given.first().map_or(0, Vec::len);
    let mut padded: Vec<Vec<f64>> = given.iter().take(rows).cloned().collect();
    padded.resize(rows, vec![f64::NAN; width]);
    padded
}

/// Rows of equal width into columns.
fn transpose(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let width = rows.first().map_or(0, Vec::len);
    (0..width)
        .map(|column| rows.iter().map(|row| row[column]).collect())
        .collect()
}
