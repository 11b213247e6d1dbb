//! The epochs of training: one-step epochs of shuffled pair batches and, for the
//! multi-step objective, rollout epochs over shuffled shooting windows (see
//! [`super::recipe`]).
//!
//! With [`Engine::Fused`] the one-step epochs run on a [`FusedNetwork`] and everything else
//! on the graph [`Network`]: whichever of the two stepped last holds the current weights
//! and Adam state, and hands both over before the other one steps (at the curriculum's
//! switch to rollouts, and at the end, so that the polish and the evaluation see the
//! trained network). Hidden states are refreshed through the graph network after it has
//! been given the fused step's current weights.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::{AdamState, BackendError, Batch, NamedTensor, Network, Setup, StepSettings};
use crate::fused::FusedNetwork;
use crate::ir;

use super::checkpoint::Safety;
use super::pairs::stage_fractions;
use super::split::Training;
use super::validation::{refresh, Course};
use super::windows::{rollout_batch, shooting_starts};
use super::{Engine, Event, Recipe, TrainError, TrainOptions, FILL_REFRESH};

/// What the epochs need besides the network.
pub(super) struct Fit<'a> {
    pub model: &'a ir::Model,
    pub setup: &'a Setup,
    pub options: &'a TrainOptions,
    pub recipe: &'a Recipe,
    pub hidden_init: &'a [f64],
    /// Hold the params at their initial values (they came from the balances).
    pub freeze_params: bool,
    /// What trains on each track.
    pub trainings: &'a [Training],
}

/// One Adam step on a one-step batch with the given settings; the loss before it.
type OneStep<'s> = dyn FnMut(&Batch, &StepSettings) -> Result<f64, BackendError> + 's;

