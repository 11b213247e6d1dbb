//! The fused training step in one element type: the forward RK4 step of the paper (eq. 4-7)
//! through every closure network and the physics program, its reverse pass
//! ([`super::reverse`] for each stage) and Adam, over buffers kept from step to step.
//!
//! The kernel runs a window of steps ([`super::rollout`]): one step for a batch of one-step
//! pairs, `K` steps for a batch of rollout windows. Here are the pieces of one step of the
//! window: [`Kernel::forward_step`] from the state the window reached to the next, and
//! [`Kernel::backward_step`] from the adjoint of that next state back to the adjoint of the
//! state it started from.
//!
//! **First layers by stage time.** A closure's network input at a stage is the batch's
//! normalised embedding at that stage time plus the stage estimate in the lag-0 state
//! columns. The embedding part is the same for every stage at the same time (RK4's second
//! and third stages share `t + h/2`), so its product with the first weight matrix is formed
//! once per stage time, and the estimate enters as a rank-`states` update; in the reverse
//! pass the first weight matrix's gradient is likewise one product per stage time. This
//! saves two of the eight large products of a GB2 step. (A rollout's predicted states fed
//! back into the embedding are part of that constant part: they are known before the step.)

#[cfg(test)]
use crate::engine::batch::Batch;
use crate::engine::error::BackendError;
use crate::engine::program::{Program, ProgramInputs};
#[cfg(test)]
use crate::engine::settings::StepSettings;
use crate::engine::setup::Setup;
use crate::ir::{self, Dynamics};
use crate::numeric::Real;
#[cfg(test)]
use crate::numeric::{Adam, AdamState};
use crate::solve::ode::tableau::RK4;

use super::activation::{activate, Lane};
use super::buffers::{Scratch, Stage, StepData};
use super::dense::{Gemm, View};
use super::plan::{ClosurePlan, Plan};
use super::rows::{
    add_scaled, add_scaled_rows, advance_rows, scaled_rows_into, stage_estimate_into,
};

/// The fused step's weights, optimiser state and reusable buffers.
pub struct Kernel<E: Lane> {
    pub(super) plan: Plan,
    pub(super) program: Program,
    pub(super) dynamics: Dynamics,
    /// The nominal step `h` (rows that give none).
    pub(super) step: f64,
    pub(super) substeps: usize,
    pub(super) states: usize,
    /// `1 / std` of each measured state (the loss's z-score).
    pub(super) inverse_std: Vec<E>,
    /// Every trainable value, tensors back to back in [`Plan::tensors`] order.
    pub weights: Vec<E>,
    /// The gradient of the last [`Kernel::loss_and_gradient`], same layout.
    pub gradient: Vec<E>,
    /// The kernel's own optimiser, for its tests (training steps through
    /// [`crate::engine::step::Optimiser`]).
    #[cfg(test)]
    adam: Adam<E>,
    pub(super) rows: usize,
    /// Steps of the loaded window (1 for one-step pairs).
    pub(super) steps: usize,
    /// What each step of the loaded window reads (the first `steps` entries are current;
    /// the buffers of all are kept).
    pub(super) window: Vec<StepData<E>>,
    /// `trajectory[k]`: `rows x states` after `k` steps of the window (0: its start).
    pub(super) trajectory: Vec<Vec<E>>,
    /// `adjoints[k]`: the loss's gradient with respect to `trajectory[k]`.
    pub(super) adjoints: Vec<Vec<E>>,
    /// `first_products[closure][offset]`: `constants @ W0 + b0` of the step being run.
    first_products: Vec<Vec<Vec<E>>>,
    /// The stages of every step, step after step.
    pub(super) stages: Vec<Stage<E>>,
    pub(super) gemm: Gemm<E>,
    pub(super) scratch: Scratch<E>,
}

