//! Running a trained network along a track: one-step (offline) predictions, free runs
//! (online), the run-in of hidden states and of the reference where the data leave it
//! unknown, and the paper's two errors in normalised units, over measured cells only.
//!
//! A free run given a [`PhysicalRange`] stops at the first predicted measured state that
//! leaves it or is not finite, and records where ([`Divergence`]); its online error is then
//! infinite, never a finite error over the knots before the stop.
//!
//! A free run goes through the one free run ([`crate::solve::ode::free_run`]): its segments
//! are the knots, its stepper the network's step ([`NetworkStep`]), and after each knot the
//! run feeds the next (the data or its own prediction) and checks the physical range.

use crate::engine::graph::{BackendError, Network, Normalisation};
use crate::ir;
use crate::record::measure::{cell_error, StateErrors};
use crate::record::Track;
use crate::solve::ode::{free_run, Observer, Segment};
use std::ops::ControlFlow;

use super::stepping::{NetworkStep, Stepping};
use crate::engine::pairs::PairTable;

mod range;

#[cfg(test)]
pub use range::UNDERSHOOT;
pub use range::{Divergence, PhysicalRange};

/// Rows per prediction batch when evaluating many pairs at once.
const EVALUATION_CHUNK: usize = 512;

/// Mean squared errors of z-scored measured states, each over its measured cells. Infinite
/// errors (a diverged free run) are written to JSON as `"inf"` ([`crate::json`]; a `null`
/// of older files reads as infinite).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorSet {
    /// Per measured state with at least one scored cell, in model order: `(name, mse)`.
    #[serde(with = "crate::json::null_is_infinite")]
    pub per_state: Vec<(String, f64)>,
    /// Mean over those states.
    #[serde(with = "crate::json::null_is_infinite")]
    pub overall: f64,
    /// Number of predicted knots the errors average over (up to the stop of a diverged
    /// run).
    pub rows: usize,
    /// Number of measured cells scored.
    #[serde(default)]
    pub cells: usize,
    /// Where a free run left the physical range (its errors are then infinite).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub divergence: Option<Divergence>,
}

/// How measured states evolve along a simulated trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feed {
    /// Measured states are reset to the reference wherever it is known from data, and
    /// run free (into the embedding too) where it is not: one-step predictions, the run-in
    /// of hidden states and the model's fill of unknown stretches.
    Data,
    /// The network is fed its own predictions, through the state and the embedding alike.
    Own,
}

/// A trajectory from knot `start` to knot `end`, inclusive.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// First knot.
    pub start: usize,
    /// Per knot: the state vector (measured, then hidden) the step from that knot starts at.
    pub states: Vec<Vec<f64>>,
    /// Per knot: the one-step prediction made from it.
    pub next_states: Vec<Vec<f64>>,
    /// Per knot: every closure output at that knot.
    pub closure_outputs: Vec<Vec<f64>>,
    /// Per knot: the model's outputs at that knot.
    pub outputs: Vec<Vec<f64>>,
    /// Where the run stopped early, if it left the physical range.
    pub divergence: Option<Divergence>,
    /// The most sub-steps one step needed (1 at the trained step; [`Stepping`]).
    pub substeps: usize,
}

/// Simulates knots `start..=end` of `track` step by step, starting from the reference
/// states at knot `start` and the hidden states `hidden_start`, inputs taken from the data.
/// With `Feed::Own` and a physical range, stops after the first prediction outside it.
pub fn simulate(
    network: &Network,
    model: &ir::Model,
    track: &Track,
    fractions: &[f64],
    knots: (usize, usize),
    hidden_start: &[f64],
    (feed, range, stepping): (Feed, Option<&PhysicalRange>, Stepping),
) -> Result<Trajectory, BackendError> {
    let (start, end) = knots;
    let mut state: Vec<f64> = track.states.iter().map(|s| s[start]).collect();
    state.extend_from_slice(hidden_start);
    let scales: Vec<f64> = (track.states.iter())
        .map(|s| s.iter().fold(0.0, |m: f64, v| m.max(v.abs())))
        .chain(hidden_start.iter().map(|h| h.abs()))
        .collect();
    let mut stepper = NetworkStep::new((network, model), track, fractions, &scales, stepping);
    let declared = range
        .filter(|_| feed == Feed::Own)
        .map(|r| r.declared(model));
    let mut knots = Knots {
        track,
        feed,
        range: declared.as_ref(),
        names: model.states.iter().map(|s| s.name.clone()).collect(),
        trajectory: Trajectory {
            start,
            states: Vec::new(),
            next_states: Vec::new(),
            closure_outputs: Vec::new(),
            outputs: Vec::new(),
            divergence: None,
            substeps: 1,
        },
    };
    let segments = (start..=end).map(|knot| Segment {
        index: knot,
        span: (
            track.times[knot],
            track.times.get(knot + 1).copied().unwrap_or(f64::NAN),
        ),
        samples: &[],
    });
    free_run(&mut stepper, segments, &mut state, &mut knots)?;
    let mut trajectory = knots.trajectory;
    trajectory.substeps = stepper.most();
    Ok(trajectory)
}

