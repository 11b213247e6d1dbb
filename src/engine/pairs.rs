//! One-step training pairs from tracks (records on their integration grids): the delay
//! embedding at the RK4 stage times, held inputs, and the next states with their loss
//! weights (records spec, section 3).
//!
//! A pair is the step from knot `k` to knot `k + 1` of one track. Its embedding at stage
//! fraction `f` reads, for each `(var, lag)` of the layout, the track at time
//! `t_k + f h_k - lag * delay` ([`Track::stage_position`]):
//!
//! - **States** are read from the reference (measured cells and their interpolant, or the
//!   model's own fill). A lag-0 state is the stage estimate, supplied by the network; the
//!   value here is ignored.
//! - **Inputs** are held. The stage at the end of the step (`f = 1`) takes the left limit:
//!   a switch at `t_k + h` acts from the next step on.
//! - **Leakage**: a delayed value must not come from inside the step being predicted. With
//!   `delay >= h` every lag >= 1 lies at or before `t_k`; a closure with a delay below the
//!   grid's longest step is rejected before training
//!   ([`crate::train::TrainError::DelayBelowStep`]).
//!
//! A pair *measures its history* ([`measured_history`]) when every lagged read lies within
//! the record and every state it reads (the start state included) is known from data there:
//! the one-step objective and the offline error use only such pairs.

use crate::engine::batch::Batch;
use crate::ir::{self, Var};
use crate::record::grid::{hold, interpolate, Track};
use crate::solve::ode::tableau::RK4;

/// Positions this far before the first knot still count as inside the record (rounding).
const INSIDE: f64 = -1e-9;

/// The stage times of one step, as fractions of `h`: RK4's for `K` sub-steps, `m / 2K` for
/// `m = 0..=2K` ([`Tableau::stage_fractions`], `der` models), or only `0` (`next` models).
///
/// [`Tableau::stage_fractions`]: crate::solve::ode::tableau::Tableau::stage_fractions
pub fn stage_fractions(dynamics: ir::Dynamics, substeps: usize) -> Vec<f64> {
    match dynamics {
        ir::Dynamics::Discrete => vec![0.0],
        ir::Dynamics::Continuous => RK4.stage_fractions(substeps),
    }
}

/// The first knot of a uniform track whose step can be a pair with its whole embedding
/// inside the record: the embedding's history must fit before it.
pub fn first_pair_row(model: &ir::Model, step: f64) -> usize {
    let span = (model.closures.iter())
        .map(|c| c.embedding.span())
        .fold(0.0, f64::max);
    (span / step - 1e-9).ceil().max(0.0) as usize
}

/// The raw embedding of `closure` for the step from `knot` of `track`, at stage fraction
/// `fraction`.
pub fn embedding_row(closure: &ir::Closure, track: &Track, knot: usize, fraction: f64) -> Vec<f64> {
    let delay = closure.embedding.delay;
    (closure.embedding.layout().into_iter())
        .map(|(var, lag)| {
            let position = track.stage_position(knot, fraction, (lag, delay));
            match var {
                Var::State(i) => interpolate(&track.states[i], position),
                Var::Input(i) => hold(&track.inputs[i], position, fraction >= 1.0),
                _ => f64::NAN,
            }
        })
        .collect()
}

/// Whether the step from `knot` measures its history: the start's measured states known
/// from data, and every lagged read of every closure inside the record and (for states)
/// known from data.
pub fn measured_history(model: &ir::Model, track: &Track, knot: usize, fractions: &[f64]) -> bool {
    if !(0..model.states.len()).all(|i| track.known[i][knot]) {
        return false;
    }
    model.closures.iter().all(|closure| {
        let delay = closure.embedding.delay;
        closure.embedding.layout().into_iter().all(|(var, lag)| {
            lag == 0
                || fractions.iter().all(|&fraction| {
                    let position = track.stage_position(knot, fraction, (lag, delay));
                    position >= INSIDE
                        && match var {
                            Var::State(i) => track.known_between(i, position, position),
                            _ => true,
                        }
                })
        })
    })
}

/// Whether the knot after `knot` has a measured cell (of a state or an observable) to
/// compare with.
pub fn has_target(track: &Track, knot: usize) -> bool {
    knot + 1 < track.len() && track.has_cell(knot + 1)
}

/// One pair: track index and knot.
pub type PairAt = (usize, usize);

/// Precomputed pairs, row-major, ready to be gathered into batches.
#[derive(Debug, Clone, PartialEq)]
pub struct PairTable {
    /// The track and knot each pair starts at.
    pub pairs: Vec<PairAt>,
    state_width: usize,
    input_width: usize,
    measured: usize,
    widths: Vec<usize>,
    states: Vec<f64>,
    inputs: Vec<f64>,
    /// `embeddings[closure][stage]`, `pairs x width`.
    embeddings: Vec<Vec<Vec<f64>>>,
    targets: Vec<f64>,
    weights: Vec<f64>,
    steps: Vec<f64>,
    /// The observable outputs, their `pairs x observables` targets and weights.
    observables: usize,
    observed: Vec<f64>,
    observed_weights: Vec<f64>,
}

