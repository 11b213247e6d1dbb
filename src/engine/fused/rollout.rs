//! Windows of steps on the fused kernel: a batch of one-step pairs is a window of one step,
//! a [`RolloutBatch`] one of `K` steps in which the network is fed its own predictions,
//! through the state and, by [`Feedback`], through the delay embedding.
//!
//! **Forward.** Step `k` starts from the state the window reached; before it runs, every
//! feedback entry of the step adds `weight / std` times the predicted state it names to its
//! network input column. Those shares are known before the step, so they join the step's
//! constant embedding part, whose product with the first weight matrix is formed once per
//! stage time ([`super::kernel`]), and the first weight matrix's gradient
//! `constants^T delta` covers them too.
//!
//! **Loss**, as the graph backend's: `sum(w r^2) / #(w > 0)` over the z-scored residuals `r`
//! of every weighted measured cell of every step (a step without weights counts every
//! cell).
//!
//! **Reverse.** The steps are reversed last to first. The adjoint of the state after step
//! `k` is its loss seed plus what later steps sent back: the adjoint of step `k + 1`'s start
//! state and, for each feedback entry that read it, `weight / std` times the product of that
//! step's first-layer delta (summed over the stages at the entry's stage time) with row
//! `column` of the first weight matrix. Each step's reverse ([`Kernel::backward_step`]) turns
//! the adjoint of its end state into that of its start state, accumulating the weight and
//! param gradients.

use crate::engine::batch::{Batch, Feedback, RolloutBatch};
use crate::engine::error::BackendError;

use super::activation::Lane;
use super::buffers::{FedBack, StepData};
use super::dense::View;
use super::kernel::Kernel;
use super::rows::add_scaled;

/// One step's share of a batch, before it is checked.
struct StepSource<'a> {
    inputs: &'a [f64],
    embeddings: &'a [Vec<Vec<f64>>],
    step_sizes: &'a [f64],
    targets: &'a [f64],
    weights: &'a [f64],
}

fn unfit(what: &str) -> BackendError {
    BackendError::internal(format!("the batch does not fit the model: {what}"))
}

impl<E: Lane> Kernel<E> {
    /// The normalised one-step loss of the batch; its gradient is left in
    /// [`Kernel::gradient`].
    pub fn loss_and_gradient(&mut self, batch: &Batch) -> Result<f64, BackendError> {
        self.begin(batch.rows, 1, &batch.states)?;
        let source = StepSource {
            inputs: &batch.inputs,
            embeddings: &batch.embeddings,
            step_sizes: &batch.step_sizes,
            targets: &batch.targets,
            weights: &batch.weights,
        };
        self.load_step(0, source)?;
        Ok(self.run(true))
    }

    /// The loss of a rollout batch over every step of every window; its gradient through
    /// the whole rollout is left in [`Kernel::gradient`].
    pub fn rollout_loss_and_gradient(&mut self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        self.load_windows(batch)?;
        Ok(self.run(true))
    }

    /// The loss of a rollout batch (no gradient).
    pub fn rollout_loss(&mut self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        self.load_windows(batch)?;
        Ok(self.run(false))
    }

    /// Runs the loaded window forward, then (with `gradient`) in reverse; the loss.
    fn run(&mut self, gradient: bool) -> f64 {
        for step in 0..self.steps {
            self.feed_back(step);
            self.forward_step(step);
        }
        let loss = self.window_loss();
        if gradient {
            self.gradient.fill(E::ZERO);
            for step in (0..self.steps).rev() {
                let mut upstream = std::mem::take(&mut self.adjoints[step + 1]);
                self.backward_step(step, &mut upstream);
                self.feedback_adjoints(step);
                add_scaled(&mut self.adjoints[step], 1.0, &upstream);
                self.adjoints[step + 1] = upstream;
            }
        }
        loss
    }

    /// Sizes the buffers for `steps` steps of `rows` rows starting at `states`.
    fn begin(&mut self, rows: usize, steps: usize, states: &[f64]) -> Result<(), BackendError> {
        if states.len() != rows * self.states {
            return Err(unfit("start states"));
        }
        if steps == 0 {
            return Err(unfit("a window without a step"));
        }
        (self.rows, self.steps) = (rows, steps);
        if self.window.len() < steps {
            self.window.resize_with(steps, StepData::default);
        }
        for buffers in [&mut self.trajectory, &mut self.adjoints] {
            if buffers.len() < steps + 1 {
                buffers.resize_with(steps + 1, Vec::new);
            }
        }
        let stages = steps * self.stages_per_step();
        if self.stages.len() < stages {
            self.stages.resize_with(stages, Default::default);
        }
        let start = &mut self.trajectory[0];
        start.clear();
        start.extend(states.iter().map(|&v| E::from_double(v)));
        Ok(())
    }

