//! Predictions of a trained network along a record, as a table: the states (measured and
//! hidden), every closure output and every model output over time, one row per record row.
//!
//! Rows run from where the run starts (the first row, history held before it, or with
//! [`History::Measured`] the first row with a full embedding history) to the end of the
//! record. *Offline*, the state at a row is the one-step prediction from the measured
//! history at the knot before (the first row repeats the data); where the data do not
//! know a state the run goes free (the model's fill). *Online*, everything comes from one
//! free run from the start, driven by the data's inputs alone. Hidden states are run in
//! from their initial values at the first row in both modes.
//!
//! An online run stops where a measured state leaves the physical range of the training
//! data ([`PhysicalRange`]): the table keeps every row, the offending state at its row and
//! `NaN` everywhere after it, and [`PredictionTable::divergence`] says where and why.

use crate::engine::graph::{Network, Setup};
use crate::ir;
use crate::record::{Record, Track};

use crate::engine::pairs::stage_fractions;
use crate::record::grid::grid_for;
use crate::train::evaluate::{run_in, simulate, Divergence, Feed, PhysicalRange, Trajectory};
use crate::train::initial::initial_state;
use crate::train::recipe::DEFAULT_RANGE_FACTOR;
use crate::train::split::{window_start, History};
use crate::train::stepping::Stepping;
use crate::train::{hidden_initial_values, TrainError};

pub mod whatif;

/// How predictions are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One step from the true history.
    Offline,
    /// A free run from the initial history, each step cut into as many sub-steps as its
    /// stiffness needs ([`crate::train::stepping`]).
    Online,
    /// A free run at the trained step alone (`--substeps` of the run): the trained one-step
    /// map iterated, as its ONNX export steps.
    OnlineTrainedStep,
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

impl PredictionTable {
    /// Drops the rows from the divergence on: the offending row holds the value that left
    /// the range and no closure outputs, the rows after it `NaN`. What is left is the
    /// prediction up to where the run stopped, every value finite (the divergence says
    /// where and why). Without a divergence nothing changes.
    pub fn cut_at_divergence(&mut self) {
        let Some(divergence) = &self.divergence else {
            return;
        };
        let rows = (self.columns.first()).map_or(0, |times| {
            times.iter().take_while(|t| **t < divergence.time).count()
        });
        for column in &mut self.columns {
            column.truncate(rows);
        }
    }
}

/// Predicts along `record` with a trained network; online runs stop outside the default
/// physical range of the training data.
pub fn predict(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    record: &Record,
    (mode, history): (Mode, History),
) -> Result<PredictionTable, TrainError> {
    let range = PhysicalRange::new(&setup.normalisation, DEFAULT_RANGE_FACTOR);
    predict_in_range(
        model,
        network,
        setup,
        record,
        (mode, history, range.as_ref()),
    )
}

/// The track a trained network runs along `record` on: the grid of its training.
pub fn track_of(model: &ir::Model, setup: &Setup, record: &Record) -> Result<Track, TrainError> {
    let grid = grid_for(model, setup.step);
    let start = initial_state(model, record)?;
    Ok(Track::lay(record, &grid, &start.values()))
}

/// Predicts along `record`; an online run stops when it leaves `range` (none: never).
pub fn predict_in_range(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    record: &Record,
    (mode, history, range): (Mode, History, Option<&PhysicalRange>),
) -> Result<PredictionTable, TrainError> {
    let track = track_of(model, setup, record)?;
    let first = window_start(model, &track, history);
    if track.len() < first + 2 {
        return Err(TrainError::TooFewRows {
            file: record.source.clone(),
            needed: first + 2,
            found: track.len(),
            reason: format!("{first} rows of embedding history and one step"),
        });
    }
    let initial = hidden_initial_values(model)?;
    let start = Start {
        knot: first,
        hidden_initial: &initial,
        hidden_at_start: &[],
    };
    predict_on_track(model, network, setup, track, start, (mode, range))
}

