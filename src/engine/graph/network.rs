//! The graph engine's network in the precision of its [`Setup`]: one `GreyBox` in `f32`
//! or `f64`, every call run on whichever it holds.

use crate::engine::batch::{Batch, Prediction, RolloutBatch};
use crate::engine::error::BackendError;
#[cfg(test)]
use crate::engine::settings::StepSettings;
#[cfg(test)]
use crate::engine::settings::TrainStep;
use crate::engine::setup::{dispatch, Precision, Setup};
use crate::ir;
#[cfg(test)]
use crate::numeric::AdamState;
use crate::numeric::NamedTensor;

use super::net::GreyBox;

/// The trainable network in the chosen precision, with its Adam state.
pub struct Network {
    inner: Inner,
}

enum Inner {
    Single(GreyBox<f32>),
    Double(GreyBox<f64>),
}

impl Network {
    /// Lowers `model` into a trainable network with freshly initialised weights.
    pub fn build(model: &ir::Model, setup: &Setup) -> Result<Network, BackendError> {
        let inner = match setup.precision {
            Precision::F32 => Inner::Single(GreyBox::build(model, setup)?),
            Precision::F64 => Inner::Double(GreyBox::build(model, setup)?),
        };
        Ok(Network { inner })
    }

    /// One Adam step on the mean normalised squared error over every step of every
    /// window of a rollout batch (gradients through the whole rollout); returns the loss
    /// before the step.
    #[cfg(test)]
    pub fn rollout_step(
        &mut self,
        batch: &RolloutBatch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, net => net.rollout_step(batch, settings))
    }

    /// The rollout loss of a batch (see [`Network::rollout_step`]).
    pub fn rollout_loss(&self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        dispatch!(self, net => net.rollout_loss(batch))
    }

    /// The rollout loss and its gradient with respect to every tensor of
    /// [`Network::weights`].
    pub fn rollout_gradient(
        &self,
        batch: &RolloutBatch,
    ) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(self, net => net.rollout_gradient(batch))
    }

    /// The states after each step of each window: `[step]` of `rows x (measured + hidden)`.
    pub fn rollout_predict(&self, batch: &RolloutBatch) -> Result<Vec<Vec<f64>>, BackendError> {
        dispatch!(self, net => net.rollout_predict(batch))
    }

    /// The normalised one-step loss of a batch.
    pub fn loss(&self, batch: &Batch) -> Result<f64, BackendError> {
        dispatch!(self, net => net.loss(batch))
    }

    /// The loss and its gradient with respect to every tensor of [`Network::weights`].
    pub fn gradient(&self, batch: &Batch) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(self, net => net.gradient(batch))
    }

    /// One-step predictions (no targets needed).
    pub fn predict(&self, batch: &Batch) -> Result<Prediction, BackendError> {
        dispatch!(self, net => net.predict(batch))
    }

    /// The trainable tensors: each closure's layers, then the raw params (if any).
    pub fn weights(&self) -> Vec<NamedTensor> {
        dispatch!(self, net => net.weights())
    }

    /// Replaces the trainable tensors (names and shapes must match [`Network::weights`]).
    pub fn set_weights(&mut self, weights: &[NamedTensor]) -> Result<(), BackendError> {
        dispatch!(mut self, net => net.set_weights(weights))
    }

    /// Replaces the trainable values from one flat vector (the tensors of
    /// [`Network::weights`] back to back).
    pub fn set_flat_weights(&mut self, flat: &[f64]) -> Result<(), BackendError> {
        dispatch!(mut self, net => net.set_flat_weights(flat))
    }

    /// The constrained values of the model's params, in declaration order.
    pub fn param_values(&self) -> Vec<f64> {
        dispatch!(self, net => net.param_values())
    }

    /// RK4 sub-steps per call (1 for `next` models).
    pub fn substeps(&self) -> usize {
        dispatch!(self, net => net.substeps())
    }

    /// The same network taking `substeps` RK4 sub-steps per call (weights copied, a fresh
    /// optimiser).
    pub fn with_substeps(&self, substeps: usize) -> Network {
        let inner = match &self.inner {
            Inner::Single(net) => Inner::Single(net.with_substeps(substeps)),
            Inner::Double(net) => Inner::Double(net.with_substeps(substeps)),
        };
        Network { inner }
    }

    /// Adam's step count and moments, per tensor of [`Network::weights`] (to hand training
    /// over to [`crate::engine::fused::FusedNetwork`] and back).
    #[cfg(test)]
    pub fn adam_state(&self) -> AdamState {
        dispatch!(self, net => net.adam_state())
    }

    /// Replaces Adam's step count and moments (sizes must match [`Network::weights`]).
    #[cfg(test)]
    pub fn set_adam_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        dispatch!(mut self, net => net.set_adam_state(state))
    }
}

#[cfg(test)]
impl TrainStep for Network {
    fn train_step_with(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, net => net.train_step(batch, settings))
    }
}
