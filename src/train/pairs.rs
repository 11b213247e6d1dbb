//! One-step training pairs from a record: the delay embedding at the RK4 stage times, held
//! inputs, and the measured next states (spec section 3).
//!
//! Positions are measured in samples from the first row: a stage at time `t_i + f h`
//! looking back `lag` delays sits at `i + f - lag * delay / h`.
//!
//! - **States** between samples are interpolated linearly. A lag-0 state is the stage
//!   estimate, supplied by the network; the value here is ignored.
//! - **Inputs** are held (zero-order hold): the value of the sample at or before the
//!   position. The stage at the end of the step (`f = 1`) takes the left limit instead, as
//!   the integral over `[t_i, t_i + h)` sees it: a switch at `t_i + h` acts from the next
//!   step on, as in a simulator that holds inputs over each sampling interval.
//! - **Leakage**: a delayed value must not come from inside the step being predicted. With
//!   `delay >= h` every lag >= 1 lies at or before `t_i`; a closure with `delay < h` is
//!   rejected before training ([`crate::train::TrainError::DelayBelowStep`]).
//! - The first `(dim - 1) delay` of a record only fills the embedding: the first pair starts
//!   at row [`first_pair_row`]. Positions before the record (only reached when the hidden
//!   states are run in from row 0) repeat the first sample.

use crate::backend::Batch;
use crate::ir::{self, Var};

/// Positions this close to a sample are that sample (rounding of `i + m / 2K - lag d / h`).
const SNAP: f64 = 1e-9;

/// A uniformly sampled record in model terms: one series per input and measured state.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Sampling step `h`.
    pub step: f64,
    /// Sample times.
    pub times: Vec<f64>,
    /// `inputs[i][row]`, in model input order.
    pub inputs: Vec<Vec<f64>>,
    /// `states[i][row]`, in model measured-state order.
    pub states: Vec<Vec<f64>>,
}

impl Record {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the record has no rows.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
}

/// Linear interpolation of `values` at a fractional sample `position` (clamped to the
/// record).
pub fn interpolate(values: &[f64], position: f64) -> f64 {
    let last = values.len().saturating_sub(1);
    let position = snap(position).clamp(0.0, last as f64);
    let below = position.floor() as usize;
    let fraction = position - below as f64;
    if fraction == 0.0 || below >= last {
        return values[below.min(last)];
    }
    values[below] * (1.0 - fraction) + values[below + 1] * fraction
}

/// Zero-order hold of `values` at a fractional sample `position`: the sample at or before
/// it, or with `left_limit` the sample strictly before it when it falls on a sample.
pub fn hold(values: &[f64], position: f64, left_limit: bool) -> f64 {
    let last = values.len().saturating_sub(1) as f64;
    let position = snap(position);
    let index = if left_limit {
        position.ceil() - 1.0
    } else {
        position.floor()
    };
    values[index.clamp(0.0, last) as usize]
}

/// A fractional sample position, snapped onto the nearest sample when within rounding of it.
pub fn snap(position: f64) -> f64 {
    let nearest = position.round();
    if (position - nearest).abs() < SNAP {
        nearest
    } else {
        position
    }
}

/// The first row whose step is a training pair: the embedding's history must fit before it.
pub fn first_pair_row(model: &ir::Model, step: f64) -> usize {
    let span = (model.closures.iter())
        .map(|c| c.embedding.span())
        .fold(0.0, f64::max);
    (span / step - SNAP).ceil().max(0.0) as usize
}

/// The stage times of one step, as fractions of `h`: `m / 2K` for `m = 0..=2K` (`der`
/// models), or only `0` (`next` models).
pub fn stage_fractions(dynamics: ir::Dynamics, substeps: usize) -> Vec<f64> {
    match dynamics {
        ir::Dynamics::Discrete => vec![0.0],
        ir::Dynamics::Continuous => {
            let halves = 2 * substeps.max(1);
            (0..=halves).map(|m| m as f64 / halves as f64).collect()
        }
    }
}

/// The raw embedding of `closure` for the step starting at `row`, at stage fraction
/// `fraction`, read from `record`.
pub fn embedding_row(
    closure: &ir::Closure,
    record: &Record,
    row: usize,
    fraction: f64,
) -> Vec<f64> {
    let embedding = &closure.embedding;
    let lag_in_samples = embedding.delay / record.step;
    (embedding.layout().into_iter())
        .map(|(var, lag)| {
            let position = row as f64 + fraction - lag as f64 * lag_in_samples;
            match var {
                Var::State(i) => interpolate(&record.states[i], position),
                Var::Input(i) => hold(&record.inputs[i], position, fraction >= 1.0),
                _ => f64::NAN,
            }
        })
        .collect()
}

/// Precomputed pairs, row-major, ready to be gathered into batches.
#[derive(Debug, Clone, PartialEq)]
pub struct PairTable {
    /// The record row each pair starts at.
    pub rows: Vec<usize>,
    state_width: usize,
    input_width: usize,
    measured: usize,
    widths: Vec<usize>,
    states: Vec<f64>,
    inputs: Vec<f64>,
    /// `embeddings[closure][stage]`, `pairs x width`.
    embeddings: Vec<Vec<Vec<f64>>>,
    targets: Vec<f64>,
}