/// A grey box's free run along a track, knot by knot: what it records, and its say after
/// each knot (the feed and the physical range).
struct Knots<'a> {
    track: &'a Track,
    feed: Feed,
    /// The physical range a run fed its own predictions stops outside of.
    range: Option<&'a PhysicalRange>,
    /// The measured states' names.
    names: Vec<String>,
    trajectory: Trajectory,
}

impl Observer<NetworkStep<'_>> for Knots<'_> {
    fn before(&mut self, _: &Segment<'_>, state: &[f64]) -> Result<(), BackendError> {
        if crate::stop::requested() {
            return Err(BackendError::Stopped);
        }
        self.trajectory.states.push(state.to_vec());
        Ok(())
    }

    fn sample(&mut self, _: &[f64], _: &[f64]) {}

    /// Records the knot's prediction; stops a run that left the physical range; feeds the
    /// next knot: a measured state from the data where [`Feed::Data`] knows it there, else
    /// the run's own value, into the history the embedding reads too.
    fn after(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        stepper: &mut NetworkStep<'_>,
    ) -> Result<ControlFlow<()>, BackendError> {
        let knot = segment.index;
        let prediction = (stepper.take_prediction())
            .ok_or_else(|| BackendError::internal("a knot stepped without a prediction"))?;
        self.trajectory
            .closure_outputs
            .push(prediction.closure_outputs);
        self.trajectory.outputs.push(prediction.outputs);
        let next = state.to_vec();
        if let Some(range) = self.range {
            let at = (self.track.name.as_str(), knot + 1, segment.span.1);
            if let Some(divergence) = range.check(&self.names, at, &next) {
                self.trajectory.divergence = Some(divergence);
                self.trajectory.next_states.push(next);
                return Ok(ControlFlow::Break(()));
            }
        }
        if knot + 1 < self.track.len() {
            let track = self.track;
            for (index, value) in state.iter_mut().enumerate().take(self.names.len()) {
                if self.feed == Feed::Data && track.known[index][knot + 1] {
                    *value = track.states[index][knot + 1];
                } else {
                    stepper.remember(index, knot + 1, *value);
                }
            }
        }
        self.trajectory.next_states.push(next);
        Ok(ControlFlow::Continue(()))
    }
}

/// What a run along a whole track from its first knot gives: hidden-state estimates at
/// every knot, and the model's values of every measured state (equal to the reference
/// where it is known, the model's own run where it is not).
pub struct RunIn {
    /// `hidden[knot]`: the hidden states (empty for models without any).
    pub hidden: Vec<Vec<f64>>,
    /// `states[i][knot]`: the run's measured state `i`.
    pub states: Vec<Vec<f64>>,
}

/// Runs `track` from its first knot with [`Feed::Data`], the hidden states from `initial`.
pub fn run_in(
    network: &Network,
    model: &ir::Model,
    track: &Track,
    fractions: &[f64],
    initial: &[f64],
) -> Result<RunIn, BackendError> {
    let measured = model.states.len();
    let needed = !model.hidden.is_empty() || !track.fully_known();
    if !needed || track.is_empty() {
        return Ok(RunIn {
            hidden: vec![
                Vec::new();
                if model.hidden.is_empty() {
                    track.len()
                } else {
                    0
                }
            ],
            states: track.states.clone(),
        });
    }
    let run = simulate(
        network,
        model,
        track,
        fractions,
        (0, track.len() - 1),
        initial,
        (Feed::Data, None, Stepping::Controlled),
    )?;
    let hidden = (run.states.iter())
        .map(|s| s[measured..].to_vec())
        .collect();
    let states = (0..measured)
        .map(|index| run.states.iter().map(|s| s[index]).collect())
        .collect();
    Ok(RunIn { hidden, states })
}

/// Squared z-scored errors summed per measured state and observable, with their cell
/// counts: errors of several runs pool into one [`ErrorSet`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ErrorSum {
    names: Vec<String>,
    errors: StateErrors,
    rows: usize,
    divergence: Option<Divergence>,
}