    /// Checks one step of a batch and loads it into `window[step]` (its feedback cleared).
    fn load_step(&mut self, step: usize, source: StepSource) -> Result<(), BackendError> {
        let rows = self.rows;
        let measured = self.inverse_std.len();
        let shape = self.program.shape();
        let fits = source.inputs.len() == rows * shape.inputs
            && source.targets.len() == rows * measured
            && source.embeddings.len() == self.plan.closures.len()
            && (source.step_sizes.is_empty() || source.step_sizes.len() == rows)
            && (source.weights.is_empty() || source.weights.len() == rows * measured);
        let valid_steps = (source.step_sizes.iter()).all(|h| *h >= 0.0 && h.is_finite());
        let valid_weights = (source.weights.iter()).all(|w| *w >= 0.0 && w.is_finite());
        if !(fits && valid_steps && valid_weights) {
            return Err(unfit("sizes, step sizes or loss weights"));
        }
        let offsets = self.stage_offsets();
        let (nominal, substeps) = (self.step, self.substeps as f64);
        let data = &mut self.window[step];
        data.substep_sizes.clear();
        if source.step_sizes.is_empty() {
            data.substep_sizes.resize(rows, nominal / substeps);
        } else {
            (data.substep_sizes).extend(source.step_sizes.iter().map(|h| h / substeps));
        }
        let convert = |out: &mut Vec<E>, values: &[f64]| {
            out.clear();
            out.extend(values.iter().map(|&v| E::from_double(v)));
        };
        convert(&mut data.loss_weights, source.weights);
        convert(&mut data.targets, source.targets);
        convert(&mut data.inputs, source.inputs);
        data.feedback.clear();
        data.constants
            .resize_with(self.plan.closures.len(), Vec::new);
        for ((closure, raw), normalised) in (self.plan.closures.iter())
            .zip(source.embeddings)
            .zip(&mut data.constants)
        {
            if raw.len() < offsets || raw.iter().any(|r| r.len() != rows * closure.width()) {
                return Err(unfit("an embedding of the wrong size"));
            }
            normalised.resize_with(offsets, Vec::new);
            for (out, values) in normalised.iter_mut().zip(raw) {
                closure.layout.normalise_into(values, out);
            }
        }
        Ok(())
    }

    /// Checks a rollout batch and loads every step and its feedback.
    fn load_windows(&mut self, batch: &RolloutBatch) -> Result<(), BackendError> {
        let steps = batch.steps;
        let per_step = |count: usize| count == steps;
        let fits = per_step(batch.inputs.len())
            && per_step(batch.embeddings.len())
            && per_step(batch.feedback.len())
            && per_step(batch.targets.len())
            && (batch.step_sizes.is_empty() || per_step(batch.step_sizes.len()))
            && (batch.weights.is_empty() || per_step(batch.weights.len()));
        if !fits {
            return Err(unfit("steps"));
        }
        self.begin(batch.rows, steps, &batch.states)?;
        let none: &[f64] = &[];
        for step in 0..steps {
            let source = StepSource {
                inputs: &batch.inputs[step],
                embeddings: &batch.embeddings[step],
                step_sizes: batch.step_sizes.get(step).map_or(none, Vec::as_slice),
                targets: &batch.targets[step],
                weights: batch.weights.get(step).map_or(none, Vec::as_slice),
            };
            self.load_step(step, source)?;
            self.load_feedback(step, &batch.feedback[step], &batch.embeddings[step])?;
        }
        Ok(())
    }