impl PairTable {
    /// Pairs starting at `rows` of `record`; `hidden[row]` holds the hidden-state estimates
    /// (empty rows for models without hidden states). A pair at the last row has no target
    /// (it is kept for prediction; its target repeats the current state).
    pub fn build(
        model: &ir::Model,
        record: &Record,
        rows: &[usize],
        hidden: &[Vec<f64>],
        fractions: &[f64],
    ) -> PairTable {
        let measured = model.states.len();
        let mut table = PairTable {
            rows: rows.to_vec(),
            state_width: measured + model.hidden.len(),
            input_width: model.inputs.len(),
            measured,
            widths: model.closures.iter().map(|c| c.embedding.width()).collect(),
            states: Vec::new(),
            inputs: Vec::new(),
            embeddings: vec![vec![Vec::new(); fractions.len()]; model.closures.len()],
            targets: Vec::new(),
        };
        let last = record.len().saturating_sub(1);
        for &row in rows {
            table.states.extend(record.states.iter().map(|s| s[row]));
            table.states.extend(hidden.get(row).into_iter().flatten());
            table.inputs.extend(record.inputs.iter().map(|u| u[row]));
            let next = (row + 1).min(last);
            table.targets.extend(record.states.iter().map(|s| s[next]));
            for (closure, per_stage) in model.closures.iter().zip(&mut table.embeddings) {
                for (stage, &fraction) in per_stage.iter_mut().zip(fractions) {
                    stage.extend(embedding_row(closure, record, row, fraction));
                }
            }
        }
        table
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether there are no pairs.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The measured target block `pairs x measured`.
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// Replaces the hidden-state estimates (`hidden[row]` for each pair's row).
    pub fn set_hidden(&mut self, hidden: &[Vec<f64>]) {
        let hidden_width = self.state_width - self.measured;
        for (pair, &row) in self.rows.iter().enumerate() {
            if let Some(values) = hidden.get(row).filter(|v| v.len() == hidden_width) {
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
            step_sizes: Vec::new(),
            weights: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Activation;
    use crate::train::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};

    fn check_interpolate(values: &[f64], position: f64, expected: f64) {
        let found = interpolate(values, position);
        assert!(
            (found - expected).abs() < 1e-12,
            "at {position}: {found} vs {expected}"
        );
    }

    #[test]
    fn interpolation_is_linear_between_samples_and_exact_on_them() {
        let values = [1.0, 3.0, 2.0, 6.0];
        check_interpolate(&values, 0.0, 1.0);
        check_interpolate(&values, 0.5, 2.0);
        check_interpolate(&values, 1.25, 2.75);
        check_interpolate(&values, 2.0 - 1e-12, 2.0);
        check_interpolate(&values, 2.75, 5.0);
        check_interpolate(&values, 3.0, 6.0);
        check_interpolate(&values, -2.0, 1.0);
    }

    #[test]
    fn hold_keeps_the_sample_at_or_before_and_left_limits_at_stage_ends() {
        let values = [10.0, 20.0, 30.0];
        assert_eq!(hold(&values, 1.0, false), 20.0);
        assert_eq!(hold(&values, 1.5, false), 20.0);
        assert_eq!(hold(&values, 1.5, true), 20.0);
        assert_eq!(hold(&values, 2.0, true), 20.0);
        assert_eq!(hold(&values, 2.0 - 1e-12, false), 30.0);
        assert_eq!(hold(&values, 0.0, true), 10.0);
    }

    /// A closure observing a state and an input with a delay of 1.5 samples, checked at
    /// every RK4 stage time against values worked out by hand.
    #[test]
    fn embedding_at_stage_times_matches_hand_computed_values() {
        let model = ModelBuilder::new("m")
            .input("u")
            .state("x")
            .closure(ClosureSpec {
                name: "c",
                outputs: vec![OutputSpec {
                    name: "o",
                    scale: Some(1.0),
                    prior: None,
                }],
                observe: &["x", "u"],
                delay: 3.0,
                dim: 3,
                hidden: vec![2],
                activation: Activation::Tanh,
            })
            .der("x", "o")
            .build();
        // h = 2, so the delay is 1.5 samples and the embedding needs 3 samples of history.
        let record = Record {
            step: 2.0,
            times: (0..8).map(|i| 2.0 * i as f64).collect(),
            inputs: vec![vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]],
            states: vec![vec![0.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0]],
        };
        assert_eq!(first_pair_row(&model, record.step), 3);
        let fractions = stage_fractions(model.dynamics, 1);
        assert_eq!(fractions, vec![0.0, 0.5, 1.0]);
        let closure = &model.closures[0];
        // Layout: [x(t), u(t), x(t-3), u(t-3), x(t-6), u(t-6)], step from row 4 (t = 8).
        // Stage t = 8: x at samples 4, 2.5, 1 -> 80, 30, 10; u held at 4, 2.5, 1 -> 4, 2, 1.
        let start = embedding_row(closure, &record, 4, 0.0);
        assert_eq!(start, vec![80.0, 4.0, 30.0, 2.0, 10.0, 1.0]);
        // Stage t = 9: samples 4.5, 3, 1.5 -> x 120, 40, 15; u 4, 3 (switched at 3), 1.
        let middle = embedding_row(closure, &record, 4, 0.5);
        assert_eq!(middle, vec![120.0, 4.0, 40.0, 3.0, 15.0, 1.0]);
        // Stage t = 10: samples 5, 3.5, 2 -> x 160, 60, 20; u 4 (left limit: held over the
        // step), 3, 1 (left limit at 2).
        let end = embedding_row(closure, &record, 4, 1.0);
        assert_eq!(end, vec![160.0, 4.0, 60.0, 3.0, 20.0, 1.0]);
        let table = PairTable::build(&model, &record, &[4, 6], &[], &fractions);
        let batch = table.batch(&[1, 0]);
        assert_eq!(batch.states, vec![320.0, 80.0]);
        assert_eq!(batch.inputs, vec![6.0, 4.0]);
        assert_eq!(batch.targets, vec![640.0, 160.0]);
        assert_eq!(&batch.embeddings[0][2][6..], &end[..]);
    }
}