impl PairTable {
    /// The pairs `pairs` of `tracks`; `hidden[track][knot]` holds the hidden-state
    /// estimates (empty for models without hidden states, or before they are run in). A pair at a track's last knot
    /// has no target (it is kept for prediction; its target repeats the current state,
    /// with weight 0).
    pub fn build(
        model: &ir::Model,
        tracks: &[Track],
        pairs: &[PairAt],
        hidden: &[Vec<Vec<f64>>],
        fractions: &[f64],
    ) -> PairTable {
        let measured = model.states.len();
        let mut table = PairTable {
            pairs: pairs.to_vec(),
            state_width: measured + model.hidden.len(),
            input_width: model.inputs.len(),
            measured,
            widths: model.closures.iter().map(|c| c.embedding.width()).collect(),
            states: Vec::new(),
            inputs: Vec::new(),
            embeddings: vec![vec![Vec::new(); fractions.len()]; model.closures.len()],
            targets: Vec::new(),
            weights: Vec::new(),
            steps: Vec::new(),
            observables: 0,
            observed: Vec::new(),
            observed_weights: Vec::new(),
        };
        for &(index, knot) in pairs {
            let track = &tracks[index];
            let next = (knot + 1).min(track.len() - 1);
            table.states.extend(track.states.iter().map(|s| s[knot]));
            // Hidden states not run in yet hold 0 until [`PairTable::set_hidden`].
            let hidden_width = table.state_width - measured;
            match hidden.get(index).and_then(|h| h.get(knot)) {
                Some(values) if values.len() == hidden_width => table.states.extend(values),
                _ => table.states.extend(std::iter::repeat_n(0.0, hidden_width)),
            }
            table.inputs.extend(track.inputs.iter().map(|u| u[knot]));
            table.targets.extend(track.states.iter().map(|s| s[next]));
            let counts = next > knot;
            (table.weights).extend(track.measured.iter().map(|m| f64::from(counts && m[next])));
            table.steps.push(track.steps[knot]);
            for (closure, per_stage) in model.closures.iter().zip(&mut table.embeddings) {
                for (stage, &fraction) in per_stage.iter_mut().zip(fractions) {
                    stage.extend(embedding_row(closure, track, knot, fraction));
                }
            }
        }
        table
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// Whether there are no pairs.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// Adds the targets of the model outputs `outputs` (the observables, in the
    /// normalisation's order) at each pair's end, with weight 1 where measured and 0 where
    /// not.
    pub fn observe(&mut self, tracks: &[Track], outputs: &[usize]) {
        self.observables = outputs.len();
        self.observed.clear();
        self.observed_weights.clear();
        for &(index, knot) in &self.pairs {
            let track = &tracks[index];
            for &output in outputs {
                let cell = (knot + 1 < track.len())
                    .then(|| track.observed_cell(output, knot + 1))
                    .flatten();
                self.observed.push(cell.unwrap_or(0.0));
                self.observed_weights.push(f64::from(cell.is_some()));
            }
        }
    }

    /// Multiplies every target cell's loss weight by its column's `weights[state]`.
    pub fn scale_weights(&mut self, weights: &[f64]) {
        if weights.iter().all(|&w| w == 1.0) {
            return;
        }
        for row in self.weights.chunks_mut(self.measured.max(1)) {
            for (cell, weight) in row.iter_mut().zip(weights) {
                *cell *= weight;
            }
        }
    }

    /// Replaces the hidden-state estimates (`hidden[track][knot]` for each pair).
    pub fn set_hidden(&mut self, hidden: &[Vec<Vec<f64>>]) {
        let hidden_width = self.state_width - self.measured;
        for (pair, &(index, knot)) in self.pairs.iter().enumerate() {
            let estimates = hidden.get(index).and_then(|h| h.get(knot));
            if let Some(values) = estimates.filter(|v| v.len() == hidden_width) {
                let start = pair * self.state_width + self.measured;
                self.states[start..start + hidden_width].copy_from_slice(values);
            }
        }
    }

    /// Gathers pairs `indices` into a batch.
    pub fn batch(&self, indices: &[usize]) -> Batch {
        let gather = |block: &[f64], width: usize| -> Vec<f64> {
            let mut out = Vec::with_capacity(indices.len() * width);
            for &index in indices {
                out.extend_from_slice(&block[index * width..(index + 1) * width]);
            }
            out
        };
        Batch {
            rows: indices.len(),
            states: gather(&self.states, self.state_width),
            inputs: gather(&self.inputs, self.input_width),
            embeddings: (self.embeddings.iter().zip(&self.widths))
                .map(|(stages, &width)| stages.iter().map(|s| gather(s, width)).collect())
                .collect(),
            targets: gather(&self.targets, self.measured),
            step_sizes: gather(&self.steps, 1),
            weights: gather(&self.weights, self.measured),
            observed: gather(&self.observed, self.observables),
            observed_weights: gather(&self.observed_weights, self.observables),
        }
    }
}

#[cfg(test)]
mod tests;