impl ErrorSum {
    /// Zero for `model`'s measured states, then the observables of `normalisation`.
    pub fn new(model: &ir::Model, normalisation: &Normalisation) -> Self {
        let names: Vec<String> = (model.states.iter().map(|s| s.name.clone()))
            .chain(
                (normalisation.observables.iter())
                    .filter_map(|&o| model.outputs.get(o).map(|d| d.name.clone())),
            )
            .collect();
        ErrorSum {
            errors: StateErrors::new(names.len()),
            names,
            rows: 0,
            divergence: None,
        }
    }

    /// Adds the squared z-scored error of one cell of column `column` (states, then
    /// observables).
    pub fn add(&mut self, column: usize, squared: f64) {
        self.errors.add(column, squared);
    }

    /// Adds another sum (a diverged run makes the whole set infinite).
    pub fn merge(&mut self, other: &ErrorSum) {
        self.errors.merge(&other.errors);
        self.rows += other.rows;
        if self.divergence.is_none() {
            self.divergence = other.divergence.clone();
        }
    }

    /// The mean squared errors per column (columns without a cell left out) and their
    /// mean; `None` when no cell was scored.
    pub fn finish(&self) -> Option<ErrorSet> {
        let cells = self.errors.cells();
        if let Some(divergence) = &self.divergence {
            return Some(ErrorSet {
                per_state: (self.names.iter())
                    .map(|name| (name.clone(), f64::INFINITY))
                    .collect(),
                overall: f64::INFINITY,
                rows: self.rows,
                cells,
                divergence: Some(divergence.clone()),
            });
        }
        if cells == 0 {
            return None;
        }
        let per_state: Vec<(String, f64)> = (self.names.iter().zip(self.errors.nmse()))
            .filter_map(|(name, nmse)| Some((name.clone(), nmse?)))
            .collect();
        Some(ErrorSet {
            overall: self.errors.error(),
            per_state,
            rows: self.rows,
            cells,
            divergence: None,
        })
    }
}

/// Offline error: one step from the true history for every pair of `table`, over the
/// measured cells of the targets.
pub fn offline_error(
    network: &Network,
    model: &ir::Model,
    table: &PairTable,
    normalisation: &Normalisation,
) -> Result<ErrorSum, BackendError> {
    let measured = model.states.len();
    let width = measured + model.hidden.len();
    let observables = normalisation.observables.len();
    let mut sum = ErrorSum::new(model, normalisation);
    let indices: Vec<usize> = (0..table.len()).collect();
    for chunk in indices.chunks(EVALUATION_CHUNK) {
        let batch = table.batch(chunk);
        let prediction = network.predict(&batch)?;
        for row in 0..chunk.len() {
            for state in 0..measured {
                if batch.weights[row * measured + state] <= 0.0 {
                    continue;
                }
                let predicted = prediction.next_states[row * width + state];
                let target = batch.targets[row * measured + state];
                sum.add(
                    state,
                    cell_error(predicted, target, normalisation.state_std[state]),
                );
            }
            for index in 0..observables {
                let cell = row * observables + index;
                if batch.observed_weights[cell] <= 0.0 {
                    continue;
                }
                let std = normalisation.observable_std[index];
                sum.add(
                    measured + index,
                    cell_error(prediction.observed[cell], batch.observed[cell], std),
                );
            }
        }
    }
    sum.rows = table.len();
    Ok(sum)
}

/// Online error of a free run against the track's measured cells at knots after its start
/// and at or after `scored_from` (a time); infinite for every state when the run diverged.
pub fn online_error(
    model: &ir::Model,
    track: &Track,
    run: &Trajectory,
    (normalisation, scored_from): (&Normalisation, f64),
) -> ErrorSum {
    let measured = model.states.len();
    let mut sum = ErrorSum::new(model, normalisation);
    if let Some(divergence) = &run.divergence {
        sum.rows = run.next_states.len();
        sum.divergence = Some(divergence.clone());
        return sum;
    }
    for (offset, next) in run.next_states.iter().enumerate() {
        let knot = run.start + offset + 1;
        if knot >= track.len() {
            break;
        }
        if track.times[knot] < scored_from {
            continue;
        }
        for (state, &value) in next.iter().enumerate().take(measured) {
            if track.measured[state][knot] {
                let std = normalisation.state_std[state];
                sum.add(state, cell_error(value, track.states[state][knot], std));
            }
        }
        // The outputs at a knot come from the step that starts there.
        let outputs = run.outputs.get(offset + 1);
        for (index, &output) in normalisation.observables.iter().enumerate() {
            let predicted = outputs.and_then(|o| o.get(output));
            if let (Some(value), Some(predicted)) = (track.observed_cell(output, knot), predicted) {
                let std = normalisation.observable_std[index];
                sum.add(measured + index, cell_error(*predicted, value, std));
            }
        }
        sum.rows += 1;
    }
    sum
}
