//! The fused training step in one element type: the forward RK4 step of the paper (eq. 4-7)
//! through every closure network and the physics program, the normalised loss, the reverse
//! pass ([`super::reverse`]) and Adam, over buffers kept from step to step.
//!
//! **First layers by stage time.** A closure's network input at a stage is the batch's
//! normalised embedding at that stage time plus the stage estimate in the lag-0 state
//! columns. The embedding part is the same for every stage at the same time (RK4's second
//! and third stages share `t + h/2`), so its product with the first weight matrix is formed
//! once per stage time, and the estimate enters as a rank-`states` update; in the reverse
//! pass the first weight matrix's gradient is likewise one product per stage time. This
//! saves two of the eight large products of a GB2 step.

use crate::backend::program::{Program, ProgramInputs};
use crate::backend::{BackendError, Batch, Setup, StepSettings};
use crate::ir::{self, Dynamics};
use crate::numeric::Real;

use super::activation::{activate, Lane};
use super::dense::{Gemm, View};
use super::plan::{ClosurePlan, Plan};
use super::reverse::Scratch;
use crate::numeric::{Adam, AdamState, Update};

/// What one stage evaluation keeps for the reverse pass.
#[derive(Debug, Default)]
pub(super) struct Stage<E> {
    /// Index of the stage time (into each closure's embeddings).
    pub offset: usize,
    /// `rows x states`: the state estimate the stage is evaluated at.
    pub state: Vec<E>,
    /// `layers[closure][l]`: the activations leaving layer `l` (`l >= 1`; entry 0 unused);
    /// the last entry is the network output.
    pub layers: Vec<Vec<Vec<E>>>,
    /// `slopes[closure][l]`: the activation's slope at hidden layer `l + 1`.
    pub slopes: Vec<Vec<Vec<E>>>,
    /// Register values of the physics program.
    pub values: Vec<E>,
    /// `rows x states`: the balances (or next values of a `next` model).
    pub balances: Vec<E>,
}

/// The fused step's weights, optimiser state and reusable buffers.
pub struct Kernel<E: Lane> {
    pub(super) plan: Plan,
    pub(super) program: Program,
    dynamics: Dynamics,
    step: f64,
    substeps: usize,
    pub(super) states: usize,
    inverse_std: Vec<E>,
    /// Every trainable value, tensors back to back in [`Plan::tensors`] order.
    pub weights: Vec<E>,
    /// The gradient of the last [`Kernel::loss_and_gradient`], same layout.
    pub gradient: Vec<E>,
    adam: Adam<E>,
    pub(super) rows: usize,
    /// The sub-step `h / K` of each row of the loaded batch.
    substep_sizes: Vec<f64>,
    /// `rows x measured` loss weights of the loaded batch (empty: every cell weighs 1).
    loss_weights: Vec<f64>,
    pub(super) inputs: Vec<E>,
    /// `constants[closure][offset]`: normalised embeddings (lag-0 state entries `-mean/std`).
    pub(super) constants: Vec<Vec<Vec<E>>>,
    /// `first_products[closure][offset]`: `constants @ W0 + b0`.
    first_products: Vec<Vec<Vec<E>>>,
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
        let count = if model.dynamics == Dynamics::Discrete {
            1
        } else {
            4 * setup.substeps.max(1)
        };
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
            adam: Adam::new(size),
            rows: 0,
            substep_sizes: Vec::new(),
            loss_weights: Vec::new(),
            inputs: Vec::new(),
            constants: vec![Vec::new(); plan.closures.len()],
            first_products: vec![Vec::new(); plan.closures.len()],
            stages: (0..count).map(|_| Stage::default()).collect(),
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
    pub fn train_step(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        let loss = self.loss_and_gradient(batch)?;
        let (start, length) = self.plan.params;
        let groups = settings.groups(self.weights.len(), Some(start..start + length));
        let update = Update {
            groups: &groups,
            max_gradient_norm: settings.max_gradient_norm,
        };
        self.adam
            .step(&mut self.weights, &mut self.gradient, &update);
        Ok(loss)
    }

    fn lengths(&self) -> Vec<usize> {
        self.plan.tensors.iter().map(|&(_, n)| n).collect()
    }

    /// Adam's step count and moments, cut into the plan's tensors.
    pub fn adam_state(&self) -> AdamState {
        self.adam.state(&self.lengths())
    }

