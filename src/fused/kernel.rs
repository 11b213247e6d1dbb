//! The fused training step in one element type: the forward RK4 step of the paper (eq. 4-7)
//! through every closure network and the physics program, the normalised loss, a
//! hand-written reverse pass, and Adam, over buffers kept from step to step.

use crate::backend::program::{Program, ProgramInputs};
use crate::backend::real::Real;
use crate::backend::{BackendError, Batch, Setup};
use crate::ir::{self, Dynamics};

use super::activation::{activate, Lane};
use super::dense::{add_column_sums, Gemm, View};
use super::plan::{ClosurePlan, Plan};

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-8;

/// What one stage evaluation keeps for the reverse pass.
#[derive(Debug, Default)]
struct Stage<E> {
    /// Offset of the stage time (index into each closure's embeddings).
    offset: usize,
    /// `rows x states`: the state estimate the stage is evaluated at.
    state: Vec<E>,
    /// `layers[closure][l]`: the activations entering layer `l` (`l = 0`: the network
    /// input); the last entry is the network output.
    layers: Vec<Vec<Vec<E>>>,
    /// `slopes[closure][l]`: the activation's slope at hidden layer `l + 1`.
    slopes: Vec<Vec<Vec<E>>>,
    /// Register values of the physics program.
    values: Vec<E>,
    /// `rows x states`: the balances (or next values of a `next` model).
    balances: Vec<E>,
}

