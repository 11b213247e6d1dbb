//! Running a trained network along a record: one-step (offline) predictions, free runs
//! (online), the run-in of hidden states, and the paper's two errors in normalised units.
//!
//! A free run given a [`PhysicalRange`] stops at the first predicted measured state that
//! leaves it or is not finite, and records where ([`Divergence`]); its online error is then
//! infinite, never a finite error over the rows before the stop.

use std::fmt;

use crate::backend::{BackendError, Batch, Network, Normalisation};
use crate::ir;

use super::pairs::{embedding_row, PairTable, Record};

/// Rows per prediction batch when evaluating many pairs at once.
const EVALUATION_CHUNK: usize = 512;

/// Mean squared errors of z-scored measured states. Infinite errors (a diverged free run)
/// are written to JSON as `null` and read back as infinite.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorSet {
    /// Per measured state, in model order: `(name, mse)`.
    #[serde(deserialize_with = "lenient::per_state")]
    pub per_state: Vec<(String, f64)>,
    /// Mean over states.
    #[serde(deserialize_with = "lenient::number")]
    pub overall: f64,
    /// Number of predicted rows the errors average over (up to the stop of a diverged run).
    pub rows: usize,
    /// Where a free run left the physical range (its errors are then infinite).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub divergence: Option<Divergence>,
}

/// The range each measured state of a free run must stay in.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalRange {
    /// Lower bound per measured state.
    pub lower: Vec<f64>,
    /// Upper bound per measured state.
    pub upper: Vec<f64>,
}

/// How far below zero, as a share of its training maximum, a state never negative in
/// training may go before a free run counts as diverged. A concentration near zero that a
/// model undershoots by a little is an error the MSE measures, not a blow-up; one a tenth
/// of its scale below zero is unphysical.
pub const UNDERSHOOT: f64 = 0.1;

impl PhysicalRange {
    /// From the training split's extremes: `[-UNDERSHOOT * max, factor * max]` for a state
    /// never negative in training, else `[-factor * max|x|, factor * max|x|]`. `None` when
    /// the normalisation has no extremes (runs saved before they were recorded).
    pub fn new(normalisation: &Normalisation, factor: f64) -> Option<PhysicalRange> {
        let (min, max) = (&normalisation.state_min, &normalisation.state_max);
        if min.is_empty() || min.len() != max.len() {
            return None;
        }
        let (lower, upper) = (min.iter().zip(max))
            .map(|(&lo, &hi)| {
                let largest = lo.abs().max(hi.abs());
                if lo >= 0.0 {
                    (-UNDERSHOOT * hi, factor * hi)
                } else {
                    (-factor * largest, factor * largest)
                }
            })
            .unzip();
        Some(PhysicalRange { lower, upper })
    }

    /// The first measured state of `state` outside the range or not finite.
    fn violation(&self, state: &[f64]) -> Option<usize> {
        (0..self.lower.len()).find(|&i| {
            let value = state.get(i).copied().unwrap_or(f64::NAN);
            let slack = 1e-9 * self.upper[i].abs().max(self.lower[i].abs());
            !value.is_finite() || value < self.lower[i] - slack || value > self.upper[i] + slack
        })
    }
}

/// Where and why a free run stopped.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Divergence {
    /// Record row of the offending state.
    pub row: usize,
    /// Its time.
    pub time: f64,
    /// The measured state.
    pub state: String,
    /// Its predicted value (a non-finite one is written as `null`, read back as NaN).
    #[serde(deserialize_with = "lenient::not_a_number")]
    pub value: f64,
    /// The range it had to stay in.
    pub range: (f64, f64),
}

impl fmt::Display for Divergence {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (lo, hi) = self.range;
        if self.value.is_finite() {
            write!(
                formatter,
                "the free run left the physical range at t = {} (row {}): {} = {:.4e}, outside \
                 [{lo:.4e}, {hi:.4e}]",
                self.time, self.row, self.state, self.value
            )
        } else {
            write!(
                formatter,
                "the free run became non-finite at t = {} (row {}): {} = {}",
                self.time, self.row, self.state, self.value
            )
        }
    }
}

/// How measured states evolve along a simulated trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feed {
    /// Measured states are reset to the data at every step (one-step predictions; used to
    /// run hidden states in along the record).
    Data,
    /// The network is fed its own predictions, through the state and the embedding alike.
    Own,
}

/// A trajectory from row `start` to row `end`, inclusive.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// First row.
    pub start: usize,
    /// Per row: the state vector (measured, then hidden) the step from that row starts at.
    pub states: Vec<Vec<f64>>,
    /// Per row: the one-step prediction made from it.
    pub next_states: Vec<Vec<f64>>,
    /// Per row: every closure output at that row.
    pub closure_outputs: Vec<Vec<f64>>,
    /// Per row: the model's outputs at that row.
    pub outputs: Vec<Vec<f64>>,
    /// Where the run stopped early, if it left the physical range.
    pub divergence: Option<Divergence>,
}