impl<E: Lane> Kernel<E> {
    /// A kernel for `model` laid out by `plan`, starting from `weights` (`f64`, flat).
    pub fn new(
        model: &ir::Model,
        setup: &Setup,
        plan: Plan,
        weights: &[f64],
    ) -> Result<Self, BackendError> {
        let program = Program::compile(model, &setup.scales)?;
        let inverse_std = (setup.normalisation.state_std.iter())
            .map(|&s| E::from_double(1.0 / s))
            .collect();
        let weights: Vec<E> = weights.iter().map(|&v| E::from_double(v)).collect();
        let size = weights.len();
        Ok(Kernel {
            states: program.shape().states,
            program,
            dynamics: model.dynamics,
            step: setup.step,
            substeps: setup.substeps.max(1),
            inverse_std,
            weights,
            gradient: vec![E::ZERO; size],
            #[cfg(test)]
            adam: Adam::new(size),
            rows: 0,
            steps: 0,
            window: Vec::new(),
            trajectory: Vec::new(),
            adjoints: Vec::new(),
            first_products: vec![Vec::new(); plan.closures.len()],
            stages: Vec::new(),
            gemm: Gemm::default(),
            scratch: Scratch::default(),
            plan,
        })
    }

    /// The layout of the weights.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// One Adam step on the batch (clipped and with the params' own learning rate as
    /// `settings` ask); returns the loss before it.
    #[cfg(test)]
    pub fn train_step(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        let loss = self.loss_and_gradient(batch)?;
        let (start, length) = self.plan.params;
        let params = Some(start..start + length);
        settings.adam_step(
            &mut self.adam,
            &mut self.weights,
            &mut self.gradient,
            params,
        );
        Ok(loss)
    }

    #[cfg(test)]
    fn lengths(&self) -> Vec<usize> {
        self.plan.tensors.iter().map(|&(_, n)| n).collect()
    }

    /// Adam's step count and moments, cut into the plan's tensors.
    #[cfg(test)]
    pub fn adam_state(&self) -> AdamState {
        self.adam.state(&self.lengths())
    }