    /// Replaces Adam's step count and moments.
    pub fn set_adam_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        (self.adam.set_state(state, &self.lengths())).map_err(BackendError::WeightsMismatch)
    }

    /// The normalised one-step loss of the batch; its gradient is left in
    /// [`Kernel::gradient`].
    pub fn loss_and_gradient(&mut self, batch: &Batch) -> Result<f64, BackendError> {
        self.load(batch)?;
        let next = self.forward();
        let (loss, seed) = self.loss(&next, &batch.targets);
        self.gradient.fill(E::ZERO);
        self.backward(seed);
        Ok(loss)
    }

    /// Converts the batch into the element type and normalises its embeddings.
    fn load(&mut self, batch: &Batch) -> Result<(), BackendError> {
        let rows = batch.rows;
        let shape = self.program.shape();
        let measured = self.inverse_std.len();
        let fits = batch.states.len() == rows * shape.states
            && batch.inputs.len() == rows * shape.inputs
            && batch.targets.len() == rows * measured
            && batch.embeddings.len() == self.plan.closures.len()
            && (batch.step_sizes.is_empty() || batch.step_sizes.len() == rows)
            && (batch.weights.is_empty() || batch.weights.len() == rows * measured);
        let valid_steps = (batch.step_sizes.iter()).all(|h| *h >= 0.0 && h.is_finite());
        let valid_weights = (batch.weights.iter()).all(|w| *w >= 0.0 && w.is_finite());
        if !(fits && valid_steps && valid_weights) {
            return Err(BackendError::internal("the batch does not fit the model"));
        }
        self.rows = rows;
        let substeps = self.substeps as f64;
        self.substep_sizes.clear();
        if batch.step_sizes.is_empty() {
            self.substep_sizes.resize(rows, self.step / substeps);
        } else {
            (self.substep_sizes).extend(batch.step_sizes.iter().map(|h| h / substeps));
        }
        self.loss_weights.clear();
        self.loss_weights.extend_from_slice(&batch.weights);
        self.inputs.clear();
        self.inputs
            .extend(batch.inputs.iter().map(|&v| E::from_double(v)));
        let offsets = self.stage_offsets();
        for ((closure, raw), normalised) in (self.plan.closures.iter())
            .zip(&batch.embeddings)
            .zip(&mut self.constants)
        {
            if raw.len() < offsets || raw.iter().any(|r| r.len() != rows * closure.width()) {
                return Err(BackendError::internal(
                    "a batch embedding has the wrong size",
                ));
            }
            normalised.resize_with(offsets, Vec::new);
            for (out, values) in normalised.iter_mut().zip(raw) {
                closure.layout.normalise_into(values, out);
            }
        }
        let first = &mut self.stages[0].state;
        first.clear();
        first.extend(batch.states.iter().map(|&v| E::from_double(v)));
        Ok(())
    }

    pub(super) fn stage_offsets(&self) -> usize {
        match self.dynamics {
            Dynamics::Discrete => 1,
            Dynamics::Continuous => 2 * self.substeps + 1,
        }
    }

    /// The forward pass: `x(t + h)` for every row.
    fn forward(&mut self) -> Vec<E> {
        self.first_layer_products();
        if self.dynamics == Dynamics::Discrete {
            self.stages[0].offset = 0;
            self.evaluate(0);
            return self.stages[0].balances.clone();
        }
        let width = self.states;
        let mut state = self.stages[0].state.clone();
        for substep in 0..self.substeps {
            let (first, base) = (4 * substep, 2 * substep);
            let fractions = [
                (0.0, base),
                (0.5, base + 1),
                (0.5, base + 1),
                (1.0, base + 2),
            ];
            for (index, &(fraction, offset)) in fractions.iter().enumerate() {
                let stage = first + index;
                let estimate = if index == 0 {
                    state.clone()
                } else {
                    let previous = &self.stages[stage - 1].balances;
                    axpy_rows(
                        &state,
                        (&self.substep_sizes, fraction, 1.0),
                        previous,
                        width,
                    )
                };
                self.stages[stage].state = estimate;
                self.stages[stage].offset = offset;
                self.evaluate(stage);
            }
            let k = |index: usize| &self.stages[first + index].balances;
            let mut sum = axpy(k(0), 2.0, k(1));
            sum = axpy(&sum, 2.0, k(2));
            sum = axpy(&sum, 1.0, k(3));
            state = axpy_rows(&state, (&self.substep_sizes, 1.0, 6.0), &sum, width);
        }
        state
    }

    /// `constants @ W0 + b0` for every closure and stage time.
    fn first_layer_products(&mut self) {
        let rows = self.rows;
        for ((closure, constants), products) in (self.plan.closures.iter())
            .zip(&self.constants)
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
            inputs: &self.inputs,
            params: &self.weights[start..start + length],
            nets: &nets,
        };
        self.program.forward_into(&inputs, &mut stage.values);
        stage.balances = self
            .program
            .read(&stage.values, rows, &self.program.balances);
    }

    /// The loss and its gradient with respect to the predicted next states.
    /// Weighted as the graph backend's loss: `sum(w r^2) / #(w > 0)`.
    fn loss(&self, next: &[E], targets: &[f64]) -> (f64, Vec<E>) {
        let measured = self.inverse_std.len();
        let weight = |cell: usize| self.loss_weights.get(cell).copied().unwrap_or(1.0);
        let cells = (0..self.rows * measured)
            .filter(|&cell| weight(cell) > 0.0)
            .count();
        let count = E::from_double(cells.max(1) as f64);
        let mut seed = vec![E::ZERO; next.len()];
        let mut total = E::ZERO;
        for (row, ((predicted, target), seed_row)) in (next.chunks_exact(self.states))
            .zip(targets.chunks_exact(measured))
            .zip(seed.chunks_exact_mut(self.states))
            .enumerate()
        {
            for state in 0..measured {
                let w = weight(row * measured + state);
                if w <= 0.0 {
                    continue;
                }
                let w = E::from_double(w);
                let scaled =
                    (predicted[state] - E::from_double(target[state])) * self.inverse_std[state];
                total += w * scaled * scaled;
                seed_row[state] =
                    E::from_double(2.0) * (w * scaled) * self.inverse_std[state] / count;
            }
        }
        ((total / count).to_double(), seed)
    }

    /// The reverse pass from the seed on `x(t + h)`, accumulating into the gradient.
    fn backward(&mut self, seed: Vec<E>) {
        self.clear_offset_deltas();
        if self.dynamics == Dynamics::Discrete {
            self.reverse_stage(0, &seed);
        } else {
            let (sizes, width) = (self.substep_sizes.clone(), self.states);
            let mut upstream = seed;
            for substep in (0..self.substeps).rev() {
                let first = 4 * substep;
                let mut stage_seeds: Vec<Vec<E>> = [1.0, 2.0, 2.0, 1.0]
                    .iter()
                    .map(|&weight| scaled_rows(&upstream, (&sizes, weight, 6.0), width))
                    .collect();
                let mut start_gradient = upstream;
                for index in (0..4).rev() {
                    let estimate_gradient = self.reverse_stage(first + index, &stage_seeds[index]);
                    if index > 0 {
                        let fraction = if index == 3 { 1.0 } else { 0.5 };
                        add_scaled_rows(
                            &mut stage_seeds[index - 1],
                            (&sizes, fraction, 1.0),
                            &estimate_gradient,
                            width,
                        );
                    }
                    add_scaled(&mut start_gradient, 1.0, &estimate_gradient);
                }
                upstream = start_gradient;
            }
        }
        self.first_layer_gradients();
    }

    /// `dW0 += constants^T delta` per closure and stage time, `delta` summed over the
    /// stages at that time.
    fn first_layer_gradients(&mut self) {
        let rows = self.rows;
        for ((closure, constants), deltas) in (self.plan.closures.iter())
            .zip(&self.constants)
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

pub(super) fn axpy<E: Real>(a: &[E], factor: f64, b: &[E]) -> Vec<E> {
    let factor = E::from_double(factor);
    a.iter().zip(b).map(|(&x, &y)| x + factor * y).collect()
}

/// Row `i`'s sub-step `dt_i` times `multiple / divisor`, as `dt * multiple / divisor`.
type RowFactors<'a> = (&'a [f64], f64, f64);

