//! What-if runs of a trained model (`gbc simulate MODEL --weights DIR`): a free run under
//! any input programme from any initial state, through the same machinery as an online
//! prediction ([`super::predict_on_track`]): the run is a [`Record`] whose inputs come from
//! the programmes and whose states are unmeasured after the start, laid on the grid the
//! network trained on and run with the network fed its own predictions.
//!
//! - **From the held initial state** (no history): the rows run from `t_start` to `t_end`
//!   every `dt`; the measured states start at the values given (`--init X=0.2`) or
//!   declared in the model, with the history before the start held at them (the records
//!   spec's `held` history), and hidden states at their declared (or given) values.
//! - **From a history**: the history's rows before `t_start` are the measured past (its
//!   inputs and states, read by the embedding and running the hidden states in as in
//!   training), its row at `t_start` is the initial state (a value given with `--init`
//!   replaces it), and the programmes drive the run from `t_start` on. Run along a record's
//!   own inputs from the first row with a full embedding, this is exactly the record's
//!   online prediction.

use miette::Diagnostic;
use thiserror::Error;

use super::{predict_on_track, track_of, Mode, PredictionTable, Start};
use crate::engine::graph::{Network, Setup};
use crate::ir;
use crate::record::Record;
use crate::signal::Signal;
use crate::train::evaluate::PhysicalRange;
use crate::train::initial::constant_value;
use crate::train::{hidden_initial_values, TrainError};

/// Most rows a what-if run may have.
pub const MAX_ROWS: usize = 10_000_000;

/// A what-if run: its inputs, times and start.
#[derive(Debug, Clone)]
pub struct WhatIf<'a> {
    /// One signal per model input, in model order.
    pub signals: &'a [Signal],
    /// The first time of the run (the initial state's time).
    pub t_start: f64,
    /// The last time (rounded down to the grid `t_start + k dt`).
    pub t_end: f64,
    /// The spacing of the rows.
    pub dt: f64,
    /// Initial values that replace the declared (or the history's) ones: measured states
    /// then hidden states, `None` to keep.
    pub initial: Vec<Option<f64>>,
    /// The measured past, if any.
    pub history: Option<&'a Record>,
}

/// Why a what-if run cannot start.
#[derive(Debug, Error, Diagnostic)]
pub enum WhatIfError {
    /// The run's times do not make a grid.
    #[error("expected t-end > t-start and dt > 0 (all finite, at most {MAX_ROWS} rows), found t-start {t_start}, t-end {t_end}, dt {dt}")]
    #[diagnostic(
        code(gbm::E0712),
        help("e.g. `--t-start 0 --t-end 200 --dt 1`; dt defaults to the run's step")
    )]
    BadTimes {
        /// First time.
        t_start: f64,
        /// Last time.
        t_end: f64,
        /// Spacing.
        dt: f64,
    },
    /// The start is not a time of the history.
    #[error("expected --t-start at a row of the history `{history}` ({first} to {last}), found {t_start}")]
    #[diagnostic(
        code(gbm::E0713),
        help(
            "start at one of the history's times, or leave --t-start out to start at its last row"
        )
    )]
    StartOutsideHistory {
        /// The history file.
        history: String,
        /// Its first time.
        first: f64,
        /// Its last time.
        last: f64,
        /// The start asked for.
        t_start: f64,
    },
    /// A measured state has no initial value.
    #[error("state `{state}` has no initial value")]
    #[diagnostic(
        code(gbm::E0714),
        help(
            "give one with `--init {state}=VALUE`, declare one in the model (`state {state} = \
             VALUE`), or start from measured data with `--history FILE`"
        )
    )]
    NoInitialValue {
        /// The state.
        state: String,
    },
    /// Training machinery failed (a run directory, the network).
    #[error(transparent)]
    #[diagnostic(transparent)]
    Train(#[from] TrainError),
}

/// Runs `what` with a trained network: one row per time of the run from `t_start`, with
/// columns `t`, the inputs, the states (measured, then hidden), every closure output and
/// every model output. A run that leaves `range` stops there ([`PredictionTable::divergence`]).
pub fn what_if(
    model: &ir::Model,
    (network, setup): (&Network, &Setup),
    what: &WhatIf,
    range: Option<&PhysicalRange>,
) -> Result<PredictionTable, WhatIfError> {
    let times = grid_times(what)?;
    let (record, start_row) = record_of(model, what, &times)?;
    let track = track_of(model, setup, &record)?;
    let knot = (track.rows.iter())
        .position(|row| *row == Some(start_row))
        .unwrap_or(0);
    let hidden_initial = hidden_initial_values(model)?;
    let measured = model.states.len();
    let hidden_given: Vec<Option<f64>> = what.initial.iter().skip(measured).copied().collect();
    let start = Start {
        knot,
        hidden_initial: &hidden_initial,
        hidden_at_start: &hidden_given,
    };
    let mut table = predict_on_track(model, network, setup, track, start, (Mode::Online, range))?;
    insert_inputs(model, &record, start_row, &mut table);
    Ok(table)
}

