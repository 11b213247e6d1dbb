//! What runs the epochs' steps: the optimiser on top of the graph network or, where the
//! engine asks for it, the fused step.

use crate::engine::fused::FusedNetwork;
use crate::engine::graph::{BackendError, NamedTensor, Network, RolloutBatch, StepSettings};
use crate::engine::step::{Optimiser, Step, StepBatch};

/// The optimiser, the graph network and, where the engine asks for it, the fused step
/// (which then runs every batch).
pub(super) struct Engines<'n> {
    /// The graph network.
    pub network: &'n mut Network,
    /// The fused step, where the run has one.
    pub fused: Option<FusedNetwork>,
    /// The weights and Adam's state.
    pub optimiser: Optimiser,
    /// The rollout batch, its buffers kept from batch to batch.
    pub windows: RolloutBatch,
    /// The learning rates' scale after recoveries (1: as asked).
    pub scale: f64,
    /// The longest rollout after recoveries (`usize::MAX`: as the recipe says).
    pub cap: usize,
    /// Recoveries so far.
    pub recovered: usize,
}

impl Engines<'_> {
    /// One optimiser step on `batch`, on the fused step where the run has one (it runs
    /// every batch of the models it builds for), else on the graph network.
    pub fn step(&mut self, batch: StepBatch, settings: &StepSettings) -> Result<f64, BackendError> {
        let engine: &mut dyn Step = match self.fused.as_mut() {
            Some(fused) => fused,
            None => self.network,
        };
        let settings = StepSettings {
            learning_rate: settings.learning_rate * self.scale,
            param_learning_rate: settings.param_learning_rate * self.scale,
            ..*settings
        };
        self.optimiser.step(engine, batch, &settings)
    }

    /// The optimiser's current weights as the network's named tensors.
    pub fn tensors(&self) -> Vec<NamedTensor> {
        let mut tensors = self.network.weights();
        let flat = self.optimiser.weights();
        let mut at = 0;
        for tensor in &mut tensors {
            let size = tensor.values.len();
            tensor.values.copy_from_slice(&flat[at..at + size]);
            at += size;
        }
        tensors
    }

    /// The first of the optimiser's weights (params by name) that is not finite, in words.
    pub fn non_finite(&self, params: &[String]) -> Option<String> {
        crate::finite::first_non_finite(&self.optimiser.weights())?;
        crate::finite::in_tensors(&self.tensors(), params)
    }

    /// The graph network with the optimiser's current weights.
    pub fn graph_with_weights(&mut self) -> Result<&Network, BackendError> {
        self.network.set_flat_weights(&self.optimiser.weights())?;
        Ok(self.network)
    }
}