impl Fit<'_> {
    fn settings(&self) -> StepSettings {
        StepSettings {
            learning_rate: self.options.learning_rate,
            param_learning_rate: if self.freeze_params {
                0.0
            } else {
                (self.recipe.param_learning_rate).unwrap_or(self.options.learning_rate)
            },
            max_gradient_norm: self.recipe.max_gradient_norm,
        }
    }

    /// Runs every epoch (from a checkpoint's, and until `safety` stops it); returns the
    /// mean training loss of each. `network` ends with the trained weights and Adam state
    /// whichever engine ran the one-step epochs.
    pub fn run(
        &self,
        network: &mut Network,
        training: &mut Course,
        on_event: &mut dyn FnMut(Event),
        safety: &mut Safety,
    ) -> Result<Vec<f64>, TrainError> {
        let options = self.options;
        let fractions = stage_fractions(self.model.dynamics, options.substeps);
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed.wrapping_add(0x5eed));
        let mut losses = Vec::with_capacity(options.epochs);
        let first = safety.resume(network, training, &mut rng, &mut losses)?;
        let mut engines = Engines::new(network, options.engine, self.model, self.setup)?;
        let needs_fill = training.tracks.iter().any(|t| !t.fully_known());
        // A state an experiment never measures is all fill: its estimate is the model's own
        // run, refreshed every epoch.
        let unmeasured =
            (training.tracks.iter()).any(|t| t.measured.iter().any(|m| !m.iter().any(|&x| x)));
        let every = if unmeasured { 1 } else { FILL_REFRESH };
        for epoch in first..=options.epochs {
            let horizon = self.recipe.horizon_at(epoch, options.epochs);
            let fill_due = needs_fill && (epoch - 1) % every == 0;
            if epoch > 1 && (!self.model.hidden.is_empty() || fill_due) {
                let current = engines.current_weights()?;
                let how = (fractions.as_slice(), fill_due);
                refresh(current, self.model, training, how, self.hidden_init)?;
            }
            let loss = self
                .epoch(&mut engines, training, (horizon, &fractions), &mut rng)
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
            let engines = &mut engines;
            let end = EpochEnd {
                epoch,
                horizon,
                loss,
                rng: &rng,
                course: training,
                engines,
            };
            if safety.after_epoch(end, on_event)? {
                break;
            }
        }
        engines.graph()?;
        safety.finish(network)?;
        Ok(losses)
    }

    /// One epoch of `horizon`-step windows (1: one-step pairs) on the engine that runs it.
    fn epoch(
        &self,
        engines: &mut Engines,
        training: &Course,
        (horizon, fractions): (usize, &[f64]),
        rng: &mut ChaCha8Rng,
    ) -> Result<f64, EpochFailure> {
        if horizon > 1 {
            let network = engines.graph()?;
            return self.rollout_epoch(network, training, (horizon, fractions), rng);
        }
        if engines.fused.is_some() {
            let fused = engines.fused()?;
            self.one_step_epoch(&mut |b, s| fused.train_step_with(b, s), training, rng)
        } else {
            let network = engines.graph()?;
            self.one_step_epoch(&mut |b, s| network.train_step_with(b, s), training, rng)
        }
    }

    fn one_step_epoch(
        &self,
        step: &mut OneStep,
        training: &Course,
        rng: &mut ChaCha8Rng,
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let mut order: Vec<usize> = (0..training.table.len()).collect();
        order.shuffle(rng);
        let mut total = 0.0;
        for chunk in order.chunks(self.options.batch_size) {
            let loss = step(&training.table.batch(chunk), &settings)?;
            finite(loss)?;
            total += loss * chunk.len() as f64;
        }
        Ok(total / order.len().max(1) as f64)
    }

    fn rollout_epoch(
        &self,
        network: &mut Network,
        training: &Course,
        (horizon, fractions): (usize, &[f64]),
        rng: &mut ChaCha8Rng,
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let longest = (self.trainings.iter())
            .map(|t| t.knots.len())
            .max()
            .unwrap_or(0);
        let horizon = horizon.min(longest.max(1));
        let phase = rng.gen_range(0..horizon);
        let mut starts = Vec::new();
        for (index, training_part) in self.trainings.iter().enumerate() {
            let knots = &training_part.knots;
            let tiles = shooting_starts(knots.start, knots.len(), horizon, phase);
            starts.extend(tiles.into_iter().map(|knot| (index, knot)));
        }
        if starts.is_empty() {
            let step = &mut |b: &Batch, s: &StepSettings| network.train_step_with(b, s);
            return self.one_step_epoch(step, training, rng);
        }
        starts.shuffle(rng);
        let per_batch = (self.recipe.windows_per_batch)
            .unwrap_or(self.options.batch_size)
            .max(1);
        let mut total = 0.0;
        for chunk in starts.chunks(per_batch) {
            let batch = rollout_batch(
                self.model,
                (
                    &training.tracks,
                    &training.hidden,
                    &training.weights,
                    &self.setup.normalisation.observables,
                ),
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

/// The state after an epoch, for the run's safety hooks ([`Safety`]).
pub(super) struct EpochEnd<'e, 'n> {
    /// 1-based epoch.
    pub epoch: usize,
    /// Its rollout length (1: one-step).
    pub horizon: usize,
    /// Its mean training loss.
    pub loss: f64,
    /// The shuffling generator.
    pub rng: &'e ChaCha8Rng,
    /// The training tracks.
    pub course: &'e Course,
    engines: &'e mut Engines<'n>,
}

impl EpochEnd<'_, '_> {
    /// The graph network with the current weights.
    pub fn network(&mut self) -> Result<&Network, BackendError> {
        self.engines.current_weights()
    }

    /// The current weights and Adam state, from whichever engine holds them (nothing is
    /// handed over, so that looking does not change the run).
    pub fn state(&self) -> (Vec<NamedTensor>, AdamState) {
        let engines = &self.engines;
        match engines.fused.as_ref().filter(|_| engines.fused_holds) {
            Some(fused) => (fused.weights(), fused.adam_state()),
            None => (engines.network.weights(), engines.network.adam_state()),
        }
    }
}

/// The graph network and, with [`Engine::Fused`], the fused step; `fused_holds` says
/// whether the fused step has stepped since it last handed over, i.e. holds the current
/// weights and Adam state.
struct Engines<'n> {
    network: &'n mut Network,
    fused: Option<FusedNetwork>,
    fused_holds: bool,
}

impl<'n> Engines<'n> {
    /// The engines for `engine`; the fused step, if any, is built (so that a model it
    /// refuses fails before the first epoch).
    fn new(
        network: &'n mut Network,
        engine: Engine,
        model: &ir::Model,
        setup: &Setup,
    ) -> Result<Self, BackendError> {
        let fused = match engine {
            Engine::Graph => None,
            Engine::Fused => Some(FusedNetwork::build(model, setup)?),
        };
        Ok(Engines {
            network,
            fused,
            fused_holds: false,
        })
    }

    /// The graph network, given the fused step's weights and Adam state if it holds them.
    fn graph(&mut self) -> Result<&mut Network, BackendError> {
        if let Some(fused) = self.fused.as_ref().filter(|_| self.fused_holds) {
            self.network.set_weights(&fused.weights())?;
            self.network.set_adam_state(&fused.adam_state())?;
            self.fused_holds = false;
        }
        Ok(self.network)
    }

    /// The fused step, given the graph network's weights and Adam state if it holds them.
    fn fused(&mut self) -> Result<&mut FusedNetwork, BackendError> {
        let fused = (self.fused.as_mut())
            .ok_or_else(|| BackendError::internal("a fused epoch without a fused step"))?;
        if !self.fused_holds {
            fused.set_weights(&self.network.weights())?;
            fused.set_adam_state(&self.network.adam_state())?;
            self.fused_holds = true;
        }
        Ok(fused)
    }

    /// The graph network with the current weights (Adam's state stays where it is), for
    /// computations that do not step.
    fn current_weights(&mut self) -> Result<&Network, BackendError> {
        if let Some(fused) = self.fused.as_ref().filter(|_| self.fused_holds) {
            self.network.set_weights(&fused.weights())?;
        }
        Ok(self.network)
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