/// The times `t_start + k dt` up to `t_end`.
fn grid_times(what: &WhatIf) -> Result<Vec<f64>, WhatIfError> {
    let (t_start, t_end, dt) = (what.t_start, what.t_end, what.dt);
    let steps = ((t_end - t_start) / dt * (1.0 + 1e-12)).floor();
    let valid = t_start.is_finite() && t_end.is_finite() && dt > 0.0 && dt.is_finite();
    if !(valid && steps >= 1.0 && steps < MAX_ROWS as f64) {
        return Err(WhatIfError::BadTimes { t_start, t_end, dt });
    }
    Ok((0..=steps as usize)
        .map(|k| t_start + k as f64 * dt)
        .collect())
}

/// The run as a record: the history's rows before the start, then the run's rows (inputs
/// from the signals, states unmeasured after the first); and the row the run starts at.
fn record_of(
    model: &ir::Model,
    what: &WhatIf,
    times: &[f64],
) -> Result<(Record, usize), WhatIfError> {
    let measured = model.states.len();
    let mut record = Record {
        name: "what-if".into(),
        source: "what-if run".into(),
        times: Vec::new(),
        inputs: vec![Vec::new(); model.inputs.len()],
        states: vec![Vec::new(); measured],
        observables: Vec::new(),
    };
    let mut start_cells: Vec<Option<f64>> = vec![None; measured];
    if let Some(history) = what.history {
        let row = start_row(history, what.t_start)?;
        for past in 0..row {
            record.times.push(history.times[past]);
            for (column, values) in record.inputs.iter_mut().zip(&history.inputs) {
                column.push(values[past]);
            }
            for (column, cells) in record.states.iter_mut().zip(&history.states) {
                column.push(cells[past]);
            }
        }
        start_cells = history.states.iter().map(|cells| cells[row]).collect();
    }
    let start_row = record.times.len();
    for (index, (state, cell)) in model.states.iter().zip(&mut start_cells).enumerate() {
        if let Some(given) = what.initial.get(index).copied().flatten() {
            *cell = Some(given);
        } else if cell.is_none() && what.history.is_none() {
            let declared = state.init.as_ref().map(|init| constant_value(model, init));
            *cell = Some(declared.ok_or_else(|| WhatIfError::NoInitialValue {
                state: state.name.clone(),
            })?);
        }
    }
    for (k, &time) in times.iter().enumerate() {
        record.times.push(time);
        for (column, signal) in record.inputs.iter_mut().zip(what.signals) {
            column.push(signal.value_at(time));
        }
        for (column, cell) in record.states.iter_mut().zip(&start_cells) {
            column.push(if k == 0 { *cell } else { None });
        }
    }
    Ok((record, start_row))
}

/// The history's row at `t_start` (within the history's time tolerance, or rounding).
fn start_row(history: &Record, t_start: f64) -> Result<usize, WhatIfError> {
    let (first, last) = match (history.times.first(), history.times.last()) {
        (Some(&first), Some(&last)) => (first, last),
        _ => (f64::NAN, f64::NAN),
    };
    let tolerance = (1e-9 * (last - first).abs().max(1.0)).max(history.time_tolerance());
    (history.times.iter())
        .position(|&t| (t - t_start).abs() <= tolerance)
        .ok_or(WhatIfError::StartOutsideHistory {
            history: history.source.clone(),
            first,
            last,
            t_start,
        })
}

/// Puts the inputs held at each row after the time column.
fn insert_inputs(
    model: &ir::Model,
    record: &Record,
    start_row: usize,
    table: &mut PredictionTable,
) {
    let rows = table.columns.first().map_or(0, Vec::len);
    for (offset, (input, values)) in model.inputs.iter().zip(&record.inputs).enumerate() {
        let column = values[start_row..].iter().copied().take(rows).collect();
        table.header.insert(1 + offset, input.name.clone());
        table.columns.insert(1 + offset, column);
    }
}

#[cfg(test)]
mod tests;