/// Where a prediction along a track starts.
#[derive(Debug, Clone, Copy)]
pub struct Start<'a> {
    /// The knot the rows (and an online run) start at.
    pub knot: usize,
    /// The hidden states at the track's first knot, from which they are run in.
    pub hidden_initial: &'a [f64],
    /// Hidden states that replace the run-in values at `knot` (`None` or missing: keep).
    pub hidden_at_start: &'a [Option<f64>],
}

/// Predicts along `track` from `start.knot` to its end (at least one step after it); an
/// online run stops when it leaves `range` (none: never).
pub fn predict_on_track(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    mut track: Track,
    start: Start,
    (mode, range): (Mode, Option<&PhysicalRange>),
) -> Result<PredictionTable, TrainError> {
    let first = start.knot;
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let hidden_start = run_in_hidden(model, network, &mut track, &fractions, start)?;
    let last = track.len() - 1;
    // Free runs and one step from the data control their steps (a stiff interval is
    // integrated stably either way); `OnlineTrainedStep` iterates the trained map.
    let (feed, stepping) = match mode {
        Mode::Offline => (Feed::Data, Stepping::Controlled),
        Mode::Online => (Feed::Own, Stepping::Controlled),
        Mode::OnlineTrainedStep => (Feed::Own, Stepping::Fixed),
    };
    let run = simulate(
        network,
        model,
        &track,
        &fractions,
        (first, last),
        &hidden_start,
        (feed, range, stepping),
    )?;
    let knots = last + 1 - first;
    let states: Vec<Vec<f64>> = match mode {
        Mode::Online | Mode::OnlineTrainedStep => stopped_states(&run, knots),
        Mode::Offline => std::iter::once(run.states[0].clone())
            .chain(
                run.next_states
                    .iter()
                    .take(run.next_states.len() - 1)
                    .cloned(),
            )
            .collect(),
    };
    Ok(PredictionTable {
        header: table_header(model),
        columns: table_columns(&track, (first, last), &states, &run),
        divergence: run.divergence,
    })
}

/// Runs the hidden states in along `track` from its first knot, filling the states the
/// data do not know; the hidden states at `start.knot`, with those `start` gives replacing
/// the run-in values.
fn run_in_hidden(
    model: &ir::Model,
    network: &Network,
    track: &mut Track,
    fractions: &[f64],
    start: Start,
) -> Result<Vec<f64>, TrainError> {
    let initial = start.hidden_initial.to_vec();
    let run_in = run_in(network, model, track, fractions, &initial)?;
    for (state, values) in run_in.states.iter().enumerate() {
        track.fill(state, values);
    }
    let mut hidden_start = run_in.hidden.get(start.knot).cloned().unwrap_or(initial);
    for (value, given) in hidden_start.iter_mut().zip(start.hidden_at_start) {
        if let Some(given) = given {
            *value = *given;
        }
    }
    Ok(hidden_start)
}

/// The columns of a prediction table: time, the states (measured, then hidden), every
/// closure output, then every model output.
fn table_header(model: &ir::Model) -> Vec<String> {
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
    header
}

/// The table's columns at the knots `first..=last` that are record rows: the times, the
/// predicted `states`, and the run's closure outputs and model outputs.
fn table_columns(
    track: &Track,
    (first, last): (usize, usize),
    states: &[Vec<f64>],
    run: &Trajectory,
) -> Vec<Vec<f64>> {
    let knots = last + 1 - first;
    let rows: Vec<usize> = (first..=last)
        .filter(|&k| track.rows[k].is_some())
        .collect();
    let pick = |all: &[Vec<f64>]| -> Vec<Vec<f64>> {
        let padded = pad(all, knots);
        rows.iter().map(|&k| padded[k - first].clone()).collect()
    };
    let mut columns = vec![rows.iter().map(|&k| track.times[k]).collect()];
    columns.extend(transpose(&pick(states)));
    columns.extend(transpose(&pick(&run.closure_outputs)));
    columns.extend(transpose(&pick(&run.outputs)));
    columns
}

/// The states of a free run at each of `rows` rows: the offending state at the row where
/// it stopped, `NaN` after.
fn stopped_states(run: &Trajectory, rows: usize) -> Vec<Vec<f64>> {
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