    /// Checks step `step`'s feedback entries (`[closure][offset]`, one list per embedding
    /// the batch gives) and keeps those of the stage times the step runs.
    fn load_feedback(
        &mut self,
        step: usize,
        feedback: &[Vec<Vec<Feedback>>],
        embeddings: &[Vec<Vec<f64>>],
    ) -> Result<(), BackendError> {
        if feedback.len() != self.plan.closures.len() {
            return Err(unfit("feedback closures"));
        }
        let (rows, states, offsets) = (self.rows, self.states, self.stage_offsets());
        let data = &mut self.window[step];
        for (closure_index, (per_offset, closure)) in
            feedback.iter().zip(&self.plan.closures).enumerate()
        {
            if per_offset.len() != embeddings[closure_index].len() {
                return Err(unfit("feedback offsets"));
            }
            for (offset, entries) in per_offset.iter().enumerate() {
                for entry in entries {
                    let factor = (closure.layout.feedback_factor(entry.column, entry.weight))
                        .filter(|_| (1..=step).contains(&entry.sample))
                        .filter(|_| entry.fits(rows) && entry.state < states)
                        .ok_or_else(|| unfit("feedback outside the window"))?;
                    if offset < offsets {
                        data.feedback.push(FedBack {
                            closure: closure_index,
                            offset,
                            first: entry.rows.start,
                            end: entry.rows.end,
                            column: entry.column,
                            sample: entry.sample,
                            state: entry.state,
                            factor: E::from_double(factor),
                        });
                    }
                }
            }
        }
        Ok(())
    }

    /// Adds step `step`'s fed-back predictions to its embeddings.
    fn feed_back(&mut self, step: usize) {
        let states = self.states;
        let StepData {
            feedback,
            constants,
            ..
        } = &mut self.window[step];
        for entry in feedback.iter() {
            let width = self.plan.closures[entry.closure].width();
            let predicted = &self.trajectory[entry.sample];
            let constants = &mut constants[entry.closure][entry.offset];
            for row in entry.first..entry.end {
                constants[row * width + entry.column] +=
                    predicted[row * states + entry.state] * entry.factor;
            }
        }
    }

    /// Adds the adjoint of every prediction step `step` read back: `factor` times the
    /// gradient of the network input it entered, `delta W0^T` of the step's first-layer
    /// delta at the entry's stage time (one product per closure and stage time that has
    /// entries; they sit together, in load order).
    fn feedback_adjoints(&mut self, step: usize) {
        let (rows, states) = (self.rows, self.states);
        let entries = &self.window[step].feedback;
        for group in entries.chunk_by(|a, b| (a.closure, a.offset) == (b.closure, b.offset)) {
            let (closure, offset) = (group[0].closure, group[0].offset);
            let plan = &self.plan.closures[closure];
            let (inner, width) = (plan.widths[0], plan.widths[1]);
            let gradient = &mut self.scratch.input_gradient;
            gradient.resize(rows * inner, E::ZERO);
            self.gemm.multiply(
                gradient,
                (rows, inner, width),
                View::row_major(&self.scratch.offset_deltas[closure][offset], width),
                View::transposed(&self.weights[plan.weight_at[0]..][..inner * width], width),
            );
            for entry in group {
                let adjoints = &mut self.adjoints[entry.sample];
                for row in entry.first..entry.end {
                    adjoints[row * states + entry.state] +=
                        gradient[row * inner + entry.column] * entry.factor;
                }
            }
        }
    }

    /// The loss of the window, as the graph backend's; leaves its gradient with respect to
    /// each predicted state in `adjoints[1..=steps]` (and zeros in `adjoints[0]`).
    fn window_loss(&mut self) -> f64 {
        let (rows, states, steps) = (self.rows, self.states, self.steps);
        let measured = self.inverse_std.len();
        let cells: usize = (self.window[..steps].iter())
            .map(|data| match data.loss_weights.is_empty() {
                true => rows * measured,
                false => data.loss_weights.iter().filter(|&&w| w > E::ZERO).count(),
            })
            .sum();
        let count = E::from_double(cells.max(1) as f64);
        let two = E::from_double(2.0);
        let mut total = E::ZERO;
        for (index, seed) in self.adjoints[..=steps].iter_mut().enumerate() {
            seed.clear();
            seed.resize(rows * states, E::ZERO);
            let Some(step) = index.checked_sub(1) else {
                continue;
            };
            let data = &self.window[step];
            let predicted = &self.trajectory[index];
            for row in 0..rows {
                for state in 0..measured {
                    let cell = row * measured + state;
                    let w = data.loss_weights.get(cell).copied().unwrap_or(E::ONE);
                    if w <= E::ZERO {
                        continue;
                    }
                    let at = row * states + state;
                    let inverse_std = self.inverse_std[state];
                    let scaled = (predicted[at] - data.targets[cell]) * inverse_std;
                    total += w * scaled * scaled;
                    seed[at] = two * (w * scaled) * inverse_std / count;
                }
            }
        }
        (total / count).to_double()
    }
}