    /// Replaces Adam's step count and moments.
    #[cfg(test)]
    pub fn set_adam_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        (self.adam.set_state(state, &self.lengths())).map_err(BackendError::WeightsMismatch)
    }

    /// Distinct stage times of a step: RK4's (`2K + 1`) for `der` models, 1 for `next`
    /// models.
    pub(super) fn stage_offsets(&self) -> usize {
        match self.dynamics {
            Dynamics::Discrete => 1,
            Dynamics::Continuous => RK4.stage_times(self.substeps),
        }
    }

    /// Stages of a step: RK4's per sub-step (`4K`) for `der` models, 1 for `next` models.
    pub(super) fn stages_per_step(&self) -> usize {
        match self.dynamics {
            Dynamics::Discrete => 1,
            Dynamics::Continuous => RK4.stages.len() * self.substeps,
        }
    }

    /// Step `step` of the window: `trajectory[step + 1]` from `trajectory[step]` (the
    /// step's embeddings complete, feedback included), keeping every stage.
    pub(super) fn forward_step(&mut self, step: usize) {
        self.first_layer_products(step);
        let base = step * self.stages_per_step();
        let mut state = std::mem::take(&mut self.trajectory[step + 1]);
        state.clear();
        state.extend_from_slice(&self.trajectory[step]);
        if self.dynamics == Dynamics::Discrete {
            let stage = &mut self.stages[base];
            (stage.step, stage.offset) = (step, 0);
            stage.state.clear();
            stage.state.extend_from_slice(&state);
            self.evaluate(base);
            state.clear();
            state.extend_from_slice(&self.stages[base].balances);
            self.trajectory[step + 1] = state;
            return;
        }
        for substep in 0..self.substeps {
            self.forward_substep(step, substep, &mut state);
        }
        self.trajectory[step + 1] = state;
    }

    /// Sub-step `substep` of step `step` from `state`: every stage of the tableau at its
    /// estimate (kept), then the step along the weights.
    fn forward_substep(&mut self, step: usize, substep: usize, state: &mut [E]) {
        let width = self.states;
        let first = step * self.stages_per_step() + RK4.stages.len() * substep;
        for (index, coupling) in RK4.stages.iter().enumerate() {
            let (before, after) = self.stages.split_at_mut(first + index);
            let stage = &mut after[0];
            (stage.step, stage.offset) = (step, RK4.stage_offset(substep, index));
            stage.state.clear();
            if coupling.is_empty() {
                stage.state.extend_from_slice(state);
            } else {
                let sizes = (self.window[step].substep_sizes.as_slice(), coupling);
                stage_estimate_into(&mut stage.state, state, sizes, &before[first..], width);
            }
            self.evaluate(first + index);
        }
        let sizes = (self.window[step].substep_sizes.as_slice(), &RK4.weights);
        let stages = &self.stages[first..first + RK4.stages.len()];
        advance_rows(state, sizes, stages, width);
    }

    /// `constants @ W0 + b0` for every closure and stage time of step `step`.
    fn first_layer_products(&mut self, step: usize) {
        let rows = self.rows;
        for ((closure, constants), products) in (self.plan.closures.iter())
            .zip(&self.window[step].constants)
            .zip(&mut self.first_products)
        {
            let (inner, width) = (closure.widths[0], closure.widths[1]);
            let weight = &self.weights[closure.weight_at[0]..][..inner * width];
            let bias = &self.weights[closure.bias_at[0]..][..width];
            products.resize_with(constants.len(), Vec::new);
            for (product, constant) in products.iter_mut().zip(constants) {
                product.clear();
                for _ in 0..rows {
                    product.extend_from_slice(bias);
                }
                self.gemm.multiply_add(
                    product,
                    (rows, width, inner),
                    View::row_major(constant, inner),
                    View::row_major(weight, width),
                );
            }
        }
    }

    /// Evaluates every closure network and the physics at stage `index`.
    fn evaluate(&mut self, index: usize) {
        let rows = self.rows;
        let stage = &mut self.stages[index];
        stage.layers.resize_with(self.plan.closures.len(), Vec::new);
        stage.slopes.resize_with(self.plan.closures.len(), Vec::new);
        for (closure_index, closure) in self.plan.closures.iter().enumerate() {
            let layers = &mut stage.layers[closure_index];
            let slopes = &mut stage.slopes[closure_index];
            layers.resize_with(closure.widths.len(), Vec::new);
            slopes.resize_with(closure.layers().saturating_sub(1), Vec::new);
            let first = &mut layers[1];
            first.clear();
            first.extend_from_slice(&self.first_products[closure_index][stage.offset]);
            let first_weight = &self.weights[closure.weight_at[0]..];
            add_stage_state(closure, &stage.state, self.states, first_weight, first);
            for layer in 1..=closure.layers() {
                if layer > 1 {
                    let (inner, width) = (closure.widths[layer - 1], closure.widths[layer]);
                    let weight = &self.weights[closure.weight_at[layer - 1]..][..inner * width];
                    let bias = &self.weights[closure.bias_at[layer - 1]..][..width];
                    let (before, after) = layers.split_at_mut(layer);
                    let out = &mut after[0];
                    out.clear();
                    for _ in 0..rows {
                        out.extend_from_slice(bias);
                    }
                    self.gemm.multiply_add(
                        out,
                        (rows, width, inner),
                        View::row_major(&before[layer - 1], inner),
                        View::row_major(weight, width),
                    );
                }
                if layer < closure.layers() {
                    let slope = &mut slopes[layer - 1];
                    slope.resize(layers[layer].len(), E::ZERO);
                    activate(closure.activation, &mut layers[layer], slope);
                }
            }
        }
        let nets: Vec<&[E]> = (stage.layers.iter())
            .map(|layers| layers.last().map_or(&[][..], Vec::as_slice))
            .collect();
        let (start, length) = self.plan.params;
        let inputs = ProgramInputs {
            rows,
            states: &stage.state,
            inputs: &self.window[stage.step].inputs,
            params: &self.weights[start..start + length],
            nets: &nets,
        };
        self.program.forward_into(&inputs, &mut stage.values);
        stage.balances = self
            .program
            .read(&stage.values, rows, &self.program.balances);
    }

    /// The reverse of step `step`: `upstream` holds the adjoint of `trajectory[step + 1]`
    /// and leaves with that of `trajectory[step]`; the weight and param gradients are
    /// accumulated, and the step's first-layer deltas per stage time are left in the
    /// scratch's `offset_deltas` (for the adjoint of fed-back predictions).
    pub(super) fn backward_step(&mut self, step: usize, upstream: &mut [E]) {
        self.clear_offset_deltas();
        let base = step * self.stages_per_step();
        if self.dynamics == Dynamics::Discrete {
            let gradient = self.reverse_stage(base, upstream);
            upstream.copy_from_slice(&gradient);
        } else {
            let mut seeds = std::mem::take(&mut self.scratch.stage_seeds);
            seeds.resize_with(RK4.stages.len(), Vec::new);
            for substep in (0..self.substeps).rev() {
                self.backward_substep(step, substep, upstream, &mut seeds);
            }
            self.scratch.stage_seeds = seeds;
        }
        self.first_layer_gradients(step);
    }

    /// The reverse of sub-step `substep` of step `step`: `upstream` holds the adjoint of
    /// its end state and leaves with that of its start, which reaches the end directly and
    /// through every stage estimate (`seeds`: the stages' adjoints, one buffer a stage).
    fn backward_substep(
        &mut self,
        step: usize,
        substep: usize,
        upstream: &mut [E],
        seeds: &mut [Vec<E>],
    ) {
        let width = self.states;
        let first = step * self.stages_per_step() + RK4.stages.len() * substep;
        let (weights, divisor) = (&RK4.weights.numerators, RK4.weights.divisor());
        let sizes = &self.window[step].substep_sizes;
        for (seed, &weight) in seeds.iter_mut().zip(weights) {
            scaled_rows_into(seed, upstream, (sizes, f64::from(weight), divisor), width);
        }
        for (index, coupling) in RK4.stages.iter().enumerate().rev() {
            let estimate_gradient = self.reverse_stage(first + index, &seeds[index]);
            let sizes = self.window[step].substep_sizes.as_slice();
            for (earlier, numerator) in coupling.terms() {
                let factors = (sizes, numerator, coupling.divisor());
                add_scaled_rows(&mut seeds[earlier], factors, &estimate_gradient, width);
            }
            add_scaled(upstream, 1.0, &estimate_gradient);
        }
    }

    /// `dW0 += constants^T delta` per closure and stage time of step `step`, `delta`
    /// summed over the stages at that time.
    fn first_layer_gradients(&mut self, step: usize) {
        let rows = self.rows;
        for ((closure, constants), deltas) in (self.plan.closures.iter())
            .zip(&self.window[step].constants)
            .zip(&self.scratch.offset_deltas)
        {
            let (inner, width) = (closure.widths[0], closure.widths[1]);
            let weight_gradient = &mut self.gradient[closure.weight_at[0]..][..inner * width];
            for (constant, delta) in constants.iter().zip(deltas) {
                self.gemm.multiply_add(
                    weight_gradient,
                    (inner, width, rows),
                    View::transposed(constant, inner),
                    View::row_major(delta, width),
                );
            }
        }
    }

    /// Zeroes the `rows x widths[1]` sums of first-layer deltas per closure and stage time.
    fn clear_offset_deltas(&mut self) {
        let offsets = self.stage_offsets();
        let sums = &mut self.scratch.offset_deltas;
        sums.resize_with(self.plan.closures.len(), Vec::new);
        for (closure, per_offset) in self.plan.closures.iter().zip(sums) {
            per_offset.resize_with(offsets, Vec::new);
            for sum in per_offset {
                sum.clear();
                sum.resize(self.rows * closure.widths[1], E::ZERO);
            }
        }
    }
}

/// Adds the stage estimate's share of the first layer: `(x / std) W0[column, :]` for every
/// lag-0 state column.
fn add_stage_state<E: Real>(
    closure: &ClosurePlan,
    state: &[E],
    states: usize,
    first_weight: &[E],
    first: &mut [E],
) {
    let width = closure.widths[1];
    for (row, estimate) in first
        .chunks_exact_mut(width)
        .zip(state.chunks_exact(states))
    {
        for &(column, index, inverse_std) in &closure.stage_columns {
            let scale = estimate[index] * E::from_double(inverse_std);
            let weights = &first_weight[column * width..(column + 1) * width];
            for (slot, &w) in row.iter_mut().zip(weights) {
                *slot += scale * w;
            }
        }
    }
}