/// `a + (dt_i * multiple / divisor) b` row by row (`width` values a row).
fn axpy_rows<E: Real>(
    a: &[E],
    (substeps, multiple, divisor): RowFactors,
    b: &[E],
    width: usize,
) -> Vec<E> {
    let mut out = Vec::with_capacity(a.len());
    for ((a_row, b_row), &dt) in a.chunks(width).zip(b.chunks(width)).zip(substeps) {
        let factor = E::from_double(dt * multiple / divisor);
        out.extend(a_row.iter().zip(b_row).map(|(&x, &y)| x + factor * y));
    }
    out
}

/// `(dt_i * multiple / divisor) values` row by row.
fn scaled_rows<E: Real>(
    values: &[E],
    (substeps, multiple, divisor): RowFactors,
    width: usize,
) -> Vec<E> {
    let mut out = Vec::with_capacity(values.len());
    for (row, &dt) in values.chunks(width).zip(substeps) {
        let factor = E::from_double(dt * multiple / divisor);
        out.extend(row.iter().map(|&v| v * factor));
    }
    out
}

/// `target += (dt_i * multiple / divisor) values` row by row.
fn add_scaled_rows<E: Real>(
    target: &mut [E],
    (substeps, multiple, divisor): RowFactors,
    values: &[E],
    width: usize,
) {
    for ((slot_row, row), &dt) in target
        .chunks_mut(width)
        .zip(values.chunks(width))
        .zip(substeps)
    {
        let factor = E::from_double(dt * multiple / divisor);
        for (slot, &value) in slot_row.iter_mut().zip(row) {
            *slot += factor * value;
        }
    }
}

pub(super) fn add_scaled<E: Real>(target: &mut [E], factor: f64, values: &[E]) {
    let factor = E::from_double(factor);
    for (slot, &value) in target.iter_mut().zip(values) {
        *slot += factor * value;
    }
}
