//! The reverse pass of one stage: the physics program's reverse sweep, then each closure
//! network's layers from the output down to the first, whose weight gradient is completed
//! per stage time by the kernel (see [`super::kernel`]).

use crate::engine::program::ProgramInputs;

use super::activation::Lane;
use super::buffers::Scratch;
use super::dense::{add_column_sums, Gemm, View};
use super::kernel::Kernel;
use super::plan::ClosurePlan;

impl<E: Lane> Kernel<E> {
    /// Reverse of stage `index` given the adjoint of its balances: accumulates the weight
    /// and param gradients, adds each closure's first-layer delta into the scratch's
    /// `offset_deltas[closure][stage time]`, and returns the gradient with respect to the
    /// stage's state estimate.
    pub(super) fn reverse_stage(&mut self, index: usize, seed: &[E]) -> Vec<E> {
        let stage = &self.stages[index];
        let nets: Vec<&[E]> = (stage.layers.iter())
            .map(|layers| layers.last().map_or(&[][..], Vec::as_slice))
            .collect();
        let (start, length) = self.plan.params;
        let inputs = ProgramInputs {
            rows: self.rows,
            states: &stage.state,
            inputs: &self.window[stage.step].inputs,
            params: &self.weights[start..start + length],
            nets: &nets,
        };
        let targets = (self.program.balances.as_slice(), seed);
        let physics = &mut self.scratch.physics;
        (self.program).backward_into(&inputs, &stage.values, targets, physics);
        let physics = &physics.gradients;
        let mut state_gradient = physics.states.clone();
        let param_gradient = &mut self.gradient[start..start + length];
        for (slot, &value) in param_gradient.iter_mut().zip(&physics.params) {
            *slot += value;
        }
        let scratch = &mut self.scratch;
        for closure_index in 0..self.plan.closures.len() {
            let closure = &self.plan.closures[closure_index];
            scratch.delta.clear();
            (scratch.delta).extend_from_slice(&scratch.physics.gradients.nets[closure_index]);
            let mut backprop = Backprop {
                gemm: &mut self.gemm,
                closure,
                rows: self.rows,
                scratch: &mut *scratch,
            };
            let (layers, slopes) = (&stage.layers[closure_index], &stage.slopes[closure_index]);
            backprop.hidden_layers(layers, slopes, &self.weights, &mut self.gradient);
            let state = (stage.state.as_slice(), self.states);
            backprop.first_layer(
                state,
                &self.weights,
                &mut self.gradient,
                &mut state_gradient,
            );
            let sums = &mut scratch.offset_deltas[closure_index][stage.offset];
            for (sum, &value) in sums.iter_mut().zip(&scratch.delta) {
                *sum += value;
            }
        }
        state_gradient
    }
}

/// The reverse pass through one closure network at one stage.
struct Backprop<'a, E> {
    gemm: &'a mut Gemm<E>,
    closure: &'a ClosurePlan,
    rows: usize,
    scratch: &'a mut Scratch<E>,
}

impl<E: Lane> Backprop<'_, E> {
    /// From the gradient of the network output (in `scratch.delta`) down to that of the
    /// first layer's pre-activation (left there), accumulating the weight and bias gradients
    /// of every layer but the first.
    fn hidden_layers(
        &mut self,
        layers: &[Vec<E>],
        slopes: &[Vec<E>],
        weights: &[E],
        gradient: &mut [E],
    ) {
        let (closure, rows) = (self.closure, self.rows);
        let Scratch { delta, below, .. } = &mut *self.scratch;
        for layer in (1..closure.layers()).rev() {
            let (inner, width) = (closure.widths[layer], closure.widths[layer + 1]);
            self.gemm.multiply_add(
                &mut gradient[closure.weight_at[layer]..][..inner * width],
                (inner, width, rows),
                View::transposed(&layers[layer], inner),
                View::row_major(delta, width),
            );
            add_column_sums(
                &mut gradient[closure.bias_at[layer]..][..width],
                delta,
                width,
            );
            let weight = &weights[closure.weight_at[layer]..][..inner * width];
            below.resize(rows * inner, E::ZERO);
            self.gemm.multiply(
                below,
                (rows, inner, width),
                View::row_major(delta, width),
                View::transposed(weight, width),
            );
            for (value, &slope) in below.iter_mut().zip(&slopes[layer - 1]) {
                *value = *value * slope;
            }
            std::mem::swap(delta, below);
        }
    }

    /// The first layer's bias gradient, and what passes through its lag-0 state columns:
    /// their weight gradient `(x / std)^T delta` and the estimate's gradient
    /// `(delta W0[columns, :]^T) / std`. (The embedding part of the weight gradient is one
    /// product per stage time, formed by the kernel.)
    fn first_layer(
        &mut self,
        (state, states): (&[E], usize),
        weights: &[E],
        gradient: &mut [E],
        state_gradient: &mut [E],
    ) {
        let (closure, rows) = (self.closure, self.rows);
        let width = closure.widths[1];
        let scratch = &mut *self.scratch;
        add_column_sums(
            &mut gradient[closure.bias_at[0]..][..width],
            &scratch.delta,
            width,
        );
        let columns = closure.stage_columns.len();
        if columns == 0 {
            return;
        }
        let first = closure.weight_at[0];
        scratch.estimate.clear();
        for estimate in state.chunks_exact(states) {
            scratch.estimate.extend(
                (closure.stage_columns.iter())
                    .map(|&(_, index, inverse_std)| estimate[index] * E::from_double(inverse_std)),
            );
        }
        scratch.estimate_weights.clear();
        for &(column, _, _) in &closure.stage_columns {
            let row = &weights[first + column * width..][..width];
            scratch.estimate_weights.extend_from_slice(row);
        }
        scratch.estimate_gradient.resize(rows * columns, E::ZERO);
        self.gemm.multiply(
            &mut scratch.estimate_gradient,
            (rows, columns, width),
            View::row_major(&scratch.delta, width),
            View::transposed(&scratch.estimate_weights, width),
        );
        scratch
            .estimate_weight_gradient
            .resize(columns * width, E::ZERO);
        self.gemm.multiply(
            &mut scratch.estimate_weight_gradient,
            (columns, width, rows),
            View::transposed(&scratch.estimate, columns),
            View::row_major(&scratch.delta, width),
        );
        for (&(column, _, _), values) in
            (closure.stage_columns.iter()).zip(scratch.estimate_weight_gradient.chunks_exact(width))
        {
            for (slot, &value) in gradient[first + column * width..][..width]
                .iter_mut()
                .zip(values)
            {
                *slot += value;
            }
        }
        for (gradient_row, estimate_row) in (state_gradient.chunks_exact_mut(states))
            .zip(scratch.estimate_gradient.chunks_exact(columns))
        {
            for (&(_, index, inverse_std), &value) in closure.stage_columns.iter().zip(estimate_row)
            {
                gradient_row[index] += value * E::from_double(inverse_std);
            }
        }
    }
}
