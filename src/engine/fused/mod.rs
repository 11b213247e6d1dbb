//! The hand-fused training engine (performance study, issue 8; rollouts, issue 15): the
//! same losses and gradients as [`crate::engine::graph::Network`], one-step pairs and rollout
//! windows, written as plain loops over buffers that live from step to step instead of a
//! recorded dfdx graph.
//!
//! It is driven by the compiled [`ir::Model`] like the backend: any number of closures of
//! any sizes and activations, `der` models (RK4 with `K` sub-steps, networks at every stage
//! on the delay embedding completed by the stage estimate) and `next` models, hidden states,
//! and the physics, priors and param transforms through the backend's own [`Program`]. A
//! batch is a window of steps (`rollout.rs`): one step for one-step pairs, `K` steps for a
//! [`RolloutBatch`], whose predictions are fed back into later steps' embeddings. What it
//! saves:
//!
//! - no tape: the reverse pass is written out (RK4 adjoint step by step, then per stage the
//!   physics program's reverse sweep and each network's layers, and the adjoint of every
//!   fed-back prediction), so there is no per-operation allocation, boxing or tape merging;
//! - one matrix kernel ([`dense::multiply_add`]) that keeps output strips in registers, for
//!   the layers, their input gradients and their weight gradients;
//! - softplus value and slope from one exponential, in `f32` through vectorisable
//!   polynomials ([`activation`]);
//! - buffers for activations, slopes, embeddings and every step of a window reused across
//!   batches, and one flat weight vector.
//!
//! Its losses and gradients agree with the graph backend's to rounding (tested in both
//! precisions, for every shipped model and both objectives); it starts from the same
//! weights as [`crate::engine::graph::Network::build`] and reads and writes the same
//! [`NamedTensor`] lists, so training runs it under the one optimiser of
//! training's step interface (`--engine fused`, and `auto` wherever it supports the model: all
//! but measured outputs). Its own Adam step ([`TrainStep`], with [`StepSettings`] and
//! [`AdamState`] as the graph backend's) serves the comparisons of the two engines.
//!
//! [`Program`]: crate::engine::program::Program
//! [`dense::multiply_add`]: dense::Gemm::multiply_add

pub mod activation;
mod buffers;
pub mod dense;
mod kernel;
mod plan;
mod reverse;
mod rollout;
mod rows;
mod wide;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_rollout;

use crate::engine::batch::{Batch, RolloutBatch, StepBatch};
use crate::engine::error::BackendError;
use crate::engine::graph::Network;
#[cfg(test)]
use crate::engine::settings::StepSettings;
#[cfg(test)]
use crate::engine::settings::TrainStep;
use crate::engine::setup::{dispatch, Precision, Setup};
use crate::ir;
#[cfg(test)]
use crate::numeric::AdamState;
use crate::numeric::{NamedTensor, Real};

use kernel::Kernel;
use plan::Plan;

/// The fused training step in the precision of its [`Setup`].
pub struct FusedNetwork {
    inner: Inner,
}

enum Inner {
    Single(Kernel<f32>),
    Double(Kernel<f64>),
}

impl FusedNetwork {
    /// Builds the step for `model` with the initial weights [`Network::build`] gives for the
    /// same setup.
    pub fn build(model: &ir::Model, setup: &Setup) -> Result<FusedNetwork, BackendError> {
        if !setup.normalisation.observables.is_empty() {
            return Err(BackendError::Unsupported {
                engine: "fused".into(),
                what: "measured outputs (observables) in the loss".into(),
            });
        }
        let template = Network::build(model, setup)?.weights();
        let plan = Plan::build(model, setup, &template)?;
        let flat: Vec<f64> = template.iter().flat_map(|t| t.values.clone()).collect();
        let inner = match setup.precision {
            Precision::F32 => Inner::Single(Kernel::new(model, setup, plan, &flat)?),
            Precision::F64 => Inner::Double(Kernel::new(model, setup, plan, &flat)?),
        };
        Ok(FusedNetwork { inner })
    }

    /// Adam's step count and moments, per tensor of [`FusedNetwork::weights`].
    #[cfg(test)]
    pub fn adam_state(&self) -> AdamState {
        dispatch!(self, kernel => kernel.adam_state())
    }