/// The fused step's weights, optimiser state and reusable buffers.
pub struct Kernel<E: Lane> {
    plan: Plan,
    program: Program,
    dynamics: Dynamics,
    step: f64,
    substeps: usize,
    states: usize,
    inverse_std: Vec<E>,
    /// Every trainable value, tensors back to back in [`Plan::tensors`] order.
    pub weights: Vec<E>,
    /// The gradient of the last [`Kernel::loss_and_gradient`], same layout.
    pub gradient: Vec<E>,
    first_moment: Vec<E>,
    second_moment: Vec<E>,
    adam_steps: i32,
    rows: usize,
    inputs: Vec<E>,
    /// `constants[closure][offset]`: normalised embeddings (lag-0 state entries `-mean/std`).
    constants: Vec<Vec<Vec<E>>>,
    stages: Vec<Stage<E>>,
    gemm: Gemm<E>,
    delta: Vec<E>,
    below: Vec<E>,
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
            first_moment: vec![E::ZERO; size],
            second_moment: vec![E::ZERO; size],
            adam_steps: 0,
            rows: 0,
            inputs: Vec::new(),
            constants: vec![Vec::new(); plan.closures.len()],
            stages: (0..count).map(|_| Stage::default()).collect(),
            gemm: Gemm::default(),
            delta: Vec::new(),
            below: Vec::new(),
            plan,
        })
    }

    /// The layout of the weights.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// One Adam step on the batch; returns the loss before it.
    pub fn train_step(&mut self, batch: &Batch, learning_rate: f64) -> Result<f64, BackendError> {
        let loss = self.loss_and_gradient(batch)?;
        self.adam(learning_rate);
        Ok(loss)
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
            && batch.embeddings.len() == self.plan.closures.len();
        if !fits {
            return Err(BackendError::internal("the batch does not fit the model"));
        }
        self.rows = rows;
        self.inputs.clear();
        self.inputs
            .extend(batch.inputs.iter().map(|&v| E::from_double(v)));
        let offsets = self.stage_offsets();
        for ((closure, raw), normalised) in (self.plan.closures.iter())
            .zip(&batch.embeddings)
            .zip(&mut self.constants)
        {
            if raw.len() < offsets || raw.iter().any(|r| r.len() != rows * closure.width()) {
                return Err(BackendError::internal("a batch embedding has the wrong size"));
            }
            normalised.resize_with(offsets, Vec::new);
            for (out, values) in normalised.iter_mut().zip(raw) {
                normalise(closure, values, out);
            }
        }
        let first = &mut self.stages[0].state;
        first.clear();
        first.extend(batch.states.iter().map(|&v| E::from_double(v)));
        Ok(())
    }

    fn stage_offsets(&self) -> usize {
        match self.dynamics {
            Dynamics::Discrete => 1,
            Dynamics::Continuous => 2 * self.substeps + 1,
        }
    }

    /// The forward pass: `x(t + h)` for every row.
    fn forward(&mut self) -> Vec<E> {
        if self.dynamics == Dynamics::Discrete {
            self.stages[0].offset = 0;
            self.evaluate(0);
            return self.stages[0].balances.clone();
        }
        let dt = self.step / self.substeps as f64;
        let mut state = self.stages[0].state.clone();
        for substep in 0..self.substeps {
            let first = 4 * substep;
            let base = 2 * substep;
            let fractions = [(0.0, base), (0.5, base + 1), (0.5, base + 1), (1.0, base + 2)];
            for (index, &(fraction, offset)) in fractions.iter().enumerate() {
                let stage = first + index;
                let estimate = if index == 0 {
                    state.clone()
                } else {
                    let previous = &self.stages[stage - 1].balances;
                    axpy(&state, dt * fraction, previous)
                };
                self.stages[stage].state = estimate;
                self.stages[stage].offset = offset;
                self.evaluate(stage);
            }
            let k = |index: usize| &self.stages[first + index].balances;
            let mut sum = axpy(k(0), 2.0, k(1));
            sum = axpy(&sum, 2.0, k(2));
            sum = axpy(&sum, 1.0, k(3));
            state = axpy(&state, dt / 6.0, &sum);
        }
        state
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
            let input = &mut layers[0];
            input.clear();
            input.extend_from_slice(&self.constants[closure_index][stage.offset]);
            add_stage_state(closure, &stage.state, self.states, input);
            for layer in 0..closure.layers() {
                let (before, after) = layers.split_at_mut(layer + 1);
                let (inner, width) = (closure.widths[layer], closure.widths[layer + 1]);
                let weight = &self.weights[closure.weight_at[layer]..][..inner * width];
                let bias = &self.weights[closure.bias_at[layer]..][..width];
                let out = &mut after[0];
                out.clear();
                for _ in 0..rows {
                    out.extend_from_slice(bias);
                }
                self.gemm.multiply_add(
                    out,
                    (rows, width, inner),
                    View::row_major(&before[layer], inner),
                    View::row_major(weight, width),
                );
                if layer + 1 < closure.layers() {
                    let slope = &mut slopes[layer];
                    slope.resize(out.len(), E::ZERO);
                    activate(closure.activation, out, slope);
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
        stage.values = self.program.forward(&inputs);
        stage.balances = self.program.read(&stage.values, rows, &self.program.balances);
    }

    /// The loss and its gradient with respect to the predicted next states.
    fn loss(&self, next: &[E], targets: &[f64]) -> (f64, Vec<E>) {
        let measured = self.inverse_std.len();
        let count = E::from_double((self.rows * measured).max(1) as f64);
        let mut seed = vec![E::ZERO; next.len()];
        let mut total = E::ZERO;
        for ((predicted, target), seed_row) in (next.chunks_exact(self.states))
            .zip(targets.chunks_exact(measured))
            .zip(seed.chunks_exact_mut(self.states))
        {
            for state in 0..measured {
                let scaled =
                    (predicted[state] - E::from_double(target[state])) * self.inverse_std[state];
                total += scaled * scaled;
                seed_row[state] = E::from_double(2.0) * scaled * self.inverse_std[state] / count;
            }
        }
        ((total / count).to_double(), seed)
    }

    /// The reverse pass from the seed on `x(t + h)`, accumulating into the gradient.
    fn backward(&mut self, seed: Vec<E>) {
        if self.dynamics == Dynamics::Discrete {
            self.reverse_stage(0, &seed);
            return;
        }
        let dt = self.step / self.substeps as f64;
        let mut upstream = seed;
        for substep in (0..self.substeps).rev() {
            let first = 4 * substep;
            let mut stage_seeds: Vec<Vec<E>> = [1.0, 2.0, 2.0, 1.0]
                .iter()
                .map(|weight| scaled(&upstream, dt * weight / 6.0))
                .collect();
            let mut start_gradient = upstream;
            for index in (0..4).rev() {
                let estimate_gradient = self.reverse_stage(first + index, &stage_seeds[index]);
                if index > 0 {
                    let fraction = if index == 3 { 1.0 } else { 0.5 };
                    add_scaled(&mut stage_seeds[index - 1], dt * fraction, &estimate_gradient);
                }
                add_scaled(&mut start_gradient, 1.0, &estimate_gradient);
            }
            upstream = start_gradient;
        }
    }

    /// Reverse of stage `index` given the adjoint of its balances; accumulates the weight
    /// and param gradients and returns the gradient with respect to its state estimate.
    fn reverse_stage(&mut self, index: usize, seed: &[E]) -> Vec<E> {
        let rows = self.rows;
        let stage = &self.stages[index];
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
        let physics = self
            .program
            .backward(&inputs, &stage.values, &self.program.balances, seed);
        let mut state_gradient = physics.states;
        for (slot, &value) in self.gradient[start..start + length]
            .iter_mut()
            .zip(&physics.params)
        {
            *slot += value;
        }
        for ((closure_index, closure), net_gradient) in
            self.plan.closures.iter().enumerate().zip(physics.nets)
        {
            self.delta = net_gradient;
            let mut backprop = Backprop {
                gemm: &mut self.gemm,
                delta: &mut self.delta,
                below: &mut self.below,
            };
            backprop.network(
                closure,
                &stage.layers[closure_index],
                &stage.slopes[closure_index],
                &self.weights,
                &mut self.gradient,
            );
            let first_layer = &self.weights[closure.weight_at[0]..];
            add_stage_state_gradient(
                closure,
                first_layer,
                &self.delta,
                self.states,
                &mut state_gradient,
            );
        }
        state_gradient
    }

    /// One bias-corrected Adam update along [`Kernel::gradient`] (Kingma & Ba 2015).
    fn adam(&mut self, learning_rate: f64) {
        self.adam_steps += 1;
        let correction1 = 1.0 - BETA1.powi(self.adam_steps);
        let correction2 = 1.0 - BETA2.powi(self.adam_steps);
        let step = E::from_double(learning_rate * correction2.sqrt() / correction1);
        let epsilon = E::from_double(EPSILON * correction2.sqrt());
        let (beta1, beta2) = (E::from_double(BETA1), E::from_double(BETA2));
        let (keep1, keep2) = (E::from_double(1.0 - BETA1), E::from_double(1.0 - BETA2));
        for (((weight, &g), first), second) in (self.weights.iter_mut())
            .zip(&self.gradient)
            .zip(&mut self.first_moment)
            .zip(&mut self.second_moment)
        {
            *first = beta1 * *first + keep1 * g;
            *second = beta2 * *second + keep2 * g * g;
            *weight = *weight - step * *first / (second.sqrt() + epsilon);
        }
    }
}

/// The buffers of the reverse pass through one network.
struct Backprop<'a, E> {
    gemm: &'a mut Gemm<E>,
    /// On entry the gradient of the network output; on exit that of the first layer's
    /// pre-activation.
    delta: &'a mut Vec<E>,
    below: &'a mut Vec<E>,
}

