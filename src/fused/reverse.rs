//! The reverse pass of one stage: the physics program's reverse sweep, then each closure
//! network's layers from the output down to the first, whose weight gradient is completed
//! per stage time by the kernel (see [`super::kernel`]).

use crate::backend::program::ProgramInputs;

use super::activation::Lane;
use super::dense::{add_column_sums, Gemm, View};
use super::kernel::Kernel;
use super::plan::ClosurePlan;

impl<E: Lane> Kernel<E> {
    /// Reverse of stage `index` given the adjoint of its balances: accumulates the weight
    /// and param gradients, adds each closure's first-layer delta into
    /// `offset_deltas[closure][stage time]`, and returns the gradient with respect to the
    /// stage's state estimate.
    pub(super) fn reverse_stage(
        &mut self,
        index: usize,
        seed: &[E],
        offset_deltas: &mut [Vec<Vec<E>>],
    ) -> Vec<E> {
        let stage = &self.stages[index];
        let nets: Vec<&[E]> = (stage.layers.iter())
            .map(|layers| layers.last().map_or(&[][..], Vec::as_slice))
            .collect();
        let (start, length) = self.plan.params;
        let inputs = ProgramInputs {
            rows: self.rows,
            states: &stage.state,
            inputs: &self.inputs,
            params: &self.weights[start..start + length],
            nets: &nets,
        };
        let physics = self
            .program
            .backward(&inputs, &stage.values, &self.program.balances, seed);
        let mut state_gradient = physics.states;
        let param_gradient = &mut self.gradient[start..start + length];
        for (slot, &value) in param_gradient.iter_mut().zip(&physics.params) {
            *slot += value;
        }
        for (((closure, layers), slopes), (net_gradient, deltas)) in (self.plan.closures.iter())
            .zip(&stage.layers)
            .zip(&stage.slopes)
            .zip(physics.nets.into_iter().zip(offset_deltas.iter_mut()))
        {
            let mut backprop = Backprop {
                gemm: &mut self.gemm,
                closure,
                rows: self.rows,
            };
            let delta = backprop.hidden_layers(
                net_gradient,
                layers,
                slopes,
                &self.weights,
                &mut self.gradient,
            );
            backprop.first_layer(
                &delta,
                &stage.state,
                self.states,
                &self.weights,
                &mut self.gradient,
                &mut state_gradient,
            );
            for (sum, &value) in deltas[stage.offset].iter_mut().zip(&delta) {
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
}

impl<E: Lane> Backprop<'_, E> {
    /// From the gradient of the network output down to that of the first layer's
    /// pre-activation (returned), accumulating the weight and bias gradients of every layer
    /// but the first.
    fn hidden_layers(
        &mut self,
        mut delta: Vec<E>,
        layers: &[Vec<E>],
        slopes: &[Vec<E>],
        weights: &[E],
        gradient: &mut [E],
    ) -> Vec<E> {
        let (closure, rows) = (self.closure, self.rows);
        for layer in (1..closure.layers()).rev() {
            let (inner, width) = (closure.widths[layer], closure.widths[layer + 1]);
            self.gemm.multiply_add(
                &mut gradient[closure.weight_at[layer]..][..inner * width],
                (inner, width, rows),
                View::transposed(&layers[layer], inner),
                View::row_major(&delta, width),
            );
            add_column_sums(
                &mut gradient[closure.bias_at[layer]..][..width],
                &delta,
                width,
            );
            let weight = &weights[closure.weight_at[layer]..][..inner * width];
            let mut below = vec![E::ZERO; rows * inner];
            self.gemm.multiply_add(
                &mut below,
                (rows, inner, width),
                View::row_major(&delta, width),
                View::transposed(weight, width),
            );
            for (value, &slope) in below.iter_mut().zip(&slopes[layer - 1]) {
                *value = *value * slope;
            }
            delta = below;
        }
        delta
    }

    /// The first layer's bias gradient, and what passes through its lag-0 state columns:
    /// their weight gradient `(x / std) delta` and the estimate's gradient
    /// `(delta . W0[column, :]) / std`. (The embedding part of the weight gradient is one
    /// product per stage time, formed by the kernel.)
    fn first_layer(
        &mut self,
        delta: &[E],
        state: &[E],
        states: usize,
        weights: &[E],
        gradient: &mut [E],
        state_gradient: &mut [E],
    ) {
        let closure = self.closure;
        let width = closure.widths[1];
        add_column_sums(&mut gradient[closure.bias_at[0]..][..width], delta, width);
        let first = closure.weight_at[0];
        for ((delta_row, estimate), gradient_row) in (delta.chunks_exact(width))
            .zip(state.chunks_exact(states))
            .zip(state_gradient.chunks_exact_mut(states))
        {
            for &(column, index, inverse_std) in &closure.stage_columns {
                let inverse_std = E::from_double(inverse_std);
                let scale = estimate[index] * inverse_std;
                let weight_gradient = &mut gradient[first + column * width..][..width];
                let mut dot = E::ZERO;
                for ((slot, &d), &w) in weight_gradient
                    .iter_mut()
                    .zip(delta_row)
                    .zip(&weights[first + column * width..][..width])
                {
                    *slot += scale * d;
                    dot += d * w;
                }
                gradient_row[index] += dot * inverse_std;
            }
        }
    }
}
