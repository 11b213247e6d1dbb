//! How an Adam step is taken ([`StepSettings`]: the learning rates and clipping), the one
//! function that takes it on a flat weight vector, and the one Adam step an engine takes on
//! its own ([`TrainStep`]; training steps through [`crate::engine::step::Optimiser`]).

use std::ops::Range;

use crate::numeric::{Adam, Real, Update};

#[cfg(test)]
use super::batch::Batch;
#[cfg(test)]
use super::error::BackendError;

/// How one optimiser step is taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSettings {
    /// Adam learning rate of the network weights.
    pub learning_rate: f64,
    /// Adam learning rate of the raw params.
    pub param_learning_rate: f64,
    /// Rescale the whole gradient to at most this Euclidean norm (none: no clipping).
    pub max_gradient_norm: Option<f64>,
}

impl StepSettings {
    /// One learning rate for everything, no clipping.
    pub fn plain(learning_rate: f64) -> Self {
        StepSettings {
            learning_rate,
            param_learning_rate: learning_rate,
            max_gradient_norm: None,
        }
    }

    /// The optimiser's groups over `size` weights back to back: the params (at `params`,
    /// when the model has any) at their own rate, everything else at the network's.
    pub fn groups(&self, size: usize, params: Option<Range<usize>>) -> Vec<(Range<usize>, f64)> {
        match params {
            Some(params) => vec![
                (0..params.start, self.learning_rate),
                (params.start..params.end, self.param_learning_rate),
                (params.end..size, self.learning_rate),
            ],
            None => vec![(0..size, self.learning_rate)],
        }
    }

    /// One Adam step of the flat `weights` along `gradient` (clipped as asked), the params
    /// (at `params`, when the model has any) at their own learning rate.
    pub fn adam_step<E: Real>(
        &self,
        adam: &mut Adam<E>,
        weights: &mut [E],
        gradient: &mut [E],
        params: Option<Range<usize>>,
    ) {
        let groups = self.groups(weights.len(), params);
        let update = Update {
            groups: &groups,
            max_gradient_norm: self.max_gradient_norm,
        };
        adam.step(weights, gradient, &update);
    }
}

/// An engine that takes Adam steps of its own on one-step pairs, with Adam's state kept
/// inside it (the engines' tests compare both engines' steps).
#[cfg(test)]
pub trait TrainStep {
    /// One Adam step on the batch's loss with the params at their own learning rate and
    /// optional global-norm clipping; returns the loss before the step.
    fn train_step_with(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError>;

    /// One Adam step on the batch's loss at one learning rate, without clipping; returns
    /// the loss before the step.
    fn train_step(&mut self, batch: &Batch, learning_rate: f64) -> Result<f64, BackendError> {
        self.train_step_with(batch, &StepSettings::plain(learning_rate))
    }
}