impl<E: Lane> Backprop<'_, E> {
    /// Reverse pass through one closure network at one stage: accumulates the weight and
    /// bias gradients into `gradient`.
    fn network(
        &mut self,
        closure: &ClosurePlan,
        layers: &[Vec<E>],
        slopes: &[Vec<E>],
        weights: &[E],
        gradient: &mut [E],
    ) {
        let rows = layers[0].len() / closure.width().max(1);
        for layer in (0..closure.layers()).rev() {
            let (inner, width) = (closure.widths[layer], closure.widths[layer + 1]);
            self.gemm.multiply_add(
                &mut gradient[closure.weight_at[layer]..][..inner * width],
                (inner, width, rows),
                View::transposed(&layers[layer], inner),
                View::row_major(self.delta, width),
            );
            add_column_sums(
                &mut gradient[closure.bias_at[layer]..][..width],
                self.delta,
                width,
            );
            if layer == 0 {
                break;
            }
            let weight = &weights[closure.weight_at[layer]..][..inner * width];
            self.below.clear();
            self.below.resize(rows * inner, E::ZERO);
            self.gemm.multiply_add(
                self.below,
                (rows, inner, width),
                View::row_major(self.delta, width),
                View::transposed(weight, width),
            );
            for (value, &slope) in self.below.iter_mut().zip(&slopes[layer - 1]) {
                *value = *value * slope;
            }
            std::mem::swap(self.delta, self.below);
        }
    }
}

/// Normalises raw embedding rows as the graph backend does: the z-score of each column,
/// `-mean / std` in the lag-0 state columns.
fn normalise<E: Real>(closure: &ClosurePlan, raw: &[f64], out: &mut Vec<E>) {
    out.clear();
    for row in raw.chunks_exact(closure.width()) {
        out.extend(
            (row.iter().zip(&closure.column_scale))
                .zip(&closure.column_shift)
                .map(|((&value, &scale), &shift)| E::from_double(value * scale + shift)),
        );
    }
}

/// Adds the stage estimate, scaled by `1 / std`, into the lag-0 state columns.
fn add_stage_state<E: Real>(closure: &ClosurePlan, state: &[E], states: usize, input: &mut [E]) {
    let width = closure.width();
    for (row, estimate) in input.chunks_exact_mut(width).zip(state.chunks_exact(states)) {
        for &(column, index, inverse_std) in &closure.stage_columns {
            row[column] += estimate[index] * E::from_double(inverse_std);
        }
    }
}

/// The gradient reaching the stage estimate through the lag-0 state columns:
/// `g_x[r, s] += (delta[r, :] . W0[column, :]) / std`.
fn add_stage_state_gradient<E: Real>(
    closure: &ClosurePlan,
    first_layer: &[E],
    delta: &[E],
    states: usize,
    state_gradient: &mut [E],
) {
    let width = closure.widths[1];
    for (delta_row, gradient_row) in delta
        .chunks_exact(width)
        .zip(state_gradient.chunks_exact_mut(states))
    {
        for &(column, index, inverse_std) in &closure.stage_columns {
            let weights = &first_layer[column * width..(column + 1) * width];
            let mut dot = E::ZERO;
            for (&d, &w) in delta_row.iter().zip(weights) {
                dot += d * w;
            }
            gradient_row[index] += dot * E::from_double(inverse_std);
        }
    }
}

fn axpy<E: Real>(a: &[E], factor: f64, b: &[E]) -> Vec<E> {
    let factor = E::from_double(factor);
    a.iter().zip(b).map(|(&x, &y)| x + factor * y).collect()
}

fn scaled<E: Real>(values: &[E], factor: f64) -> Vec<E> {
    let factor = E::from_double(factor);
    values.iter().map(|&v| v * factor).collect()
}

fn add_scaled<E: Real>(target: &mut [E], factor: f64, values: &[E]) {
    let factor = E::from_double(factor);
    for (slot, &value) in target.iter_mut().zip(values) {
        *slot += factor * value;
    }
}