/// Simulates rows `start..=end` of `record` step by step, starting from the measured states
/// of row `start` and the hidden states `hidden_start`, inputs taken from the data. With
/// `Feed::Own` and a physical range, stops after the first prediction outside it.
pub fn simulate(
    network: &Network,
    model: &ir::Model,
    record: &Record,
    fractions: &[f64],
    rows: (usize, usize),
    hidden_start: &[f64],
    (feed, range): (Feed, Option<&PhysicalRange>),
) -> Result<Trajectory, BackendError> {
    let (start, end) = rows;
    let measured = model.states.len();
    let mut history = record.clone();
    let mut state: Vec<f64> = record.states.iter().map(|s| s[start]).collect();
    state.extend_from_slice(hidden_start);
    let mut trajectory = Trajectory {
        start,
        states: Vec::new(),
        next_states: Vec::new(),
        closure_outputs: Vec::new(),
        outputs: Vec::new(),
        divergence: None,
    };
    for row in start..=end {
        let batch = Batch {
            rows: 1,
            states: state.clone(),
            inputs: record.inputs.iter().map(|u| u[row]).collect(),
            embeddings: (model.closures.iter())
                .map(|c| {
                    (fractions.iter())
                        .map(|&f| embedding_row(c, &history, row, f))
                        .collect()
                })
                .collect(),
            targets: Vec::new(),
            step_sizes: Vec::new(),
            weights: Vec::new(),
        };
        let prediction = network.predict(&batch)?;
        trajectory.states.push(std::mem::take(&mut state));
        trajectory.closure_outputs.push(prediction.closure_outputs);
        trajectory.outputs.push(prediction.outputs);
        let next = prediction.next_states;
        if let Some(range) = range.filter(|_| feed == Feed::Own) {
            if let Some(state) = range.violation(&next) {
                trajectory.divergence = Some(Divergence {
                    row: row + 1,
                    time: record.times.get(row + 1).copied().unwrap_or(f64::NAN),
                    state: model.states[state].name.clone(),
                    value: next[state],
                    range: (range.lower[state], range.upper[state]),
                });
                trajectory.next_states.push(next);
                break;
            }
        }
        if row + 1 < record.len() {
            state = match feed {
                Feed::Own => {
                    for (series, &value) in history.states.iter_mut().zip(&next) {
                        series[row + 1] = value;
                    }
                    next.clone()
                }
                Feed::Data => {
                    let mut reset: Vec<f64> = record.states.iter().map(|s| s[row + 1]).collect();
                    reset.extend_from_slice(&next[measured..]);
                    reset
                }
            };
        }
        trajectory.next_states.push(next);
    }
    Ok(trajectory)
}

/// Hidden-state estimates at every row of `record`: from their initial values at row 0,
/// integrated along the record with the measured states taken from the data. Empty rows
/// for models without hidden states.
pub fn run_in_hidden(
    network: &Network,
    model: &ir::Model,
    record: &Record,
    fractions: &[f64],
    initial: &[f64],
) -> Result<Vec<Vec<f64>>, BackendError> {
    if model.hidden.is_empty() || record.is_empty() {
        return Ok(vec![Vec::new(); record.len()]);
    }
    let last = record.len() - 1;
    let run = simulate(
        network,
        model,
        record,
        fractions,
        (0, last),
        initial,
        (Feed::Data, None),
    )?;
    let measured = model.states.len();
    Ok(run
        .states
        .into_iter()
        .map(|s| s[measured..].to_vec())
        .collect())
}

/// Offline error: one step from the true history for every pair of `table`.
pub fn offline_error(
    network: &Network,
    model: &ir::Model,
    table: &PairTable,
    normalisation: &Normalisation,
) -> Result<ErrorSet, BackendError> {
    let measured = model.states.len();
    let width = measured + model.hidden.len();
    let mut squared = vec![0.0; measured];
    let indices: Vec<usize> = (0..table.len()).collect();
    for chunk in indices.chunks(EVALUATION_CHUNK) {
        let batch = table.batch(chunk);
        let prediction = network.predict(&batch)?;
        for row in 0..chunk.len() {
            for (state, total) in squared.iter_mut().enumerate() {
                let error = prediction.next_states[row * width + state]
                    - batch.targets[row * measured + state];
                *total += (error / normalisation.state_std[state]).powi(2);
            }
        }
    }
    Ok(error_set(model, squared, table.len()))
}

/// JSON has no infinity or NaN: `serde_json` writes them as `null`; read `null` back.
mod lenient {
    use serde::{Deserialize, Deserializer};

    /// A number, `null` read as infinity.
    pub fn number<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::INFINITY))
    }

    /// A number, `null` read as NaN.
    pub fn not_a_number<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
    }

    /// `(name, number)` pairs, `null` read as infinity.
    pub fn per_state<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Vec<(String, f64)>, D::Error> {
        let pairs = Vec::<(String, Option<f64>)>::deserialize(deserializer)?;
        Ok((pairs.into_iter())
            .map(|(name, value)| (name, value.unwrap_or(f64::INFINITY)))
            .collect())
    }
}

/// Online error of a free run against the record, over the rows after its start; infinite
/// for every state when the run diverged.
pub fn online_error(
    model: &ir::Model,
    record: &Record,
    run: &Trajectory,
    normalisation: &Normalisation,
) -> ErrorSet {
    let measured = model.states.len();
    if let Some(divergence) = &run.divergence {
        let mut set = error_set(model, vec![f64::INFINITY; measured], 1);
        set.rows = run.next_states.len();
        set.divergence = Some(divergence.clone());
        return set;
    }
    let mut squared = vec![0.0; measured];
    let mut rows = 0;
    for (offset, next) in run.next_states.iter().enumerate() {
        let row = run.start + offset + 1;
        if row >= record.len() {
            break;
        }
        for (state, total) in squared.iter_mut().enumerate() {
            let error = next[state] - record.states[state][row];
            *total += (error / normalisation.state_std[state]).powi(2);
        }
        rows += 1;
    }
    error_set(model, squared, rows)
}

fn error_set(model: &ir::Model, squared: Vec<f64>, rows: usize) -> ErrorSet {
    let count = rows.max(1) as f64;
    let per_state: Vec<(String, f64)> = (model.states.iter().zip(squared))
        .map(|(state, total)| (state.name.clone(), total / count))
        .collect();
    let overall = per_state.iter().map(|(_, e)| e).sum::<f64>() / per_state.len().max(1) as f64;
    ErrorSet {
        per_state,
        overall,
        rows,
        divergence: None,
    }
}