    /// Replaces Adam's step count and moments (sizes must match
    /// [`FusedNetwork::weights`]).
    #[cfg(test)]
    pub fn set_adam_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        dispatch!(mut self, kernel => kernel.set_adam_state(state))
    }

    /// The loss and its gradient with respect to every tensor of
    /// [`FusedNetwork::weights`].
    pub fn gradient(&mut self, batch: &Batch) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(mut self, kernel => {
            let loss = kernel.loss_and_gradient(batch)?;
            Ok((loss, split(kernel.plan(), &kernel.gradient)))
        })
    }

    /// The loss of a rollout batch, the mean normalised squared error over every step of
    /// every window as [`Network::rollout_loss`], and its gradient through the whole
    /// rollout with respect to every tensor of [`FusedNetwork::weights`].
    pub fn rollout_gradient(
        &mut self,
        batch: &RolloutBatch,
    ) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(mut self, kernel => {
            let loss = kernel.rollout_loss_and_gradient(batch)?;
            Ok((loss, split(kernel.plan(), &kernel.gradient)))
        })
    }

    /// The loss of one-step pairs or rollout windows, with the gradient
    /// written flat into `gradient` (tensors back to back, as
    /// [`FusedNetwork::set_flat_weights`] reads them): the training loop's call, with no
    /// allocation once `gradient` has its size.
    pub fn flat_gradient(
        &mut self,
        batch: StepBatch,
        gradient: &mut Vec<f64>,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, kernel => {
            let loss = match batch {
                StepBatch::Pairs(pairs) => kernel.loss_and_gradient(pairs)?,
                StepBatch::Windows(windows) => kernel.rollout_loss_and_gradient(windows)?,
            };
            gradient.clear();
            gradient.extend(kernel.gradient.iter().map(|g| g.to_double()));
            Ok(loss)
        })
    }

    /// The loss of a rollout batch (see [`FusedNetwork::rollout_gradient`]).
    pub fn rollout_loss(&mut self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        dispatch!(mut self, kernel => kernel.rollout_loss(batch))
    }

    /// Replaces the trainable values from one flat vector (the tensors of
    /// [`FusedNetwork::weights`] back to back).
    pub fn set_flat_weights(&mut self, flat: &[f64]) -> Result<(), BackendError> {
        dispatch!(mut self, kernel => {
            if flat.len() != kernel.weights.len() {
                return Err(BackendError::WeightsMismatch(format!(
                    "{} values where the model has {}",
                    flat.len(),
                    kernel.weights.len()
                )));
            }
            for (slot, &value) in kernel.weights.iter_mut().zip(flat) {
                *slot = Real::from_double(value);
            }
            Ok(())
        })
    }

    /// The trainable tensors, named and shaped as [`Network::weights`].
    pub fn weights(&self) -> Vec<NamedTensor> {
        dispatch!(self, kernel => {
            let plan = kernel.plan();
            (plan.names.iter().zip(split(plan, &kernel.weights)))
                .map(|((name, shape), values)| NamedTensor {
                    name: name.clone(),
                    shape: shape.clone(),
                    values,
                })
                .collect()
        })
    }

    /// Replaces the trainable tensors (names and shapes must match
    /// [`FusedNetwork::weights`]).
    pub fn set_weights(&mut self, weights: &[NamedTensor]) -> Result<(), BackendError> {
        dispatch!(mut self, kernel => {
            let plan = kernel.plan();
            check_weights(plan, weights)?;
            let flat = weights.iter().flat_map(|t| t.values.iter());
            for (slot, &value) in kernel.weights.iter_mut().zip(flat) {
                *slot = Real::from_double(value);
            }
            Ok(())
        })
    }
}

#[cfg(test)]
impl TrainStep for FusedNetwork {
    fn train_step_with(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, kernel => kernel.train_step(batch, settings))
    }
}

/// The flat vector cut into the plan's tensors, as `f64`.
fn split<E: Real>(plan: &Plan, flat: &[E]) -> Vec<Vec<f64>> {
    (plan.tensors.iter())
        .map(|&(start, length)| {
            flat[start..start + length]
                .iter()
                .map(|v| v.to_double())
                .collect()
        })
        .collect()
}

fn check_weights(plan: &Plan, weights: &[NamedTensor]) -> Result<(), BackendError> {
    if weights.len() != plan.names.len() {
        return Err(BackendError::WeightsMismatch(format!(
            "{} tensors where the model has {}",
            weights.len(),
            plan.names.len()
        )));
    }
    for (tensor, (name, shape)) in weights.iter().zip(&plan.names) {
        let length: usize = shape.iter().product();
        if &tensor.name != name || &tensor.shape != shape || tensor.values.len() != length {
            return Err(BackendError::WeightsMismatch(format!(
                "`{}` {:?} where the model has `{name}` {shape:?}",
                tensor.name, tensor.shape
            )));
        }
    }
    Ok(())
}
