//! The state after an epoch, as the run's safety hooks see it (checkpoints, the stop of
//! `--toward-mechanism auto`, a kept last finite epoch).

use super::engines::Engines;
use crate::engine::graph::{AdamState, BackendError, NamedTensor, Network};
use crate::train::validation::Course;
use rand_chacha::ChaCha8Rng;

/// The state after an epoch, for the run's safety hooks ([`Safety`]).
pub(in crate::train) struct EpochEnd<'e, 'n> {
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
    pub(super) engines: &'e mut Engines<'n>,
}

impl EpochEnd<'_, '_> {
    /// The graph network with the current weights.
    pub fn network(&mut self) -> Result<&Network, BackendError> {
        self.engines.graph_with_weights()
    }

    /// The current weights and Adam state, from the optimiser (looking changes nothing).
    pub fn state(&self) -> (Vec<NamedTensor>, AdamState) {
        let engines = &self.engines;
        (engines.tensors(), engines.optimiser.adam_state())
    }
}
