//! The epochs of training: one-step epochs of shuffled pair batches and, for the
//! multi-step objective, rollout epochs over shuffled shooting windows (see
//! [`super::recipe`]).

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::{Network, StepSettings};
use crate::ir;

use super::pairs::stage_fractions;
use super::windows::{rollout_batch, shooting_starts};
use super::{refresh_hidden, Event, Recipe, Split, TrainError, TrainOptions};

/// What the epochs need besides the network.
pub(super) struct Fit<'a> {
    pub model: &'a ir::Model,
    pub options: &'a TrainOptions,
    pub recipe: &'a Recipe,
    pub hidden_init: &'a [f64],
}

impl Fit<'_> {
    fn settings(&self) -> StepSettings {
        StepSettings {
            learning_rate: self.options.learning_rate,
            param_learning_rate: (self.recipe.param_learning_rate)
                .unwrap_or(self.options.learning_rate),
            max_gradient_norm: self.recipe.max_gradient_norm,
        }
    }

    /// Runs every epoch; returns the mean training loss of each.
    pub fn run(
        &self,
        network: &mut Network,
        training: &mut Split,
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Vec<f64>, TrainError> {
        let options = self.options;
        let fractions = stage_fractions(self.model.dynamics, options.substeps);
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed.wrapping_add(0x5eed));
        let mut losses = Vec::with_capacity(options.epochs);
        for epoch in 1..=options.epochs {
            if epoch > 1 {
                refresh_hidden(network, self.model, training, &fractions, self.hidden_init)?;
            }
            let horizon = self.recipe.horizon_at(epoch, options.epochs);
            let loss = if horizon <= 1 {
                self.one_step_epoch(network, training, &mut rng)
            } else {
                self.rollout_epoch(network, training, (horizon, &fractions), &mut rng)
            }
            .map_err(|found| match found {
                EpochFailure::Backend(error) => TrainError::Backend(error),
                EpochFailure::NotFinite(loss) => TrainError::Diverged { epoch, loss },
            })?;
            losses.push(loss);
            on_event(Event::Epoch {
                epoch,
                loss,
                horizon,
            });
        }
        Ok(losses)
    }

    fn one_step_epoch(
        &self,
        network: &mut Network,
        training: &Split,
        rng: &mut ChaCha8Rng,
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let mut order: Vec<usize> = (0..training.table.len()).collect();
        order.shuffle(rng);
        let mut total = 0.0;
        for chunk in order.chunks(self.options.batch_size) {
            let loss = network.train_step_with(&training.table.batch(chunk), &settings)?;
            finite(loss)?;
            total += loss * chunk.len() as f64;
        }
        Ok(total / order.len().max(1) as f64)
    }

    fn rollout_epoch(
        &self,
        network: &mut Network,
        training: &Split,
        (horizon, fractions): (usize, &[f64]),
        rng: &mut ChaCha8Rng,
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let pairs = training.table.len();
        let first = training.table.rows.first().copied().unwrap_or(0);
        let horizon = horizon.min(pairs.max(1));
        let phase = rng.gen_range(0..horizon);
        let mut starts = shooting_starts(first, pairs, horizon, phase);
        if starts.is_empty() {
            return self.one_step_epoch(network, training, rng);
        }
        starts.shuffle(rng);
        let per_batch = (self.recipe.windows_per_batch)
            .unwrap_or(self.options.batch_size)
            .max(1);
        let mut total = 0.0;
        for chunk in starts.chunks(per_batch) {
            let batch = rollout_batch(
                self.model,
                &training.record,
                &training.hidden,
                chunk,
                horizon,
                fractions,
            );
            let loss = network.rollout_step(&batch, &settings)?;
            finite(loss)?;
            total += loss * chunk.len() as f64;
        }
        Ok(total / starts.len() as f64)
    }
}

/// Why an epoch stopped.
enum EpochFailure {
    Backend(crate::backend::BackendError),
    NotFinite(f64),
}

impl From<crate::backend::BackendError> for EpochFailure {
    fn from(error: crate::backend::BackendError) -> Self {
        EpochFailure::Backend(error)
    }
}

fn finite(loss: f64) -> Result<(), EpochFailure> {
    if loss.is_finite() {
        Ok(())
    } else {
        Err(EpochFailure::NotFinite(loss))
    }
}
